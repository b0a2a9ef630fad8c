// `agvloc-desk calibrate ranging-mount` end to end on a small rendered drive: a rack face, its
// landmarks rendered by the site renderer (sensor effects on) through the true mount at each
// frame's pose, a replay folder whose poses.csv holds those poses with a floor fix's sigma, and
// a configuration whose mount is off by 1 degree and 5 mm per axis.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <map>
#include <regex>
#include <sstream>
#include <string>
#include <vector>

#include "agv/recording/recording.hpp"
#include "agv/sim/ranging_camera.hpp"
#include "agv/sim/site_render.hpp"
#include "agv/site/site_file.hpp"
#include "commands.hpp"

namespace agv::desk {
namespace {

namespace fs = std::filesystem;
constexpr double kDeg = kPi / 180.0;

CameraIntrinsics intrinsics() {
  CameraIntrinsics k;
  k.width_px = 640;
  k.height_px = 400;
  k.fx = k.fy = 400.0;
  k.cx = 319.5;
  k.cy = 199.5;
  return k;
}

ranging::RangingMount true_mount() {
  ranging::RangingMount m;
  m.x_mm = 200.0;
  m.y_mm = 250.0;
  m.z_mm = 1000.0;
  m.pitch_rad = -0.5 * kDeg;
  m.yaw_rad = 90.0 * kDeg;
  return m;
}

sim::SiteScene rack_scene() {
  sim::SiteScene s;
  s.site.name = "mount calibration test";
  s.site.outline.vertices_mm = {{-3000, -3000}, {9000, -3000}, {9000, 4000}, {-3000, 4000}};
  for (int i = 0; i < 10; ++i) {
    s.site.wall_landmarks.push_back({static_cast<std::uint32_t>(101 + i),
                                     site::LandmarkFamily::kTag36h11, 600.0 * i, 1500.0,
                                     i % 2 ? 1300.0 : 800.0, -kPi / 2, 150.0});
  }
  return s;
}

Pose2 pose_at(std::int64_t t_ns) {
  const double t = 1e-9 * static_cast<double>(t_ns);
  return {500.0 * t, 100.0 * std::sin(t), 0.1 * std::sin(1.3 * t)};
}

struct Scene {
  fs::path dir;
  fs::path rec, replay, config;
};

// Writes the recording's ranging stream, the site, the replay's poses.csv and summary.txt and
// the configuration (mount off by 5 mm and 1 deg per axis).
Scene make_scene(const std::string& name, bool replay_with_ranging) {
  Scene s;
  s.dir = fs::temp_directory_path() / ("agv_cal_ranging_" + name);
  fs::remove_all(s.dir);
  s.rec = s.dir / "rec";
  s.replay = s.dir / "replay";
  fs::create_directories(s.rec / "ranging");
  fs::create_directories(s.replay);
  const sim::SiteScene scene = rack_scene();
  std::ofstream(s.rec / "site.yaml") << site::write_site(scene.site);
  const sim::SiteFrameRenderer renderer(intrinsics());
  std::vector<recording::FrameRow> rows;
  std::string err;
  for (int f = 0; f < 40; ++f) {
    const std::int64_t t = 100'000'000LL * (f + 1);
    const auto cam = sim::ranging_camera(intrinsics(), pose_at(t), true_mount());
    const auto r = renderer.render(scene, cam, sim::realistic_site_params(), 7 + f);
    const std::string file = std::to_string(f) + ".png";
    EXPECT_TRUE(recording::write_frame_png((s.rec / "ranging").string(), file, r.image, &err));
    rows.push_back({t, file});
  }
  EXPECT_TRUE(recording::write_frames_csv((s.rec / "ranging").string(), rows, &err)) << err;
  std::ofstream p(s.replay / "poses.csv");
  p << "t_ns,valid,health,x_mm,y_mm,theta_deg,v_mps,omega_radps,sigma_x_mm,sigma_y_mm,"
       "sigma_theta_deg,time_since_fix_ms,faults,rejections\n";
  for (std::int64_t t = 0; t <= 4'200'000'000LL; t += 10'000'000) {
    const Pose2 v = pose_at(t);
    p << t << ",1,1," << v.x_mm << "," << v.y_mm << "," << v.theta_rad / kDeg
      << ",0.5,0,0.3,0.3,0.02,5,0,0\n";
  }
  std::ofstream(s.replay / "summary.txt")
      << "replay summary\n"
      << (replay_with_ranging ? "ranging camera: 40 frames\n" : "");
  s.config = s.rec / "off.yaml";
  std::ofstream(s.config)
      << "ranging_camera:\n  enabled: true\n  driver: replay\n  site: site.yaml\n"
         "  width: 640\n  height: 400\n  fps: 10\n"
         "  intrinsics: {fx: 400, fy: 400, cx: 319.5, cy: 199.5}\n"
         "  focal_sigma_rel: 0.001\n"
         "  mount: {x_mm: 205, y_mm: 245, z_mm: 1005, roll_deg: 1, "
         "pitch_deg: 0.5, yaw_deg: 91}\n";
  return s;
}

int run(const Scene& s, const fs::path& out) {
  std::vector<std::string> args = {"calibrate-ranging-mount",
                                   "--config",
                                   s.config.string(),
                                   "--recording",
                                   s.rec.string(),
                                   "--replay",
                                   s.replay.string(),
                                   "--out",
                                   out.string()};
  std::vector<char*> argv;
  for (auto& a : args) argv.push_back(a.data());
  return calibrate_ranging_mount(static_cast<int>(argv.size()), argv.data());
}

std::map<std::string, double> snippet_values(const fs::path& path) {
  std::ifstream f(path);
  std::stringstream text;
  text << f.rdbuf();
  const std::string t = text.str();
  std::map<std::string, double> out;
  const std::regex line(R"(^\s+(\w+): ([-0-9.e]+)$)", std::regex::multiline);
  for (auto it = std::sregex_iterator(t.begin(), t.end(), line); it != std::sregex_iterator(); ++it)
    out[(*it)[1]] = std::stod((*it)[2]);
  return out;
}

TEST(CmdCalibrateRanging, WritesTheMountOfARenderedDrive) {
  const Scene s = make_scene("ok", false);
  const fs::path out = s.dir / "mount.yaml";
  ASSERT_EQ(run(s, out), 0);
  const auto v = snippet_values(out);
  ASSERT_EQ(v.count("yaw_deg"), 1u);
  EXPECT_NEAR(v.at("yaw_deg"), 90.0, 0.1);
  EXPECT_NEAR(v.at("pitch_deg"), -0.5, 0.2);
  EXPECT_NEAR(v.at("roll_deg"), 0.0, 0.2);
  EXPECT_NEAR(v.at("x_mm"), 200.0, 2.0);
  EXPECT_NEAR(v.at("y_mm"), 250.0, 2.0);
  EXPECT_NEAR(v.at("z_mm"), 1000.0, 3.0);
  // The sigmas written (the largest of the offsets' and of the angles') cover the errors: the
  // lens's stated 0.1 % focal doubt carries the corners' scale bias on rendered frames (1.0 mm
  // along the optical axis at 1.25 m, 14 sigma when the lens is taken as exact).
  EXPECT_LT(std::abs(v.at("x_mm") - 200.0), 3.0 * v.at("sigma_mm"));
  EXPECT_LT(std::abs(v.at("y_mm") - 250.0), 3.0 * v.at("sigma_mm"));
  EXPECT_LT(std::abs(v.at("z_mm") - 1000.0), 3.0 * v.at("sigma_mm"));
  EXPECT_LT(std::abs(v.at("yaw_deg") - 90.0), 3.0 * v.at("sigma_deg"));
  EXPECT_LT(std::abs(v.at("pitch_deg") + 0.5), 3.0 * v.at("sigma_deg"));
  EXPECT_LT(std::abs(v.at("roll_deg")), 3.0 * v.at("sigma_deg"));
  fs::remove_all(s.dir);
}

TEST(CmdCalibrateRanging, RefusesAReplayThatUsedTheSecondCamera) {
  const Scene s = make_scene("ranging_replay", true);
  const fs::path out = s.dir / "mount.yaml";
  EXPECT_EQ(run(s, out), 2);
  EXPECT_FALSE(fs::exists(out));
  fs::remove_all(s.dir);
}

TEST(CmdCalibrateRanging, RefusesAConfigurationWithoutTheSecondCamera) {
  const Scene s = make_scene("disabled", false);
  std::ofstream(s.config) << "ranging_camera:\n  enabled: false\n";
  EXPECT_EQ(run(s, s.dir / "mount.yaml"), 2);
  fs::remove_all(s.dir);
}

TEST(CmdCalibrateRanging, PosesOutsideTheSigmaLimitsGiveNoMount) {
  const Scene s = make_scene("lost", false);
  // Every tick dead reckoning (health 2): no frame has a pose to calibrate from.
  std::ifstream in(s.replay / "poses.csv");
  std::stringstream text;
  text << in.rdbuf();
  in.close();
  std::string t = text.str();
  t = std::regex_replace(t, std::regex(R"(\n(\d+),1,1,)"), "\n$1,1,2,");
  std::ofstream(s.replay / "poses.csv") << t;
  const fs::path out = s.dir / "mount.yaml";
  EXPECT_EQ(run(s, out), 1);
  EXPECT_FALSE(fs::exists(out));
  fs::remove_all(s.dir);
}

}  // namespace
}  // namespace agv::desk
