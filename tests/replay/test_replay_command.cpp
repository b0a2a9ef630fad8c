// `agvloc replay` on hostile recordings: frames that cannot be read are reported with
// their reason, a replay that read no frame fails, and the simulated time span is bounded.
#include <gtest/gtest.h>
#include <unistd.h>

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <opencv2/core.hpp>
#include <string>
#include <vector>

#include "../support/fresh_dir.hpp"
#include "../support/tag_recording.hpp"
#include "agv/config/keys.hpp"
#include "agv/recording/recording.hpp"
#include "agv/sim/imu_model.hpp"
#include "agv/sim/render.hpp"
#include "commands.hpp"
#include "replay_meta.hpp"

namespace fs = std::filesystem;
using namespace agv;

namespace {

fs::path fresh_dir(const std::string& name) {
  return test_support::fresh_dir("replaycmd", name);
}

// A 64x48 recording with `n` frames (0.1 s apart) and 100 Hz odometry over the same time.
fs::path write_recording(const std::string& name, int n) {
  const fs::path d = fresh_dir(name);
  recording::Meta m;
  m.camera = CameraModel::default_640x480();
  m.camera.intrinsics.width_px = 64;
  m.camera.intrinsics.height_px = 48;
  m.camera.intrinsics.cx = 31.5;
  m.camera.intrinsics.cy = 23.5;
  std::string err;
  EXPECT_TRUE(recording::write_meta(d.string(), m, &err)) << err;
  std::vector<recording::FrameRow> frames;
  for (int i = 0; i < n; ++i) {
    const std::string f = "frames/" + std::to_string(i) + ".png";
    EXPECT_TRUE(
        recording::write_frame_png(d.string(), f, cv::Mat(48, 64, CV_8UC1, cv::Scalar(90)), &err))
        << err;
    frames.push_back({1'000'000'000LL + i * 100'000'000LL, f});
  }
  EXPECT_TRUE(recording::write_frames_csv(d.string(), frames, &err)) << err;
  std::vector<recording::OdomRow> odom;
  for (int i = 0; i <= n * 10; ++i) odom.push_back({1'000'000'000LL + i * 10'000'000LL, 0.1, 0.0});
  EXPECT_TRUE(recording::write_odom_csv(d.string(), odom, &err)) << err;
  return d;
}

// Keeps the PNG signature and IHDR, replaces the rest: libpng itself reports the damage.
void corrupt(const fs::path& png) {
  std::string s;
  {
    std::ifstream f(png, std::ios::binary);
    s.assign(std::istreambuf_iterator<char>(f), {});
  }
  s.resize(33);
  s += std::string(40, 'x');
  std::ofstream(png, std::ios::binary | std::ios::trunc) << s;
}

struct ReplayRun {
  int rc;
  std::string err;
};

ReplayRun replay(const fs::path& rec) {
  std::vector<std::string> args = {"replay", rec.string(), "--out", (rec / "out").string(),
                                   "--fast", "--quiet"};
  std::vector<char*> argv;
  for (auto& a : args) argv.push_back(a.data());
  testing::internal::CaptureStderr();
  const int rc = agv::cmd::replay(static_cast<int>(argv.size()), argv.data());
  return {rc, testing::internal::GetCapturedStderr()};
}

}  // namespace

// All frames unreadable replayed with exit 0 and without libpng's reason.
TEST(ReplayCommand, NoReadableFrameIsAFailureAndSaysWhy) {
  const fs::path d = write_recording("allbad", 3);
  for (int i = 0; i < 3; ++i) corrupt(d / "frames" / (std::to_string(i) + ".png"));
  const ReplayRun r = replay(d);
  EXPECT_EQ(r.rc, 1) << r.err;
  EXPECT_NE(r.err.find("3 of 3 frames could not be read (last: frames.csv:4: cannot decode "
                       "'frames/2.png'"),
            std::string::npos)
      << r.err;
  EXPECT_NE(r.err.find("corrupt PNG ("), std::string::npos) << r.err;  // libpng's message
  EXPECT_EQ(r.err.find("corrupt PNG (libpng error"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("no frame of " + d.string() + " could be read"), std::string::npos) << r.err;
  fs::remove_all(d);
}

TEST(ReplayCommand, SomeUnreadableFramesAreReportedButTheRunSucceeds) {
  const fs::path d = write_recording("somebad", 3);
  corrupt(d / "frames" / "1.png");
  const ReplayRun r = replay(d);
  EXPECT_EQ(r.rc, 0) << r.err;
  EXPECT_NE(r.err.find("1 of 3 frames could not be read (last: frames.csv:3:"), std::string::npos)
      << r.err;
  fs::remove_all(d);
}

// Odometry rows at t = 1e10 and 9e18 made replay write output without end.
TEST(ReplayCommand, TimeSpanIsBoundedAndTheRowsNamed) {
  const fs::path d = write_recording("span", 1);
  std::ofstream(d / "odom.csv", std::ios::trunc)
      << "t_ns,v_mps,omega_radps\n10000000000,0,0\n9000000000000000000,0,0\n";
  ReplayRun r = replay(d);
  EXPECT_EQ(r.rc, 1) << r.err;  // beyond 2^62 ns: the recording itself is rejected
  EXPECT_NE(r.err.find("odom.csv:3: t_ns outside [0, 4611686018427387904]"), std::string::npos)
      << r.err;
  std::ofstream(d / "odom.csv", std::ios::trunc)
      << "t_ns,v_mps,omega_radps\n10000000000,0,0\n4000000000000000000,0,0\n";
  r = replay(d);
  EXPECT_EQ(r.rc, 2) << r.err;
  EXPECT_NE(r.err.find("frames.csv:2 (t_ns 1000000000) to odom.csv:3 (t_ns 4000000000000000000)"),
            std::string::npos)
      << r.err;
  EXPECT_NE(r.err.find("replay simulates at most 1000000 output periods (10000 s at this output "
                       "rate)"),
            std::string::npos)
      << r.err;
  EXPECT_FALSE(fs::exists(d / "out" / "poses.csv"));
  fs::remove_all(d);
}

// A short tag36h11 recording (vehicle standing over tag 7 at several headings): with
// landmark.family: tag36h11 and the map, every frame gives an ok fix at the true pose; with the
// default family none does, and replay names landmark.family as the likely cause (it exited 0
// with 0 fixes and no hint).
TEST(ReplayCommand, TagRecordingGivesFixes) {
  const fs::path d = fresh_dir("tag");
  recording::Meta m;
  m.camera = CameraModel::default_640x480();
  std::string err;
  ASSERT_TRUE(testsupport::write_tag_recording(
      d, m, m.camera, "id,x_mm,y_mm,heading_deg\n7,2000.0,1000.0,-90\n", &err))
      << err;
  constexpr int kFrames = testsupport::kTagFrames;
  const Pose2 vehicle = testsupport::tag_recording_vehicle();
  std::string err_text;
  auto ok_fixes = [&](const std::string& family) -> int {
    std::ofstream(d / "tag.yaml", std::ios::trunc) << "landmark:\n  family: " << family << "\n";
    std::vector<std::string> args = {
        "replay", d.string(), "--out", (d / "out").string(), "--config", (d / "tag.yaml").string(),
        "--fast", "--quiet"};
    std::vector<char*> argv;
    for (auto& a : args) argv.push_back(a.data());
    testing::internal::CaptureStderr();
    const int rc = agv::cmd::replay(static_cast<int>(argv.size()), argv.data());
    const std::string e = testing::internal::GetCapturedStderr();
    err_text = e;
    EXPECT_EQ(rc, 0) << e;
    std::ifstream f(d / "out" / "fixes.csv");
    std::string line;
    int ok = 0;
    while (std::getline(f, line)) {
      if (line.find(",ok,7,") == std::string::npos) continue;
      ++ok;
      double t, ex, ey, ephi, x, y;
      char st[8];
      EXPECT_EQ(std::sscanf(line.c_str(), "%lf,%2s,7,%lf,%lf,%lf,%lf,%lf", &t, st, &ex, &ey, &ephi,
                            &x, &y),
                7)
          << line;
      EXPECT_NEAR(x, vehicle.x_mm, 0.5) << line;
      EXPECT_NEAR(y, vehicle.y_mm, 0.5) << line;
    }
    return ok;
  };
  EXPECT_EQ(ok_fixes("tag36h11"), kFrames);
  EXPECT_EQ(err_text.find("landmark.family"), std::string::npos) << err_text;
  EXPECT_EQ(ok_fixes("qr"), 0);
  EXPECT_NE(err_text.find("no landmark fix in 5 frames ("), std::string::npos) << err_text;
  EXPECT_NE(err_text.find("is landmark.family (qr, from --config) the family printed"),
            std::string::npos)
      << err_text;
  EXPECT_NE(err_text.find("landmark.family: tag36h11"), std::string::npos) << err_text;
  fs::remove_all(d);
}

// A tag recording over tag 7 (tests/support/tag_recording.hpp).
constexpr int kTagFrames = testsupport::kTagFrames;
void write_tag_recording(const fs::path& d, const recording::Meta& m,
                         const CameraModel& truth_camera, const std::string& map_csv) {
  std::string err;
  ASSERT_TRUE(testsupport::write_tag_recording(d, m, truth_camera, map_csv, &err)) << err;
}

struct TagReplay {
  int ok = 0;
  std::string err;
};
// Replays d, with --config holding `config_yaml` unless it is empty; counts the ok fixes.
TagReplay replay_tags(const fs::path& d, const std::string& config_yaml) {
  std::vector<std::string> args = {"replay", d.string(), "--out", (d / "out").string(),
                                   "--fast", "--quiet"};
  if (!config_yaml.empty()) {
    std::ofstream(d / "c.yaml", std::ios::trunc) << config_yaml;
    args.push_back("--config");
    args.push_back((d / "c.yaml").string());
  }
  std::vector<char*> argv;
  for (auto& a : args) argv.push_back(a.data());
  testing::internal::CaptureStderr();
  const int rc = agv::cmd::replay(static_cast<int>(argv.size()), argv.data());
  TagReplay r;
  r.err = testing::internal::GetCapturedStderr();
  EXPECT_EQ(rc, 0) << r.err;
  std::ifstream f(d / "out" / "fixes.csv");
  std::string line;
  while (std::getline(f, line)) r.ok += line.find(",ok,") != std::string::npos;
  return r;
}

// meta.yaml records the family (a tag recording replayed without --config ran the QR
// pipeline, every frame "QR code unreadable", exit 0): replay runs it without --config, and a
// --config that sets another family wins, the difference printed as for the other meta keys.
TEST(ReplayCommand, TagFamilyOfMetaYamlIsUsedAndConfigWins) {
  const fs::path d = fresh_dir("tagmeta");
  recording::Meta m;
  m.camera = CameraModel::default_640x480();
  m.landmark_family = "tag36h11";
  write_tag_recording(d, m, m.camera, "id,x_mm,y_mm,heading_deg\n7,2000.0,1000.0,-90\n");
  TagReplay r = replay_tags(d, "");
  EXPECT_EQ(r.ok, kTagFrames) << r.err;
  EXPECT_EQ(r.err.find("no landmark fix"), std::string::npos) << r.err;
  r = replay_tags(d, "landmark:\n  family: qr\n");
  EXPECT_EQ(r.ok, 0) << r.err;
  EXPECT_NE(r.err.find("landmark.family: --config qr (used), meta.yaml tag36h11"),
            std::string::npos)
      << r.err;
  EXPECT_NE(r.err.find("likely cause: the family: is landmark.family (qr, from --config)"),
            std::string::npos)
      << r.err;
  // An older recording without the key: the default family, said to be the default.
  m.landmark_family.clear();
  write_tag_recording(d, m, m.camera, "id,x_mm,y_mm,heading_deg\n7,2000.0,1000.0,-90\n");
  r = replay_tags(d, "");
  EXPECT_EQ(r.ok, 0) << r.err;
  EXPECT_NE(r.err.find("landmark.family (qr, the default: neither --config nor meta.yaml sets it)"),
            std::string::npos)
      << r.err;
  fs::remove_all(d);
}

// No fix at all on a tag floor: the message names the likely cause from what the frames gave
// ("a message that names the likely cause when nothing is found"): the camera height
// (tags found, their square 6 % small: the camera is 12 mm higher than configured) or the map (tag
// 7 read, not in the map).
TEST(ReplayCommand, NoFixNamesHeightOrMapAsTheLikelyCause) {
  const fs::path d = fresh_dir("tagwhy");
  recording::Meta m;
  m.camera = CameraModel::default_640x480();
  m.landmark_family = "tag36h11";
  CameraModel higher = m.camera;
  higher.mount.height_mm += 12.0;
  write_tag_recording(d, m, higher, "id,x_mm,y_mm,heading_deg\n7,2000.0,1000.0,-90\n");
  TagReplay r = replay_tags(d, "");
  EXPECT_EQ(r.ok, 0) << r.err;
  EXPECT_NE(r.err.find("likely cause: the camera height or the print size: 5 landmarks were found "
                       "but their square measures 5.7 % smaller than landmark.size_mm 60"),
            std::string::npos)
      << r.err;
  EXPECT_NE(r.err.find("the camera is about 212 mm above the floor, not mounting.height_mm 200"),
            std::string::npos)
      << r.err;
  write_tag_recording(d, m, m.camera, "id,x_mm,y_mm,heading_deg\n8,2000.0,1000.0,-90\n");
  r = replay_tags(d, "");
  EXPECT_EQ(r.ok, 0) << r.err;
  EXPECT_NE(r.err.find("likely cause: the map: landmarks 7 were read but are not in the map"),
            std::string::npos)
      << r.err;
  fs::remove_all(d);
}

// imu.csv reaches fusion: the summary counts every sample handed over, some fused. Without the
// file it says so, and the run is otherwise the same (exit 0, the same output ticks).
TEST(ReplayCommand, GyroSamplesOfImuCsvAreFusedAndCounted) {
  const fs::path d = write_recording("gyro", 5);  // odometry 1.0 .. 1.5 s, 0.1 m/s straight
  std::vector<recording::ImuRow> imu;
  // The simulator's default gyro on a vehicle that does not turn (bias and noise only).
  for (const sim::ImuSample& g :
       sim::simulate_gyro(sim::GyroParams{}, sim::Trajectory{}, 500'000'000)) {
    imu.push_back({1'000'000'000LL + g.t_ns, g.gyro_z_radps});
  }
  std::string err;
  ASSERT_TRUE(recording::write_imu_csv(d.string(), imu, &err)) << err;
  auto slurp = [](const fs::path& p) {
    std::ifstream f(p, std::ios::binary);
    return std::string(std::istreambuf_iterator<char>(f), {});
  };
  ReplayRun r = replay(d);
  ASSERT_EQ(r.rc, 0) << r.err;
  std::string summary = slurp(d / "out" / "summary.txt");
  unsigned long long fused = 0, rejected = 0, rows = 0;
  const size_t at = summary.find("\ngyro: ");
  ASSERT_NE(at, std::string::npos) << summary;
  ASSERT_EQ(std::sscanf(summary.c_str() + at,
                        "\ngyro: %llu samples fused, %llu rejected (imu.csv: "
                        "%llu rows)",
                        &fused, &rejected, &rows),
            3)
      << summary;
  EXPECT_EQ(rows, 101u);  // 200 Hz over 0.5 s
  EXPECT_EQ(fused + rejected, rows);
  EXPECT_GT(fused, 0u);
  const std::string poses_with = slurp(d / "out" / "poses.csv");

  fs::remove(d / "imu.csv");
  r = replay(d);
  ASSERT_EQ(r.rc, 0) << r.err;
  summary = slurp(d / "out" / "summary.txt");
  EXPECT_NE(summary.find("\ngyro: none (no imu.csv: wheel odometry only)\n"), std::string::npos)
      << summary;
  const std::string poses_without = slurp(d / "out" / "poses.csv");
  EXPECT_EQ(std::count(poses_with.begin(), poses_with.end(), '\n'),
            std::count(poses_without.begin(), poses_without.end(), '\n'));
  fs::remove_all(d);
}

// Replay took the camera from meta.yaml and silently ignored a calibrated mounting in
// --config (70 fused / 652 gated, no warning). Now what --config sets is used, meta.yaml gives
// the rest, and every value that differs is printed with both values.
TEST(ReplayCommand, ConfigOverMetaYamlIsOneRuleAndEachDifferenceIsPrinted) {
  for (const auto& k : app::meta_keys()) EXPECT_NE(config::find_key(k), nullptr) << k;

  recording::Meta meta;
  meta.camera = CameraModel::default_640x480();
  meta.camera.mount.yaw_rad = deg_to_rad(1.0);
  meta.camera.mount.offset_x_mm = 250.0;
  meta.landmark_size_mm = 60.0;
  config::Config cfg;
  std::vector<std::string> errors;
  ASSERT_TRUE(
      config::parse_config("mounting: {yaw_deg: 1.2057, height_mm: 200}\n"
                           "landmark: {size_mm: 60.6}\n",
                           "", &cfg, &errors, config::ConfigUse::kReplay));
  std::vector<std::string> lines;
  std::string err;
  ASSERT_TRUE(app::apply_recording_meta(
      meta, {"mounting.yaw_deg", "mounting.height_mm", "landmark.size_mm"}, "c.yaml", &cfg, &lines,
      &err))
      << err;
  EXPECT_NEAR(rad_to_deg(cfg.camera_model.mount.yaw_rad), 1.2057, 1e-12);  // --config's
  EXPECT_EQ(cfg.landmark_size_mm, 60.6);
  EXPECT_EQ(cfg.camera_model.mount.offset_x_mm, 250.0);  // not in --config: meta.yaml's
  EXPECT_EQ(cfg.camera_model.intrinsics.fx, meta.camera.intrinsics.fx);
  ASSERT_EQ(lines.size(), 2u);  // height_mm is the same in both: no line
  EXPECT_EQ(lines[0], "mounting.yaw_deg: --config 1.2057 (used), meta.yaml 1");
  EXPECT_EQ(lines[1], "landmark.size_mm: --config 60.6 (used), meta.yaml 60");

  // Without --config the recording describes its own camera.
  config::Config none;
  lines.clear();
  ASSERT_TRUE(app::apply_recording_meta(meta, {}, "", &none, &lines, &err));
  EXPECT_TRUE(lines.empty());
  EXPECT_EQ(none.camera_model.mount.yaw_rad, meta.camera.mount.yaw_rad);
  EXPECT_EQ(none.camera_model.intrinsics.width_px, 640);

  // The command: the lines on stderr and in summary.txt; another image size is refused.
  const fs::path d = write_recording("precedence", 3);  // meta: 64x48, fx 769.23, height 200
  auto run = [&](const std::string& yaml) {
    std::ofstream(d / "c.yaml", std::ios::trunc) << yaml;
    std::vector<std::string> args = {
        "replay", d.string(), "--out", (d / "out").string(), "--config", (d / "c.yaml").string(),
        "--fast", "--quiet"};
    std::vector<char*> argv;
    for (auto& a : args) argv.push_back(a.data());
    testing::internal::CaptureStderr();
    const int rc = agv::cmd::replay(static_cast<int>(argv.size()), argv.data());
    return ReplayRun{rc, testing::internal::GetCapturedStderr()};
  };
  ReplayRun r = run("intrinsics: {fx: 150, cx: 31.5}\nmounting: {offset_x_mm: 5}\n");
  ASSERT_EQ(r.rc, 0) << r.err;
  EXPECT_NE(r.err.find("replay: intrinsics.fx: --config 150 (used), meta.yaml 769.230769\n"),
            std::string::npos)
      << r.err;
  EXPECT_NE(r.err.find("replay: mounting.offset_x_mm: --config 5 (used), meta.yaml 0\n"),
            std::string::npos)
      << r.err;
  EXPECT_EQ(r.err.find("intrinsics.cx"), std::string::npos) << r.err;  // equal: no line
  std::ifstream f(d / "out" / "summary.txt");
  const std::string summary((std::istreambuf_iterator<char>(f)), {});
  EXPECT_NE(summary.find("camera from --config over meta.yaml: intrinsics.fx: --config 150"),
            std::string::npos)
      << summary;

  r = run("loop: {output_rate_hz: 50}\n");  // no camera key: nothing to say
  ASSERT_EQ(r.rc, 0) << r.err;
  EXPECT_EQ(r.err.find("(used)"), std::string::npos) << r.err;

  r = run("camera: {width: 640, height: 48}\n");
  EXPECT_EQ(r.rc, 2);
  EXPECT_NE(r.err.find("replay: camera.width: " + (d / "c.yaml").string() +
                       " sets 640, the recording's meta.yaml 64: the frames are 64x48 px"),
            std::string::npos)
      << r.err;
  fs::remove_all(d);
}
