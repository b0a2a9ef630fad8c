#include <gtest/gtest.h>

#include <thread>

#include "agv/fakecamera/fake_camera.hpp"

namespace {

using agv::fakecamera::FakeCamera;
using agv::hal::CameraStatus;
using agv::hal::FrameView;

// Simulated clock: sleeping advances time instantly.
class SimClock : public agv::hal::Clock {
 public:
  std::int64_t now_ns() const override { return t_; }
  int sleep_until_ns(std::int64_t t) override {
    if (t > t_) t_ = t;
    return 0;
  }

 private:
  std::int64_t t_ = 0;
};

TEST(FakeCamera, NotStartedUntilStart) {
  FakeCamera cam;
  FrameView f;
  cam.push_frame(FakeCamera::solid(8, 4, 1), 100);
  EXPECT_EQ(cam.next_frame(0, &f), CameraStatus::kNotStarted);
  ASSERT_EQ(cam.start(), CameraStatus::kOk);
  EXPECT_EQ(cam.next_frame(0, &f), CameraStatus::kOk);
  EXPECT_EQ(cam.next_frame(0, nullptr), CameraStatus::kInvalidArgument);
}

TEST(FakeCamera, DeliversScriptedFramesInOrder) {
  FakeCamera cam;
  auto img = FakeCamera::solid(8, 4, 7);
  img.gray[5] = 99;
  cam.push_frame(img, 1'000);
  cam.push_frame(FakeCamera::solid(8, 4, 9), 2'000);
  ASSERT_EQ(cam.start(), CameraStatus::kOk);
  FrameView a, b;
  ASSERT_EQ(cam.next_frame(0, &a), CameraStatus::kOk);
  ASSERT_EQ(cam.next_frame(0, &b), CameraStatus::kOk);
  EXPECT_EQ(a.t_exposure_ns, 1'000);
  EXPECT_EQ(b.t_exposure_ns, 2'000);
  EXPECT_EQ(a.sequence + 1, b.sequence);
  EXPECT_EQ(a.width_px, 8);
  EXPECT_EQ(a.stride_bytes, 8);
  EXPECT_EQ(a.data[5], 99);
  EXPECT_EQ(b.data[0], 9);
  EXPECT_NE(a.slot, b.slot);
  EXPECT_EQ(cam.frames_outstanding(), 2);
  cam.release(a);
  cam.release(a);  // double release ignored
  EXPECT_EQ(cam.frames_outstanding(), 1);
  FrameView foreign = b;
  foreign.slot = 42;
  cam.release(foreign);
  EXPECT_EQ(cam.frames_outstanding(), 1);
  cam.release(b);
  EXPECT_EQ(cam.frames_outstanding(), 0);
  EXPECT_EQ(cam.stats().frames_delivered, 2u);
}

TEST(FakeCamera, StallLongerThanTimeoutGivesTimeoutsAndAdvancesClock) {
  SimClock clock;
  FakeCamera::Options o;
  o.clock = &clock;
  FakeCamera cam(o);
  cam.push_stall(250);
  cam.push_frame(FakeCamera::solid(2, 2, 0), 5);
  ASSERT_EQ(cam.start(), CameraStatus::kOk);
  FrameView f;
  EXPECT_EQ(cam.next_frame(100, &f), CameraStatus::kTimeout);
  EXPECT_EQ(clock.now_ns(), 100);
  EXPECT_EQ(cam.next_frame(100, &f), CameraStatus::kTimeout);
  EXPECT_EQ(clock.now_ns(), 200);
  // The stall ends after 50 more ns, within this call's timeout: the frame arrives.
  EXPECT_EQ(cam.next_frame(100, &f), CameraStatus::kOk);
  EXPECT_EQ(clock.now_ns(), 250);
  // Script exhausted: the camera delivers nothing.
  EXPECT_EQ(cam.next_frame(100, &f), CameraStatus::kTimeout);
  EXPECT_EQ(clock.now_ns(), 350);
}

TEST(FakeCamera, DisconnectIsStickyUntilRestart) {
  FakeCamera cam;
  cam.push_disconnect();
  cam.push_frame(FakeCamera::solid(2, 2, 0), 5);
  ASSERT_EQ(cam.start(), CameraStatus::kOk);
  FrameView f;
  EXPECT_EQ(cam.next_frame(0, &f), CameraStatus::kDisconnected);
  EXPECT_EQ(cam.next_frame(0, &f), CameraStatus::kDisconnected);
  EXPECT_STRNE(cam.last_error(), "");
  EXPECT_EQ(cam.stats().errors, 1u);
  cam.stop();
  ASSERT_EQ(cam.start(), CameraStatus::kOk);
  EXPECT_EQ(cam.next_frame(0, &f), CameraStatus::kOk);
  EXPECT_EQ(cam.start_calls(), 2);
  EXPECT_EQ(cam.stop_calls(), 1);
}

TEST(FakeCamera, ScriptedStartFailure) {
  FakeCamera::Options o;
  o.start_status = CameraStatus::kDisconnected;
  FakeCamera cam(o);
  EXPECT_EQ(cam.start(), CameraStatus::kDisconnected);
  FrameView f;
  EXPECT_EQ(cam.next_frame(0, &f), CameraStatus::kNotStarted);
  cam.set_start_status(CameraStatus::kOk);
  EXPECT_EQ(cam.start(), CameraStatus::kOk);
}

TEST(FakeCamera, EndOfStream) {
  FakeCamera cam;
  cam.push_frame(FakeCamera::solid(2, 2, 0), 5);
  cam.push_end_of_stream();
  cam.push_frame(FakeCamera::solid(2, 2, 0), 6);
  ASSERT_EQ(cam.start(), CameraStatus::kOk);
  FrameView f;
  EXPECT_EQ(cam.next_frame(0, &f), CameraStatus::kOk);
  EXPECT_EQ(cam.next_frame(0, &f), CameraStatus::kEndOfStream);
  EXPECT_EQ(cam.next_frame(0, &f), CameraStatus::kEndOfStream);

  FakeCamera::Options o;
  o.end_of_stream_when_empty = true;
  FakeCamera replay(o);
  ASSERT_EQ(replay.start(), CameraStatus::kOk);
  EXPECT_EQ(replay.next_frame(0, &f), CameraStatus::kEndOfStream);
}

TEST(FakeCamera, HeldBuffersStarveAndDropFrames) {
  FakeCamera::Options o;
  o.slots = 2;
  FakeCamera cam(o);
  for (int i = 0; i < 4; ++i) cam.push_frame(FakeCamera::solid(2, 2, 0), i);
  ASSERT_EQ(cam.start(), CameraStatus::kOk);
  FrameView a, b, c;
  ASSERT_EQ(cam.next_frame(0, &a), CameraStatus::kOk);
  ASSERT_EQ(cam.next_frame(0, &b), CameraStatus::kOk);
  // Both slots held: the remaining two frames are lost, like a starved V4L2 queue.
  EXPECT_EQ(cam.next_frame(0, &c), CameraStatus::kTimeout);
  EXPECT_EQ(cam.stats().frames_dropped, 2u);
  cam.release(a);
  cam.push_frame(FakeCamera::solid(2, 2, 0), 10);
  ASSERT_EQ(cam.next_frame(0, &c), CameraStatus::kOk);
  EXPECT_EQ(c.slot, a.slot);  // recycled
}

TEST(FakeCamera, SequenceGapsCountAsDrops) {
  FakeCamera cam;
  cam.push_frame(FakeCamera::solid(2, 2, 0), 1, 10);
  cam.push_frame(FakeCamera::solid(2, 2, 0), 2, 13);
  ASSERT_EQ(cam.start(), CameraStatus::kOk);
  FrameView f;
  ASSERT_EQ(cam.next_frame(0, &f), CameraStatus::kOk);
  cam.release(f);
  ASSERT_EQ(cam.next_frame(0, &f), CameraStatus::kOk);
  EXPECT_EQ(f.sequence, 13u);
  EXPECT_EQ(cam.stats().frames_dropped, 2u);
}

TEST(FakeCamera, InconsistentFrameIsADeviceError) {
  FakeCamera cam;
  agv::fakecamera::FakeImage bad;
  bad.width_px = 4;
  bad.height_px = 4;
  bad.gray.resize(3);
  cam.push_frame(bad, 1);
  ASSERT_EQ(cam.start(), CameraStatus::kOk);
  FrameView f;
  EXPECT_EQ(cam.next_frame(0, &f), CameraStatus::kDeviceError);
}

TEST(FakeCamera, WaitsForFramesPushedFromAnotherThread) {
  FakeCamera::Options o;
  o.wait_for_events = true;
  FakeCamera cam(o);
  ASSERT_EQ(cam.start(), CameraStatus::kOk);
  std::thread producer([&] { cam.push_frame(FakeCamera::solid(2, 2, 3), 77); });
  FrameView f;
  const CameraStatus s = cam.next_frame(5'000'000'000, &f);
  producer.join();
  ASSERT_EQ(s, CameraStatus::kOk);
  EXPECT_EQ(f.t_exposure_ns, 77);
}

}  // namespace
