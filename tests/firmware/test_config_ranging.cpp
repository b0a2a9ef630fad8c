// The second camera's section (ranging_camera.*): off by default, its calibration and site file
// required once enabled, every value reaching the structs the replay and the core read.
#include <gtest/gtest.h>

#include <cmath>
#include <string>
#include <vector>

#include "agv/config/config.hpp"
#include "output_loop.hpp"

namespace {

using agv::config::Config;

const char* const kFloor = "intrinsics: {fx: 769.23, fy: 769.23, cx: 319.5, cy: 239.5}\n";

bool mentions(const std::vector<std::string>& errors, const std::string& what) {
  for (const auto& e : errors) {
    if (e.find(what) != std::string::npos) return true;
  }
  return false;
}

TEST(ConfigRanging, OffByDefault) {
  Config cfg;
  std::vector<std::string> errors;
  ASSERT_TRUE(agv::config::parse_config(kFloor, "/etc/agvloc", &cfg, &errors));
  EXPECT_FALSE(cfg.ranging_camera.enabled);
  EXPECT_TRUE(cfg.ranging_camera.site_file.empty());
  EXPECT_EQ(agv::app::localizer_config(cfg).ranging.camera_offset_ns, 0);
}

TEST(ConfigRanging, EnabledNeedsCalibrationAndSite) {
  Config cfg;
  std::vector<std::string> errors;
  EXPECT_FALSE(agv::config::parse_config(std::string(kFloor) + "ranging_camera: {enabled: true}\n",
                                         "", &cfg, &errors));
  EXPECT_TRUE(mentions(errors, "ranging_camera.intrinsics.fx: missing")) << errors.front();
  EXPECT_TRUE(mentions(errors, "ranging_camera.intrinsics.fy: missing"));
  EXPECT_TRUE(mentions(errors, "ranging_camera.site: missing"));
  // Replay needs them too: the recording's ranging stream carries no calibration.
  errors.clear();
  EXPECT_FALSE(agv::config::parse_config("ranging_camera: {enabled: true}\n", "", &cfg, &errors,
                                         agv::config::ConfigUse::kReplay));
  EXPECT_TRUE(mentions(errors, "ranging_camera.site: missing"));
}

TEST(ConfigRanging, ValuesReachTheStructs) {
  const std::string yaml = std::string(kFloor) +
                           "ranging_camera:\n"
                           "  enabled: true\n"
                           "  driver: v4l2\n"
                           "  id: /dev/video2\n"
                           "  width: 640\n"
                           "  height: 400\n"
                           "  fps: 10\n"
                           "  time_offset_ms: -12.5\n"
                           "  site: sites/hall.yaml\n"
                           "  intrinsics: {fx: 500, fy: 501, cx: 319.5, cy: 199.5, k1: -0.05}\n"
                           "  mount: {x_mm: 300, y_mm: -20, z_mm: 1000, roll_deg: 1, pitch_deg: "
                           "-2, yaw_deg: 90}\n";
  Config cfg;
  std::vector<std::string> errors;
  ASSERT_TRUE(agv::config::parse_config(yaml, "/etc/agvloc", &cfg, &errors))
      << (errors.empty() ? "" : errors.front());
  const agv::config::RangingCameraSection& r = cfg.ranging_camera;
  EXPECT_TRUE(r.enabled);
  EXPECT_EQ(r.driver, agv::config::CameraDriver::kV4l2);
  EXPECT_EQ(r.camera.id, "/dev/video2");
  EXPECT_EQ(r.camera.width_px, 640);
  EXPECT_EQ(r.intrinsics.width_px, 640);
  EXPECT_EQ(r.intrinsics.height_px, 400);
  EXPECT_DOUBLE_EQ(r.camera.fps, 10.0);
  EXPECT_EQ(r.site_file, "/etc/agvloc/sites/hall.yaml");
  EXPECT_DOUBLE_EQ(r.intrinsics.fy, 501.0);
  EXPECT_DOUBLE_EQ(r.intrinsics.k1, -0.05);
  EXPECT_DOUBLE_EQ(r.mount.x_mm, 300.0);
  EXPECT_DOUBLE_EQ(r.mount.y_mm, -20.0);
  EXPECT_DOUBLE_EQ(r.mount.z_mm, 1000.0);
  EXPECT_NEAR(r.mount.yaw_rad, M_PI / 2, 1e-12);
  EXPECT_NEAR(r.mount.pitch_rad, -M_PI / 90, 1e-12);
  EXPECT_NEAR(r.mount.roll_rad, M_PI / 180, 1e-12);
  // The floor camera keeps its own values.
  EXPECT_EQ(cfg.camera.camera.width_px, 640);
  EXPECT_EQ(cfg.camera.camera.height_px, 480);
  EXPECT_EQ(agv::app::localizer_config(cfg).ranging.camera_offset_ns, -12'500'000);
  EXPECT_EQ(agv::app::localizer_config(cfg).ranging.common_bearing_sigma_rad, 0.0);
}

TEST(ConfigRanging, ShallowPairsFromFaceYawsReachTheFixes) {
  const std::string base = std::string(kFloor) +
                           "ranging_camera:\n"
                           "  enabled: true\n"
                           "  site: hall.yaml\n"
                           "  intrinsics: {fx: 1000, fy: 1000, cx: 639.5, cy: 399.5}\n";
  for (const bool on : {true, false}) {
    const std::string yaml =
        base + (on ? "" : "  shallow_pairs_from_face_yaws: false\n");  // on by default
    Config cfg;
    std::vector<std::string> errors;
    ASSERT_TRUE(agv::config::parse_config(yaml, "/etc/agvloc", &cfg, &errors))
        << (errors.empty() ? "" : errors.front());
    EXPECT_EQ(agv::app::localizer_config(cfg).ranging.fix.face_yaw_pairs_below_crossing, on);
  }
}

TEST(ConfigRanging, TheCalibrationsDoubtReachesTheObserverAndTheFixes) {
  const std::string yaml = std::string(kFloor) +
                           "ranging_camera:\n"
                           "  enabled: true\n"
                           "  site: hall.yaml\n"
                           "  intrinsics: {fx: 1000, fy: 1000, cx: 639.5, cy: 399.5}\n"
                           "  mount: {sigma_deg: 0.5, sigma_mm: 3}\n"
                           "  calibration_sigma_px: 2\n"
                           "  focal_sigma_rel: 0.002\n";
  Config cfg;
  std::vector<std::string> errors;
  ASSERT_TRUE(agv::config::parse_config(yaml, "", &cfg, &errors))
      << (errors.empty() ? "" : errors.front());
  const agv::config::RangingCameraSection& r = cfg.ranging_camera;
  EXPECT_NEAR(r.mount_sigma_rad, 0.5 * M_PI / 180.0, 1e-15);
  EXPECT_DOUBLE_EQ(r.mount_sigma_mm, 3.0);
  EXPECT_DOUBLE_EQ(r.calibration_sigma_px, 2.0);
  EXPECT_DOUBLE_EQ(r.focal_sigma_rel, 0.002);
  // The mount's yaw and the principal point's column (2 px at f = 1000 px) shared by every bearing.
  EXPECT_NEAR(agv::app::localizer_config(cfg).ranging.common_bearing_sigma_rad,
              std::hypot(0.5 * M_PI / 180.0, 0.002), 1e-15);
  errors.clear();
  EXPECT_FALSE(agv::config::parse_config(
      std::string(kFloor) + "ranging_camera: {mount: {sigma_deg: -1}}\n", "", &cfg, &errors));
  EXPECT_TRUE(mentions(errors, "ranging_camera.mount.sigma_deg"));
}

}  // namespace
