// `agvloc-desk sim` end to end: writes a recording the strict reader accepts, with truth at every
// frame time, deterministic for a seed.
#include <ZXing/ReadBarcode.h>
#include <gtest/gtest.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <opencv2/imgcodecs.hpp>
#include <sstream>

#include "../support/desk_command.hpp"
#include "agv/recording/recording.hpp"
#include "agv/sim/render.hpp"
#include "agv/vision/landmark_localizer.hpp"
#include "commands.hpp"

namespace fs = std::filesystem;
using namespace agv;

namespace {

int run_sim(std::vector<std::string> args) {
  return testsupport::run_command(desk::sim, "sim", std::move(args));
}

std::string slurp(const fs::path& p) {
  std::ifstream f(p, std::ios::binary);
  std::ostringstream s;
  s << f.rdbuf();
  return s.str();
}

// The sim's arguments: `common`, then --out `out`, then `extra`.
std::vector<std::string> sim_args(std::vector<std::string> common, const fs::path& out,
                                  const std::vector<std::string>& extra) {
  common.insert(common.end(), {"--out", out.string()});
  common.insert(common.end(), extra.begin(), extra.end());
  return common;
}

fs::path tmp(const std::string& name) {
  const fs::path d =
      fs::temp_directory_path() / ("agv_test_simcmd_" + std::to_string(::getpid()) + "_" + name);
  fs::remove_all(d);
  return d;
}

}  // namespace

TEST(SimCommand, WritesValidDeterministicRecording) {
  const fs::path a = tmp("a"), b = tmp("b"), c = tmp("c");
  const std::vector<std::string> common = {"--duration-s", "1.0",     "--fps",     "10",
                                           "--trajectory", "figure8", "--degrade", "realistic"};
  auto with = [&](const fs::path& out, const std::string& seed) {
    return sim_args(common, out, {"--seed", seed});
  };
  ASSERT_EQ(run_sim(with(a, "3")), 0);
  ASSERT_EQ(run_sim(with(b, "3")), 0);
  ASSERT_EQ(run_sim(with(c, "4")), 0);
  recording::Recording r;
  std::string err;
  ASSERT_TRUE(recording::read_recording(a.string(), &r, &err)) << err;
  EXPECT_EQ(r.frames.size(), 11u);
  EXPECT_EQ(r.odom.size(), 101u);
  ASSERT_TRUE(r.has_truth);
  EXPECT_EQ(r.meta.camera.intrinsics.width_px, 640);
  // Truth has a row at every frame time.
  for (const auto& f : r.frames) {
    bool found = false;
    for (const auto& t : r.truth) found = found || t.t_ns == f.t_ns;
    EXPECT_TRUE(found) << f.t_ns;
  }
  // Odometry reports about the true speed after the ramp (0.5 m/s, 1 % scale error).
  EXPECT_NEAR(r.odom.back().v_mps, 0.505, 0.02);
  // Same seed, same bytes; another seed, other noise.
  for (const char* f : {"frames.csv", "odom.csv", "truth.csv", "frames/000007.png"}) {
    EXPECT_EQ(slurp(a / f), slurp(b / f)) << f;
  }
  EXPECT_NE(slurp(a / "frames/000007.png"), slurp(c / "frames/000007.png"));
  EXPECT_NE(slurp(a / "odom.csv"), slurp(c / "odom.csv"));
  // Refuses to overwrite without --force.
  EXPECT_EQ(run_sim(with(a, "3")), 2);
  std::vector<std::string> forced = with(a, "3");
  forced.push_back("--force");
  EXPECT_EQ(run_sim(forced), 0);
  for (const auto& d : {a, b, c}) fs::remove_all(d);
}

// The recording says which odometry sample timing it was made with (default: period mean).
TEST(SimCommand, RecordsOdometrySampleTiming) {
  const fs::path a = tmp("timing_default"), b = tmp("timing_instant");
  const std::vector<std::string> common = {"--duration-s", "0.1", "--fps", "10"};
  auto with = [&](const fs::path& out, const std::vector<std::string>& extra) {
    return sim_args(common, out, extra);
  };
  ASSERT_EQ(run_sim(with(a, {})), 0);
  ASSERT_EQ(run_sim(with(b, {"--odom-sample", "instant", "--misprint", "8:300:0"})), 0);
  recording::Recording ra, rb;
  std::string err;
  ASSERT_TRUE(recording::read_recording(a.string(), &ra, &err)) << err;
  ASSERT_TRUE(recording::read_recording(b.string(), &rb, &err)) << err;
  EXPECT_NE(ra.meta.source.find("(odometry samples: period_mean)"), std::string::npos)
      << ra.meta.source;
  EXPECT_NE(rb.meta.source.find("(odometry samples: instant)"), std::string::npos)
      << rb.meta.source;
  // During the start ramp the period mean lags the instantaneous speed by half a period.
  ASSERT_GE(ra.odom.size(), 5u);
  EXPECT_NEAR(rb.odom[4].v_mps - ra.odom[4].v_mps, 0.5 * 0.5 * 0.01 * 1.01, 1e-6);
  for (const auto& d : {a, b}) fs::remove_all(d);
}

// imu.csv: written by default (200 Hz industrial gyro, seeded), with the gyro's own rate and
// stamps when set, and not at all with --no-gyro (also not left over by --force).
TEST(SimCommand, WritesImuCsvUnlessNoGyro) {
  const fs::path a = tmp("gyro_a"), b = tmp("gyro_b"), c = tmp("gyro_c");
  const std::vector<std::string> common = {"--duration-s", "0.5",   "--fps", "5",
                                           "--trajectory", "circle"};
  auto with = [&](const fs::path& out, const std::vector<std::string>& extra) {
    return sim_args(common, out, extra);
  };
  ASSERT_EQ(run_sim(with(a, {})), 0);
  ASSERT_EQ(run_sim(with(b, {})), 0);
  recording::Recording r;
  std::string err;
  ASSERT_TRUE(recording::read_recording(a.string(), &r, &err)) << err;
  ASSERT_TRUE(r.has_imu);
  ASSERT_EQ(r.imu.size(), 101u);                       // 200 Hz over 0.5 s, both ends
  EXPECT_EQ(r.imu.front().t_ns, r.odom.front().t_ns);  // the same clock, no latency by default
  EXPECT_EQ(r.imu[1].t_ns - r.imu[0].t_ns, 5'000'000);
  // Standing at first: the 0.2 deg/s bias plus noise (sigma 0.14 deg/s per sample).
  EXPECT_LT(std::abs(r.imu.front().gyro_z_radps), deg_to_rad(1.0));
  EXPECT_EQ(slurp(a / "imu.csv"), slurp(b / "imu.csv"));  // seeded
  // Own rate and latency; the other files do not change with the gyro's settings.
  ASSERT_EQ(run_sim(with(c, {"--gyro-hz", "100", "--gyro-latency-ms", "3", "--gyro-range-dps", "1",
                             "--gyro-bias-dps", "5"})),
            0);
  ASSERT_TRUE(recording::read_recording(c.string(), &r, &err)) << err;
  ASSERT_EQ(r.imu.size(), 51u);
  EXPECT_EQ(r.imu.front().t_ns, r.odom.front().t_ns + 3'000'000);
  for (const auto& row : r.imu) EXPECT_NEAR(row.gyro_z_radps, deg_to_rad(1.0), 1e-10);  // clipped
  for (const char* f : {"odom.csv", "truth.csv", "frames.csv", "frames/000002.png"}) {
    EXPECT_EQ(slurp(a / f), slurp(c / f)) << f;
  }
  // --no-gyro: no imu.csv, and --force does not leave the old one behind.
  ASSERT_EQ(run_sim(with(c, {"--no-gyro", "--force"})), 0);
  EXPECT_FALSE(fs::exists(c / "imu.csv"));
  ASSERT_TRUE(recording::read_recording(c.string(), &r, &err)) << err;
  EXPECT_FALSE(r.has_imu);
  EXPECT_EQ(slurp(a / "odom.csv"), slurp(c / "odom.csv"));
  EXPECT_EQ(run_sim(with(tmp("gyro_bad"), {"--gyro-hz", "0"})), 2);
  EXPECT_EQ(run_sim(with(tmp("gyro_bad"), {"--gyro-range-dps", "-5"})), 2);
  EXPECT_FALSE(fs::exists(tmp("gyro_bad") / "meta.yaml"));
  for (const auto& d : {a, b, c}) fs::remove_all(d);
}

TEST(SimCommand, RejectsBadArguments) {
  const fs::path d = tmp("bad");
  EXPECT_EQ(run_sim({"--out", d.string(), "--trajectory", "spiral"}), 2);
  EXPECT_EQ(run_sim({"--out", d.string(), "--profile", "1x1"}), 2);
  EXPECT_EQ(run_sim({"--out", d.string(), "--fps", "0"}), 2);
  EXPECT_EQ(run_sim({"--out", d.string(), "--map", "/nonexistent.csv"}), 2);
  EXPECT_EQ(run_sim({"--duration-s", "1"}), 2);  // --out is required
  EXPECT_EQ(run_sim({"--out", d.string(), "--odom-sample", "mean"}), 2);
  EXPECT_EQ(run_sim({"--out", d.string(), "--misprint", "8:300"}), 2);
  EXPECT_EQ(run_sim({"--out", d.string(), "--misprint", "8:300:0x"}), 2);
  EXPECT_EQ(run_sim({"--out", d.string(), "--misprint", "99:300:0"}), 2);  // not in the map
  EXPECT_EQ(run_sim({"--out", d.string(), "--misprint", "-4294967288:300:0"}), 2);  // not 8
  EXPECT_EQ(run_sim({"--out", d.string(), "--misprint", "8:300:0", "--payload", "id"}), 2);
  EXPECT_FALSE(fs::exists(d / "meta.yaml"));
}

namespace {

int run_landmark(std::vector<std::string> args) {
  return testsupport::run_command(desk::landmark, "landmark", std::move(args));
}

}  // namespace

TEST(LandmarkCommand, PngDecodesAndSvgAndSheet) {
  const fs::path d = tmp("lm");
  fs::create_directories(d);
  ASSERT_EQ(run_landmark({"--id", "17", "--x-mm", "1000", "--y-mm", "-2000", "--heading-deg", "90",
                          "--svg", (d / "l.svg").string(), "--png", (d / "l.png").string(),
                          "--mm-per-px", "0.2"}),
            0);
  const cv::Mat img = cv::imread((d / "l.png").string(), cv::IMREAD_GRAYSCALE);
  ASSERT_FALSE(img.empty());
  EXPECT_EQ(img.cols, 360);  // (60 + 2 * 6) mm / 0.2
  const auto r =
      ZXing::ReadBarcode(ZXing::ImageView(img.data, img.cols, img.rows, ZXing::ImageFormat::Lum),
                         ZXing::DecodeHints().setFormats(ZXing::BarcodeFormat::QRCode));
  ASSERT_TRUE(r.isValid());
  EXPECT_EQ(r.text(), "AGV1/00017/+001000.0/-002000.0/+090.00");
  EXPECT_NE(slurp(d / "l.svg").find("viewBox=\"0 0 72 72\""), std::string::npos);
  // Sheet of the default map: all 25 landmarks.
  ASSERT_EQ(run_landmark({"--map", std::string(AGV_SOURCE_DIR) + "/tools/maps/default_grid.csv",
                          "--sheet", (d / "sheet.svg").string()}),
            0);
  const std::string sheet = slurp(d / "sheet.svg");
  size_t n = 0;
  for (size_t p = sheet.find("<polygon"); p != std::string::npos; p = sheet.find("<polygon", p + 1))
    ++n;
  EXPECT_EQ(n, 25u);
  // Bad input is a usage error, not a crash or a wrong landmark.
  EXPECT_EQ(run_landmark({"--id", "0", "--svg", (d / "x.svg").string()}), 2);
  EXPECT_EQ(run_landmark({"--id", "5"}), 2);
  EXPECT_EQ(run_landmark({"--id", "5", "--x-mm", "5e9", "--svg", (d / "x.svg").string()}), 2);
  EXPECT_EQ(run_landmark({"--map", "/nonexistent.csv", "--sheet", (d / "x.svg").string()}), 2);
  EXPECT_FALSE(fs::exists(d / "x.svg"));
  fs::remove_all(d);
}

TEST(LandmarkCommand, TagSvgAndSheet) {
  const fs::path d = tmp("tag");
  fs::create_directories(d);
  ASSERT_EQ(run_landmark({"--family", "tag36h11", "--id", "17", "--svg", (d / "t.svg").string()}),
            0);
  const std::string svg = slurp(d / "t.svg");
  EXPECT_NE(svg.find("tag36h11 id 17"), std::string::npos);
  EXPECT_NE(svg.find("viewBox=\"0 0 90 90\""), std::string::npos);  // 60 + 2 x 2 cells of 7.5
  ASSERT_EQ(run_landmark({"--family", "tag36h11", "--map",
                          std::string(AGV_SOURCE_DIR) + "/tools/maps/default_grid.csv", "--sheet",
                          (d / "sheet.svg").string()}),
            0);
  const std::string sheet = slurp(d / "sheet.svg");
  size_t n = 0;
  for (size_t p = sheet.find("tag36h11 id "); p != std::string::npos;
       p = sheet.find("tag36h11 id ", p + 1))
    ++n;
  EXPECT_EQ(n, 25u);
  EXPECT_EQ(run_landmark({"--family", "tag36h11", "--id", "587", "--svg", (d / "x.svg").string()}),
            2);
  EXPECT_EQ(run_landmark({"--family", "aruco", "--id", "5", "--svg", (d / "x.svg").string()}), 2);
  EXPECT_FALSE(fs::exists(d / "x.svg"));
  fs::remove_all(d);
}

TEST(SimCommand, TagFamilyRecordingShowsTags) {
  const fs::path a = tmp("tagrec");
  // Slow, so a few frames have a tag fully in view (landmarks are 1 m apart).
  ASSERT_EQ(run_sim({"--out", a.string(), "--duration-s", "6.0", "--fps", "10", "--speed-mps",
                     "0.2", "--family", "tag36h11", "--seed", "2"}),
            0);
  recording::Recording r;
  std::string err;
  ASSERT_TRUE(recording::read_recording(a.string(), &r, &err)) << err;
  // The frames show tags of the default map that the tag family reads.
  vision::VisionConfig vc;
  vc.family = LandmarkFamily::kTag36h11;
  const LandmarkMap map = sim::default_landmark_grid();
  vision::LandmarkLocalizer loc(vc, r.meta.camera, LandmarkGeometry{}, &map);
  int ok = 0;
  for (const auto& f : r.frames) {
    vision::LandmarkFix fix;
    const cv::Mat img = cv::imread((a / f.file).string(), cv::IMREAD_GRAYSCALE);
    if (loc.process(img, &fix) == vision::FixStatus::kOk) ++ok;
  }
  EXPECT_GT(ok, 0);
  EXPECT_EQ(
      run_sim({"--out", tmp("tagbad").string(), "--family", "tag36h11", "--misprint", "8:300:0"}),
      2);
  EXPECT_EQ(run_sim({"--out", tmp("tagbad").string(), "--family", "aruco"}), 2);
  fs::remove_all(a);
}
