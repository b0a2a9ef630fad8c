// agvloc-overhead detect on a live camera (overhead/src/detect_live.cpp), scripted: each frame's
// tags reach the publisher in order with the frame's exposure stamp, a frame that is not the
// camera's size is refused without a message, and every frame is either detected, refused or
// replaced by a newer one (never silently lost).
#include <gtest/gtest.h>

#include <algorithm>
#include <atomic>
#include <string>
#include <vector>

#include "agv/fakecamera/fake_camera.hpp"
#include "agv/posix/posix_clock.hpp"
#include "detect.hpp"
#include "two_camera_frames.hpp"

namespace agv::overhead_app {
namespace {

constexpr std::int64_t kFramePeriodNs = 50'000'000;
constexpr int kFrames = 8;

struct Published {
  std::vector<std::uint64_t> seq;
  std::vector<std::int64_t> t_ns;
  std::vector<std::vector<std::uint32_t>> ids;
};

TEST(OverheadDetectLive, TagsOfEachFrameArePublishedWithItsStampAndABadFrameIsRefused) {
  const site::Site s = test::two_camera_site();
  const std::vector<sim::AgvState> agvs = test::two_vehicles();
  posix::PosixClock clock;
  const fakecamera::FakeCamera::Options opt = test::scripted_camera(&clock);
  auto fake = std::make_unique<fakecamera::FakeCamera>(opt);
  const fakecamera::FakeImage img = test::render_fake_frame(s, 0, agvs);
  const std::int64_t t0 = monotonic_ns();
  std::vector<std::int64_t> pushed;
  for (int k = 0; k < kFrames; ++k) {
    fake->push_stall(kFramePeriodNs);
    pushed.push_back(t0 + (k + 1) * kFramePeriodNs);
    if (k == kFrames - 1) {  // last: nothing newer can replace it
      fake->push_frame(fakecamera::FakeCamera::solid(64, 48, 128), pushed.back());
    } else {
      fake->push_frame(img, pushed.back());
    }
  }
  LiveCamera cam{s.cameras[0].id, 0, std::move(fake)};
  CameraDetector det(s, OverheadConfig{}, 0);
  Published got;
  const std::atomic<bool> stop{false};
  const LiveDetectCounters n = run_detect_live(
      &cam, &det,
      [&got, &s](const overhead::DetectionMsg& m) {
        got.seq.push_back(m.seq);
        got.t_ns.push_back(m.t_ns);
        got.ids.emplace_back();
        for (const overhead::MsgTag& t : m.tags) got.ids.back().push_back(t.tag.id);
        EXPECT_EQ(m.camera_id, s.cameras[0].id);
      },
      stop, 20'000'000'000);

  EXPECT_EQ(n.frames_refused, 1u);
  EXPECT_EQ(n.frames_detected + n.frames_refused + n.frames_replaced,
            static_cast<std::uint64_t>(kFrames));
  ASSERT_EQ(got.seq.size(), n.frames_detected);
  ASSERT_GE(got.seq.size(), 1u);
  for (std::size_t i = 0; i < got.seq.size(); ++i) {
    EXPECT_EQ(got.seq[i], i + 1);  // numbers only for messages: a gap is a lost message
    EXPECT_NE(std::find(pushed.begin(), pushed.end(), got.t_ns[i]), pushed.end());
    EXPECT_NE(got.t_ns[i], pushed.back());  // the refused frame
    if (i > 0) {
      EXPECT_GT(got.t_ns[i], got.t_ns[i - 1]);
    }
    ASSERT_EQ(got.ids[i].size(), 1u) << i;  // the vehicle under this camera, nothing else
    EXPECT_EQ(got.ids[i][0], s.fleet[0].tag_id) << i;
  }
  EXPECT_EQ(det.frames(), n.frames_detected);
  EXPECT_EQ(n.health.frames, static_cast<std::uint64_t>(kFrames));
  EXPECT_NE(cam.camera, nullptr);  // handed back
}

TEST(OverheadDetectLive, DetectorRefusesAFrameOfAnotherSizeWithoutUsingANumber) {
  const site::Site s = test::two_camera_site();
  CameraDetector det(s, OverheadConfig{}, 0);
  std::string err;
  EXPECT_EQ(det.detect(1000, cv::Mat(48, 64, CV_8UC1, cv::Scalar(128)), &err), nullptr);
  EXPECT_NE(err.find("8-bit gray"), std::string::npos) << err;
  const fakecamera::FakeImage img = test::render_fake_frame(s, 0, test::two_vehicles());
  const cv::Mat gray(img.height_px, img.width_px, CV_8UC1,
                     const_cast<std::uint8_t*>(img.gray.data()));
  const overhead::DetectionMsg* m = det.detect(2000, gray, &err);
  ASSERT_NE(m, nullptr) << err;
  EXPECT_EQ(m->seq, 1u);
  EXPECT_EQ(m->t_ns, 2000);
  EXPECT_EQ(det.frames(), 1u);
}

TEST(OverheadDetectLive, StopEndsTheLoopOfACameraThatDeliversNothing) {
  const site::Site s = test::two_camera_site();
  fakecamera::FakeCamera::Options opt;  // empty script, no end of stream: kTimeout forever
  LiveCamera cam{s.cameras[0].id, 0, std::make_unique<fakecamera::FakeCamera>(opt)};
  CameraDetector det(s, OverheadConfig{}, 0);
  const std::atomic<bool> stop{true};
  int published = 0;
  const LiveDetectCounters n = run_detect_live(
      &cam, &det, [&published](const overhead::DetectionMsg&) { ++published; }, stop, 0);
  EXPECT_EQ(n.frames_detected, 0u);
  EXPECT_EQ(published, 0);
}

}  // namespace
}  // namespace agv::overhead_app
