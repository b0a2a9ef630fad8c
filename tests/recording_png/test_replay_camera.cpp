#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>

#include "agv/recording/png_io.hpp"
#include "agv/recording/recording.hpp"
#include "agv/recording/replay_camera.hpp"

using namespace agv;

namespace {

recording::Recording make_rec(const std::string& dir, int n) {
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir + "/frames");
  recording::Recording rec;
  rec.dir = dir;
  rec.meta.camera = CameraModel::default_640x480();
  rec.meta.camera.intrinsics.width_px = 32;
  rec.meta.camera.intrinsics.height_px = 24;
  for (int i = 0; i < n; ++i) {
    const std::string f = "frames/" + std::to_string(i) + ".png";
    std::string err;
    EXPECT_TRUE(png::write(dir + "/" + f, cv::Mat(24, 32, CV_8UC1, cv::Scalar(i)), &err)) << err;
    rec.frames.push_back({1'000'000'000LL + i * 33'000'000LL, f});
  }
  return rec;
}

}  // namespace

TEST(ReplayCamera, DeliversFramesInOrderWithTheirTimes) {
  const auto rec = make_rec("/tmp/agv_replay_cam_a", 5);
  recording::ReplayCamera cam(rec, nullptr);
  hal::FrameView f;
  EXPECT_EQ(cam.next_frame(0, &f), hal::CameraStatus::kNotStarted);
  ASSERT_EQ(cam.start(), hal::CameraStatus::kOk);
  for (int i = 0; i < 5; ++i) {
    ASSERT_EQ(cam.next_frame(0, &f), hal::CameraStatus::kOk);
    EXPECT_EQ(f.t_exposure_ns, rec.frames[static_cast<size_t>(i)].t_ns);
    EXPECT_EQ(f.data[0], i);
    EXPECT_EQ(f.width_px, 32);
    cam.release(f);
  }
  EXPECT_EQ(cam.next_frame(0, &f), hal::CameraStatus::kEndOfStream);
  EXPECT_EQ(cam.stats().frames_delivered, 5u);
}

TEST(ReplayCamera, HeldBuffersStarveLikeALiveDriver) {
  const auto rec = make_rec("/tmp/agv_replay_cam_b", 5);
  recording::ReplayCamera cam(rec, nullptr);
  cam.start();
  hal::FrameView f[3];
  for (auto& x : f) ASSERT_EQ(cam.next_frame(0, &x), hal::CameraStatus::kOk);  // none released
  hal::FrameView g;
  ASSERT_EQ(cam.next_frame(0, &g), hal::CameraStatus::kEndOfStream);  // 2 frames found no buffer
  EXPECT_EQ(cam.stats().frames_dropped, 2u);
  EXPECT_EQ(f[0].data[0], 0);  // held frames were not overwritten
  EXPECT_EQ(f[2].data[0], 2);
}

TEST(ReplayCamera, CorruptFramesAreSkippedAndReportedStallsWithheld) {
  auto rec = make_rec("/tmp/agv_replay_cam_c", 6);
  std::ofstream(rec.dir + "/" + rec.frames[1].file, std::ios::trunc) << "garbage";
  recording::ReplayCamera cam(rec, nullptr);
  cam.set_stall(rec.frames[3].t_ns, rec.frames[5].t_ns);  // withholds frames 3 and 4
  cam.start();
  std::vector<int> seen;
  hal::FrameView f;
  while (cam.next_frame(0, &f) == hal::CameraStatus::kOk) {
    seen.push_back(f.data[0]);
    cam.release(f);
  }
  EXPECT_EQ(seen, (std::vector<int>{0, 2, 5}));
  EXPECT_EQ(cam.stats().errors, 1u);
  EXPECT_NE(std::string(cam.last_error()).find("1.png"), std::string::npos);
}
