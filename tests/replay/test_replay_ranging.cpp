// `agvloc replay` with the second camera (ranging_camera.*): a vehicle standing with no floor
// landmark in view and two rack landmarks in view of the second camera (frames rendered by the
// site renderer) is localized from the recording's ranging/ stream; without the section it stays
// unlocalized; a missing stream is a named error, unreadable frames are skipped and counted.
#include <gtest/gtest.h>
#include <unistd.h>

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include "../support/fresh_dir.hpp"
#include "agv/recording/recording.hpp"
#include "agv/sim/ranging_camera.hpp"
#include "agv/sim/site_render.hpp"
#include "agv/site/site_file.hpp"
#include "commands.hpp"

namespace fs = std::filesystem;
using namespace agv;

namespace {

constexpr std::int64_t kT0 = 1'000'000'000;
constexpr std::int64_t kFramePeriodNs = 66'666'667;  // 15 fps
constexpr int kFrames = 10;
const Pose2 kTruth{1000.0, 2000.0, 0.0};

CameraIntrinsics ranging_intrinsics() {
  return {.width_px = 640, .height_px = 400, .fx = 400.0, .fy = 400.0, .cx = 319.5, .cy = 199.5};
}

ranging::RangingMount ranging_mount() { return {.x_mm = 300.0, .z_mm = 1000.0}; }

// A rack face 2.5 m ahead with two 150 mm tags 3 m apart, 62 deg apart as seen from the truth.
sim::SiteScene scene() {
  sim::SiteScene s;
  s.site.name = "test hall";
  s.site.outline.vertices_mm = {{0, 0}, {6000, 0}, {6000, 5000}, {0, 5000}};
  site::Obstacle rack;
  rack.id = "rack";
  rack.outline.vertices_mm = {{3500, 100}, {4500, 100}, {4500, 4900}, {3500, 4900}};
  rack.height_mm = 2500.0;
  s.site.obstacles.push_back(rack);
  s.site.wall_landmarks.push_back(
      {3, site::LandmarkFamily::kTag36h11, 3500.0, 500.0, 1000.0, kPi, 150.0});
  s.site.wall_landmarks.push_back(
      {7, site::LandmarkFamily::kTag36h11, 3500.0, 3500.0, 1100.0, kPi, 150.0});
  return s;
}

fs::path fresh_dir(const std::string& name) { return test_support::fresh_dir("replayrng", name); }

// Floor frames of bare floor (no landmark), odometry standing still, the second camera's frames
// rendered at the truth, the site file and a configuration enabling the second camera.
fs::path write_recording(const std::string& name) {
  const fs::path d = fresh_dir(name);
  std::string err;
  recording::Meta m;
  m.camera = CameraModel::default_640x480();
  m.camera.intrinsics.width_px = 64;
  m.camera.intrinsics.height_px = 48;
  m.camera.intrinsics.cx = 31.5;
  m.camera.intrinsics.cy = 23.5;
  EXPECT_TRUE(recording::write_meta(d.string(), m, &err)) << err;
  const sim::SiteScene sc = scene();
  const sim::SiteFrameRenderer renderer(ranging_intrinsics());
  std::vector<recording::FrameRow> floor, ranging;
  for (int i = 0; i < kFrames; ++i) {
    const std::int64_t t = kT0 + i * kFramePeriodNs;
    const std::string f = "frames/" + std::to_string(i) + ".png";
    EXPECT_TRUE(
        recording::write_frame_png(d.string(), f, cv::Mat(48, 64, CV_8UC1, cv::Scalar(90)), &err));
    floor.push_back({t, f});
    const sim::RenderResult r =
        renderer.render(sc, sim::ranging_camera(ranging_intrinsics(), kTruth, ranging_mount()),
                        sim::SiteRenderParams{}, 100 + static_cast<std::uint64_t>(i));
    const std::string rf = std::to_string(i) + ".png";
    EXPECT_TRUE(recording::write_frame_png((d / "ranging").string(), rf, r.image, &err)) << err;
    ranging.push_back({t + 5'000'000, rf});
  }
  EXPECT_TRUE(recording::write_frames_csv(d.string(), floor, &err)) << err;
  EXPECT_TRUE(recording::write_frames_csv((d / "ranging").string(), ranging, &err)) << err;
  std::vector<recording::OdomRow> odom;
  for (std::int64_t t = kT0 - 20'000'000; t <= kT0 + 800'000'000; t += 10'000'000) {
    odom.push_back({t, 0.0, 0.0});
  }
  EXPECT_TRUE(recording::write_odom_csv(d.string(), odom, &err)) << err;
  std::ofstream(d / "site.yaml") << site::write_site(sc.site);
  std::ofstream(d / "ranging.yaml") << "ranging_camera:\n"
                                       "  enabled: true\n"
                                       "  site: site.yaml\n"
                                       "  width: 640\n"
                                       "  height: 400\n"
                                       "  intrinsics: {fx: 400, fy: 400, cx: 319.5, cy: 199.5}\n"
                                       "  mount: {x_mm: 300, z_mm: 1000}\n";
  return d;
}

struct ReplayRun {
  int rc;
  std::string out, err;
};

ReplayRun replay(const fs::path& rec, bool with_config, bool realtime = false) {
  std::vector<std::string> args = {
      "replay", rec.string(), "--out", (rec / "out").string(), realtime ? "--realtime" : "--fast",
      "--quiet"};
  if (with_config) {
    args.push_back("--config");
    args.push_back((rec / "ranging.yaml").string());
  }
  std::vector<char*> argv;
  for (auto& a : args) argv.push_back(a.data());
  testing::internal::CaptureStdout();
  testing::internal::CaptureStderr();
  const int rc = agv::cmd::replay(static_cast<int>(argv.size()), argv.data());
  const std::string err = testing::internal::GetCapturedStderr();
  return {rc, testing::internal::GetCapturedStdout(), err};
}

struct Pose {
  std::int64_t t_ns;
  double x_mm, y_mm, theta_deg;
};

// The valid rows of poses.csv (t_ns,valid,health,x_mm,y_mm,theta_deg,...).
std::vector<Pose> valid_poses(const fs::path& rec) {
  std::ifstream f(rec / "out" / "poses.csv");
  std::vector<Pose> out;
  std::string line;
  std::getline(f, line);
  while (std::getline(f, line)) {
    long long t = 0;
    int valid = 0, health = 0;
    double x = 0, y = 0, th = 0;
    if (std::sscanf(line.c_str(), "%lld,%d,%d,%lf,%lf,%lf", &t, &valid, &health, &x, &y, &th) ==
            6 &&
        valid == 1) {
      out.push_back({t, x, y, th});
    }
  }
  return out;
}

TEST(ReplayRanging, TwoRackLandmarksLocalizeAVehicleWithNoFloorLandmark) {
  const fs::path d = write_recording("two");
  const ReplayRun r = replay(d, true);
  ASSERT_EQ(r.rc, 0) << r.err;
  EXPECT_NE(r.out.find("ranging camera: 10 frames"), std::string::npos) << r.out;
  const std::vector<Pose> poses = valid_poses(d);
  ASSERT_FALSE(poses.empty()) << r.out << r.err;
  const Pose& first = poses.front();
  const Pose& last = poses.back();
  const double err_mm = std::hypot(last.x_mm - kTruth.x_mm, last.y_mm - kTruth.y_mm);
  std::printf("localized %.0f ms after the first frame; last pose %.1f mm, %.3f deg off\n",
              static_cast<double>(first.t_ns - kT0) / 1e6, err_mm, last.theta_deg);
  EXPECT_LE(first.t_ns - kT0, 1'000'000'000);
  EXPECT_LT(err_mm, 50.0);
  EXPECT_LT(std::abs(last.theta_deg), 1.0);
  fs::remove_all(d);
}

// --realtime runs the threads of `agvloc run`: the second stream is a camera of its own, read by
// the ranging worker with the output thread's pose as the prior. Every frame is read (the replay
// camera does not drop), and the vehicle is localized as in --fast.
TEST(ReplayRanging, RealtimeReadsTheSecondCameraInItsOwnThread) {
  const fs::path d = write_recording("realtime");
  const ReplayRun r = replay(d, true, true);
  ASSERT_EQ(r.rc, 0) << r.err;
  EXPECT_NE(r.out.find("ranging camera: 10 frames"), std::string::npos) << r.out;
  EXPECT_EQ(r.err.find("replayed by --fast only"), std::string::npos) << r.err;
  EXPECT_NE(r.out.find("ranging camera: CPU per frame mean"), std::string::npos) << r.out;
  const std::vector<Pose> poses = valid_poses(d);
  ASSERT_FALSE(poses.empty()) << r.out << r.err;
  const Pose& last = poses.back();
  EXPECT_LT(std::hypot(last.x_mm - kTruth.x_mm, last.y_mm - kTruth.y_mm), 50.0);
  EXPECT_LT(std::abs(last.theta_deg), 1.0);
  fs::remove_all(d);
}

TEST(ReplayRanging, WithoutTheSectionTheStreamIsNotReadAndTheVehicleStaysLost) {
  const fs::path d = write_recording("off");
  const ReplayRun r = replay(d, false);
  ASSERT_EQ(r.rc, 0) << r.err;
  EXPECT_EQ(r.out.find("ranging camera:"), std::string::npos) << r.out;
  EXPECT_TRUE(valid_poses(d).empty());
  fs::remove_all(d);
}

TEST(ReplayRanging, MissingStreamIsANamedErrorUnreadableFramesAreCounted) {
  const fs::path d = write_recording("bad");
  fs::rename(d / "ranging" / "frames.csv", d / "ranging" / "frames.old");
  ReplayRun r = replay(d, true);
  EXPECT_EQ(r.rc, 1);
  EXPECT_NE(r.err.find("ranging/frames.csv: "), std::string::npos) << r.err;
  fs::rename(d / "ranging" / "frames.old", d / "ranging" / "frames.csv");
  // Two images damaged: skipped and counted, the others still localize.
  for (const char* f : {"0.png", "4.png"}) std::ofstream(d / "ranging" / f) << "not a png";
  r = replay(d, true);
  EXPECT_EQ(r.rc, 0) << r.err;
  EXPECT_NE(r.out.find("ranging camera: 8 frames"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("2 unreadable"), std::string::npos) << r.out;
  EXPECT_FALSE(valid_poses(d).empty());
  fs::remove_all(d);
}

}  // namespace

TEST(ReplayRanging, ABrokenSiteFileIsANamedErrorAndNothingIsReplayed) {
  const fs::path d = write_recording("badsite");
  std::ofstream(d / "site.yaml") << "site: {name: [\n";
  ReplayRun r = replay(d, true);
  EXPECT_EQ(r.rc, 2) << r.err;
  EXPECT_NE(r.err.find("ranging_camera.site: "), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("site.yaml"), std::string::npos) << r.err;
  EXPECT_TRUE(valid_poses(d).empty());
  fs::remove_all(d / "out");
  fs::remove(d / "site.yaml");
  r = replay(d, true);
  EXPECT_EQ(r.rc, 2) << r.err;
  EXPECT_NE(r.err.find("ranging_camera.site: "), std::string::npos) << r.err;
  fs::remove_all(d);
}
