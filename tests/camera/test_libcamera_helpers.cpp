#include <gtest/gtest.h>

#include <thread>

#include "agv/libcamera/completion_queue.hpp"
#include "agv/libcamera/libcamera_camera.hpp"

namespace {

using agv::libcam::CameraInfo;
using Queue = agv::libcam::CompletionQueue<int>;

TEST(LibcameraSelect, ByIdModelOrFirst) {
  const std::vector<CameraInfo> cams = {
      {"/base/a", "imx219"}, {"/base/b", "imx296"}, {"/base/c", "imx296"}};
  EXPECT_EQ(agv::libcam::select_camera(cams, "", ""), 0);
  EXPECT_EQ(agv::libcam::select_camera(cams, "/base/c", ""), 2);
  EXPECT_EQ(agv::libcam::select_camera(cams, "", "imx296"), 1);
  EXPECT_EQ(agv::libcam::select_camera(cams, "/base/c", "imx296"), 2);
  EXPECT_EQ(agv::libcam::select_camera(cams, "/base/a", "imx296"), -1);  // both must agree
  EXPECT_EQ(agv::libcam::select_camera(cams, "/base/x", ""), -1);
  EXPECT_EQ(agv::libcam::select_camera({}, "", ""), -1);
}

TEST(CompletionQueue, NewestWinsAndEvictedAreRecycled) {
  Queue q(1);
  q.push(1);
  q.push(2);
  q.push(3);
  int got = 0;
  std::vector<int> recycle;
  ASSERT_EQ(q.pop(0, &got, &recycle), Queue::Result::kItem);
  EXPECT_EQ(got, 3);
  EXPECT_EQ(recycle, (std::vector<int>{1, 2}));
  EXPECT_EQ(q.dropped(), 2u);
  recycle.clear();
  EXPECT_EQ(q.pop(0, &got, &recycle), Queue::Result::kTimeout);
  EXPECT_TRUE(recycle.empty());
}

TEST(CompletionQueue, CapacityTwoKeepsOrder) {
  Queue q(2);
  q.push(1);
  q.push(2);
  int got = 0;
  std::vector<int> recycle;
  ASSERT_EQ(q.pop(0, &got, &recycle), Queue::Result::kItem);
  EXPECT_EQ(got, 1);
  ASSERT_EQ(q.pop(0, &got, &recycle), Queue::Result::kItem);
  EXPECT_EQ(got, 2);
  EXPECT_EQ(q.dropped(), 0u);
}

TEST(CompletionQueue, DisconnectWakesWaiter) {
  Queue q(1);
  std::thread t([&] { q.set_disconnected(); });
  int got = 0;
  std::vector<int> recycle;
  EXPECT_EQ(q.pop(10'000'000'000, &got, &recycle), Queue::Result::kDisconnected);
  t.join();
  EXPECT_TRUE(q.disconnected());
  q.reset();
  EXPECT_FALSE(q.disconnected());
}

TEST(CompletionQueue, PushFromAnotherThreadIsReceived) {
  Queue q(1);
  std::thread t([&] { q.push(42); });
  int got = 0;
  std::vector<int> recycle;
  EXPECT_EQ(q.pop(10'000'000'000, &got, &recycle), Queue::Result::kItem);
  EXPECT_EQ(got, 42);
  t.join();
  q.push(7);
  EXPECT_EQ(q.drain(), std::vector<int>{7});
}

TEST(LibcameraCamera, InvalidConfigRejectedBeforeTouchingLibcamera) {
  agv::hal::CameraConfig c;
  c.exposure_us = 0;
  agv::libcam::LibcameraCamera cam(c);
  EXPECT_EQ(cam.start(), agv::hal::CameraStatus::kInvalidArgument);
  EXPECT_NE(std::string(cam.last_error()).find("exposure_us"), std::string::npos);
  agv::hal::FrameView f;
  EXPECT_EQ(cam.next_frame(0, &f), agv::hal::CameraStatus::kNotStarted);
}

TEST(LibcameraCamera, UnknownCameraIsDisconnected) {
  agv::hal::CameraConfig c;
  c.id = "/no/such/camera";
  agv::libcam::LibcameraCamera cam(c);
  EXPECT_EQ(cam.start(), agv::hal::CameraStatus::kDisconnected);
  EXPECT_NE(std::string(cam.last_error()).find("/no/such/camera"), std::string::npos);
  cam.stop();
}

}  // namespace
