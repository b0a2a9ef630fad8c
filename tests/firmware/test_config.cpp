#include <gtest/gtest.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include "config.hpp"

using agv::config::Config;

namespace {

std::vector<std::string> errors_for(const std::string& yaml) {
  Config cfg;
  std::vector<std::string> errors;
  EXPECT_FALSE(agv::config::parse_config(yaml, "", &cfg, &errors)) << yaml;
  return errors;
}

bool mentions(const std::vector<std::string>& errors, const std::string& what) {
  for (const auto& e : errors) {
    if (e.find(what) != std::string::npos) return true;
  }
  return false;
}

}  // namespace

TEST(Config, ShippedExampleLoads) {
  Config cfg;
  std::vector<std::string> errors;
  ASSERT_TRUE(agv::config::load_config(std::string(AGV_SOURCE_DIR) + "/firmware/config/agvloc.yaml",
                                       &cfg, &errors))
      << (errors.empty() ? "" : errors.front());
  EXPECT_EQ(cfg.camera.driver, "libcamera");
  EXPECT_EQ(cfg.can.base_id, 0x300u);
  EXPECT_NEAR(cfg.camera_model.mm_per_px(), 0.26, 1e-6);
  EXPECT_NE(cfg.map_file.find("tools/maps/default_grid.csv"), std::string::npos);
  // The vehicle configuration runs real time (docs/config.md, loop section).
  EXPECT_EQ(cfg.loop.realtime_priority, 50);
  EXPECT_EQ(cfg.loop.vision_priority, 40);
  EXPECT_TRUE(cfg.loop.lock_memory);
  EXPECT_TRUE(cfg.loop.pose_on_fix);
}

// The camera calibration every live configuration must carry (issue 15, finding 3).
const char* kIntrinsics = "intrinsics: {fx: 769.23, fy: 769.23, cx: 319.5, cy: 239.5}\n";

TEST(Config, EmptyMappingGivesDefaults) {
  Config cfg;
  std::vector<std::string> errors;
  ASSERT_TRUE(agv::config::parse_config(kIntrinsics, "", &cfg, &errors));
  EXPECT_DOUBLE_EQ(cfg.loop.output_rate_hz, 100.0);
  // Built-in defaults need no privileges; the fix-triggered pose needs none either.
  EXPECT_EQ(cfg.loop.realtime_priority, 0);
  EXPECT_EQ(cfg.loop.vision_priority, 0);
  EXPECT_FALSE(cfg.loop.lock_memory);
  EXPECT_EQ(cfg.loop.spin_before_deadline_us, 0);
  EXPECT_TRUE(cfg.loop.pose_on_fix);
}

TEST(Config, UnknownKeyIsNamed) {
  EXPECT_TRUE(mentions(errors_for("can:\n  interfcae: can1\n"), "can.interfcae: unknown key"));
  EXPECT_TRUE(mentions(errors_for("bogus: 1\n"), "bogus: unknown key"));
}

TEST(Config, OutOfRangeNamesKeyAndRange) {
  const auto e = errors_for("loop:\n  output_rate_hz: 5000\n");
  EXPECT_TRUE(mentions(e, "loop.output_rate_hz: value 5000 outside the accepted range [1, 1000]"));
  EXPECT_TRUE(mentions(errors_for("can:\n  base_id: 0x800\n"), "can.base_id"));
}

TEST(Config, ExtendedIdsWidenTheRange) {
  Config cfg;
  std::vector<std::string> errors;
  EXPECT_TRUE(agv::config::parse_config(
      std::string(kIntrinsics) + "can:\n  extended_ids: true\n  base_id: 0x18FF0000\n", "", &cfg,
      &errors));
  EXPECT_EQ(cfg.can.base_id, 0x18FF0000u);
}

TEST(Config, WrongTypesAndChoices) {
  EXPECT_TRUE(
      mentions(errors_for("camera:\n  width: wide\n"), "camera.width: expected an integer"));
  EXPECT_TRUE(
      mentions(errors_for("camera:\n  driver: gopro\n"), "camera.driver: 'gopro' is not one of"));
  EXPECT_TRUE(mentions(errors_for("loop:\n  lock_memory: maybe\n"),
                       "loop.lock_memory: expected true or false"));
  EXPECT_TRUE(mentions(errors_for("can: 5\n"), "can: expected a mapping"));
  EXPECT_TRUE(
      mentions(errors_for("intrinsics:\n  fx: .nan\n"), "intrinsics.fx: expected a number"));
}

TEST(Config, SyntaxErrorAndNonMapping) {
  EXPECT_TRUE(mentions(errors_for("camera: [1, 2\n"), "YAML syntax error"));
  EXPECT_TRUE(mentions(errors_for("- a\n- b\n"), "top level"));
}

TEST(Config, MissingFile) {
  Config cfg;
  std::vector<std::string> errors;
  EXPECT_FALSE(agv::config::load_config("/nonexistent/agvloc.yaml", &cfg, &errors));
  EXPECT_TRUE(mentions(errors, "cannot open"));
}

TEST(Config, FusionAndVisionSectionsReachTheAlgorithms) {
  Config cfg;
  std::vector<std::string> errors;
  ASSERT_TRUE(agv::config::parse_config(
      std::string(kIntrinsics) +
          "fusion:\n  gate_probability: 0.99\n  estimate_odometry_calibration: false\n"
          "  max_fix_delay_ms: 250\n  lost_heading_sigma_deg: 5\n"
          "vision:\n  corner_threshold: 0.7\n  robust: false\n  qr_guided: false\n"
          "  qr_max_missing_modules: 12\n",
      "", &cfg, &errors))
      << errors.front();
  EXPECT_DOUBLE_EQ(cfg.fusion.gate_probability, 0.99);
  EXPECT_FALSE(cfg.fusion.estimate_odometry_calibration);
  EXPECT_EQ(cfg.fusion.max_fix_delay_ns, 250'000'000);
  EXPECT_NEAR(cfg.fusion.lost_heading_sigma_rad, agv::deg_to_rad(5.0), 1e-12);
  EXPECT_DOUBLE_EQ(cfg.vision.corner_threshold, 0.7);
  EXPECT_FALSE(cfg.vision.robust);
  EXPECT_FALSE(cfg.vision.qr_guided);
  EXPECT_EQ(cfg.vision.qr_max_missing_modules, 12);
  EXPECT_TRUE(mentions(errors_for("vision:\n  qr_max_missing_modules: 700\n"),
                       "vision.qr_max_missing_modules"));
  EXPECT_TRUE(
      mentions(errors_for("fusion:\n  gate_probability: 1.5\n"), "fusion.gate_probability"));
  EXPECT_TRUE(mentions(errors_for("vision:\n  colour: red\n"), "vision.colour: unknown key"));
}

TEST(Config, LoopRealTimeKeysAndTheirRelations) {
  Config cfg;
  std::vector<std::string> errors;
  ASSERT_TRUE(agv::config::parse_config(
      std::string(kIntrinsics) +
          "loop:\n  realtime_priority: 50\n  vision_priority: 40\n  spin_before_deadline_us: 200\n",
      "", &cfg, &errors))
      << (errors.empty() ? "" : errors.front());
  EXPECT_EQ(cfg.loop.vision_priority, 40);
  EXPECT_EQ(cfg.loop.spin_before_deadline_us, 200);
  // Vision must stay below the output thread, also when the output thread has no priority.
  EXPECT_TRUE(mentions(errors_for("loop:\n  realtime_priority: 50\n  vision_priority: 50\n"),
                       "loop.vision_priority: value 50 must be below loop.realtime_priority (50)"));
  EXPECT_TRUE(mentions(errors_for("loop:\n  vision_priority: 10\n"),
                       "loop.vision_priority: value 10 must be below loop.realtime_priority (0)"));
  EXPECT_TRUE(mentions(errors_for("loop:\n  vision_priority: 99\n"),
                       "loop.vision_priority: value 99 outside the accepted range [0, 98]"));
  EXPECT_TRUE(
      mentions(errors_for("loop:\n  spin_before_deadline_us: 2001\n"),
               "loop.spin_before_deadline_us: value 2001 outside the accepted range [0, 2000]"));
  // The spin must leave most of the period asleep.
  EXPECT_TRUE(
      mentions(errors_for("loop:\n  output_rate_hz: 1000\n  spin_before_deadline_us: 600\n"),
               "loop.spin_before_deadline_us: value 600 exceeds half the output period (500 us at "
               "loop.output_rate_hz 1000)"));
  EXPECT_TRUE(mentions(errors_for("loop:\n  spin_before_deadline_us: -1\n"),
                       "loop.spin_before_deadline_us"));
}

TEST(Config, FusionOdometryTimingAndGapKeys) {
  Config cfg;
  std::vector<std::string> errors;
  ASSERT_TRUE(agv::config::parse_config(
      std::string(kIntrinsics) +
          "fusion:\n  odom_sample_timing: instant\n  odom_period_ms: 20\n  odom_gap_ms: 80\n"
          "  gap_yaw_rate_change_sigma_radps: 0.3\n  max_fix_lead_ms: 150\n  held_fix_capacity: 4\n"
          "  relocalize_from_single_fix: false\n  relocalize_max_fix_sigma_deg: 1\n"
          "  kidnap_min_duration_ms: 1500\n",
      "", &cfg, &errors))
      << (errors.empty() ? "" : errors.front());
  using Timing = agv::fusion::EkfConfig::OdomSampleTiming;
  EXPECT_EQ(cfg.fusion.odom_sample_timing, Timing::kInstant);
  EXPECT_EQ(cfg.fusion.odom_period_ns, 20'000'000);
  EXPECT_EQ(cfg.fusion.odom_gap_ns, 80'000'000);
  EXPECT_DOUBLE_EQ(cfg.fusion.gap_yaw_rate_change_sigma_radps, 0.3);
  EXPECT_EQ(cfg.fusion.max_fix_lead_ns, 150'000'000);
  EXPECT_EQ(cfg.fusion.held_fix_capacity, 4u);
  EXPECT_FALSE(cfg.fusion.relocalize_from_single_fix);
  EXPECT_NEAR(cfg.fusion.relocalize_max_fix_sigma_rad, agv::deg_to_rad(1.0), 1e-12);
  EXPECT_EQ(cfg.fusion.kidnap_min_duration_ns, 1'500'000'000);
  EXPECT_TRUE(mentions(errors_for("fusion:\n  odom_sample_timing: mean\n"), "odom_sample_timing"));
  // Without calibration states the noise defaults cover the uncalibrated errors; explicit keys
  // still win, whatever their order in the file.
  Config plain;
  ASSERT_TRUE(agv::config::parse_config(
      std::string(kIntrinsics) +
          "fusion:\n  cross_track_sigma_mm_per_sqrt_m: 3\n  estimate_odometry_calibration: false\n",
      "", &plain, &errors));
  EXPECT_FALSE(plain.fusion.estimate_odometry_calibration);
  EXPECT_DOUBLE_EQ(plain.fusion.along_track_sigma_mm_per_sqrt_m, 5.0);
  EXPECT_DOUBLE_EQ(plain.fusion.cross_track_sigma_mm_per_sqrt_m, 3.0);
  // A gap shorter than one period cannot be told from normal sampling.
  EXPECT_TRUE(mentions(errors_for("fusion:\n  odom_period_ms: 20\n  odom_gap_ms: 10\n"), "fusion"));
}

// ---- Issue 15: hostile configurations ------------------------------------------------------

std::string tmp_path(const std::string& name) {
  return (std::filesystem::temp_directory_path() /
          ("agv_test_config_" + std::to_string(::getpid()) + "_" + name))
      .string();
}

// Finding 1: a non-scalar key threw YAML::TypedBadConversion out of finish_map (abort, exit 134).
TEST(Config, NonScalarKeyIsANamedError) {
  EXPECT_TRUE(mentions(errors_for("[a]: 1"), "top level: key at line 1 is not a plain name"));
  EXPECT_TRUE(mentions(errors_for("camera:\n  {x: 1}: 2"),
                       "camera: key at line 2 is not a plain name (a mapping used as key)"));
  EXPECT_TRUE(mentions(errors_for(std::string(kIntrinsics) + "can:\n  odometry:\n    [1, 2]: x\n"),
                       "can.odometry: key at line 4 is not a plain name"));
}

// Finding 3: without intrinsics, --check-config passed and the loop ran with fx = fy = 0.
TEST(Config, MissingIntrinsicsIsAnError) {
  EXPECT_TRUE(
      mentions(errors_for("{}"), "intrinsics: missing section (fx, fy, cx, cy are required"));
  EXPECT_TRUE(mentions(errors_for("camera:\n  fps: 30\n"), "intrinsics: missing section"));
  const auto e = errors_for("intrinsics:\n  fx: 700\n  cx: 320\n");
  EXPECT_TRUE(mentions(e, "intrinsics.fy: missing (required: the camera calibration"));
  EXPECT_TRUE(mentions(e, "intrinsics.cy: missing"));
  EXPECT_FALSE(mentions(e, "intrinsics.fx"));
  // Distortion defaults to none; the loaded model is the one configured.
  Config cfg;
  std::vector<std::string> errors;
  ASSERT_TRUE(agv::config::parse_config(kIntrinsics, "", &cfg, &errors));
  EXPECT_NEAR(cfg.camera_model.mm_per_px(), 0.26, 1e-4);
  EXPECT_EQ(cfg.camera_model.intrinsics.k1, 0.0);
}

// Replay takes the camera from meta.yaml: there the section may be absent.
TEST(Config, ReplayNeedsNoIntrinsics) {
  Config rcfg;
  std::vector<std::string> errors;
  EXPECT_TRUE(agv::config::parse_config("{}", "", &rcfg, &errors, agv::config::ConfigUse::kReplay));
  EXPECT_FALSE(agv::config::parse_config("intrinsics:\n  fx: 0\n", "", &rcfg, &errors,
                                         agv::config::ConfigUse::kReplay));
}

// Finding 4: duplicate keys and sections were accepted silently (the first one won).
TEST(Config, DuplicateKeysAndSectionsAreErrors) {
  EXPECT_TRUE(mentions(errors_for(std::string(kIntrinsics) + "loop:\n  output_rate_hz: 50\n"
                                                             "  output_rate_hz: 200\n"),
                       "loop.output_rate_hz: duplicate key at line 4 (first at line 3)"));
  EXPECT_TRUE(mentions(errors_for(std::string(kIntrinsics) + "can:\n  interface: can0\n"
                                                             "can:\n  interface: can1\n"),
                       "can: duplicate key at line 4 (first at line 2)"));
  EXPECT_TRUE(
      mentions(errors_for(std::string(kIntrinsics) + kIntrinsics), "intrinsics: duplicate key"));
}

// Finding 5: `--config /dev/zero` and `landmark.map: /dev/zero` grew memory without limit.
TEST(Config, OnlyBoundedRegularFilesAreRead) {
  Config cfg;
  std::vector<std::string> errors;
  EXPECT_FALSE(agv::config::load_config("/dev/zero", &cfg, &errors));
  EXPECT_TRUE(mentions(errors, "/dev/zero: not a regular file"));
  errors.clear();
  const std::string big = tmp_path("big.yaml");
  std::ofstream(big) << std::string((1u << 20) + 1, '#');  // kMaxConfigBytes + 1
  EXPECT_FALSE(agv::config::load_config(big, &cfg, &errors));
  EXPECT_TRUE(mentions(errors, "larger than 1048576 bytes"));
  std::filesystem::remove(big);
  agv::LandmarkMap map;
  std::string err;
  EXPECT_FALSE(agv::config::load_map_file("/dev/zero", &map, &err));
  EXPECT_NE(err.find("/dev/zero: not a regular file"), std::string::npos) << err;
  const std::string dir = tmp_path("dir");
  std::filesystem::create_directories(dir);
  EXPECT_FALSE(agv::config::load_map_file(dir, &map, &err));
  EXPECT_NE(err.find("not a regular file"), std::string::npos) << err;
  std::filesystem::remove_all(dir);
}
