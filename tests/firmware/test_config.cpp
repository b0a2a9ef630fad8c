#include <gtest/gtest.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <map>
#include <set>
#include <sstream>
#include <string>
#include <vector>

#include "agv/adapters/stepped_clock.hpp"
#include "agv/config/cpu_list.hpp"
#include "agv/config/keys.hpp"
#include "agv/protocol/dbc.hpp"
#include "config.hpp"
#include "output_loop.hpp"

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
  EXPECT_EQ(cfg.camera.driver, agv::config::CameraDriver::kLibcamera);
  EXPECT_EQ(cfg.can.base_id, 0x300u);
  EXPECT_NEAR(cfg.camera_model.mm_per_px(), 0.26, 1e-6);
  EXPECT_NE(cfg.map_file.find("tools/maps/default_grid.csv"), std::string::npos);
  // The vehicle configuration runs real time (docs/guide/config.md, loop section).
  EXPECT_EQ(cfg.loop.realtime_priority, 50);
  EXPECT_EQ(cfg.loop.vision_priority, 40);
  // The hybrid wait: the period stays steady with the page or MQTT loading the computer.
  EXPECT_EQ(cfg.loop.spin_before_deadline_us, 1000);
  EXPECT_TRUE(cfg.loop.lock_memory);
  EXPECT_TRUE(cfg.loop.pose_on_fix);
  EXPECT_EQ(cfg.loop.realtime_cpus, "");  // CPU numbers depend on the board
}

// The camera calibration every live configuration must carry.
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

TEST(Config, LandmarkFamilyKey) {
  Config cfg;
  std::vector<std::string> errors;
  ASSERT_TRUE(agv::config::parse_config(kIntrinsics, "", &cfg, &errors));
  EXPECT_EQ(cfg.vision.family, agv::LandmarkFamily::kQr);
  ASSERT_TRUE(agv::config::parse_config(
      std::string(kIntrinsics) + "landmark:\n  family: tag36h11\n", "", &cfg, &errors));
  EXPECT_EQ(cfg.vision.family, agv::LandmarkFamily::kTag36h11);
  EXPECT_TRUE(mentions(errors_for("landmark:\n  family: aruco\n"),
                       "landmark.family: 'aruco' is not one of"));
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
  EXPECT_DOUBLE_EQ(cfg.fusion.fix.gate_probability, 0.99);
  EXPECT_FALSE(cfg.fusion.odometry.estimate_calibration);
  EXPECT_EQ(cfg.fusion.fix.max_delay_ns, 250'000'000);
  EXPECT_NEAR(cfg.fusion.health.lost_heading_sigma_rad, agv::deg_to_rad(5.0), 1e-12);
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

TEST(Config, TrackingKeysReachTheVisionConfig) {
  Config cfg;
  std::vector<std::string> errors;
  ASSERT_TRUE(agv::config::parse_config(
      std::string(kIntrinsics) +
          "vision:\n  tracking:\n    enabled: false\n    max_position_sigma_mm: 4.5\n"
          "    max_heading_sigma_deg: 0.7\n    window_sigmas: 3\n",
      "", &cfg, &errors))
      << errors.front();
  EXPECT_FALSE(cfg.vision.tracking.enabled);
  EXPECT_DOUBLE_EQ(cfg.vision.tracking.max_position_sigma_mm, 4.5);
  EXPECT_DOUBLE_EQ(cfg.vision.tracking.max_heading_sigma_deg, 0.7);
  EXPECT_DOUBLE_EQ(cfg.vision.tracking.window_sigmas, 3.0);
  EXPECT_TRUE(mentions(errors_for("vision:\n  tracking:\n    window_sigmas: 50\n"),
                       "vision.tracking.window_sigmas"));
}

TEST(Config, CpuListsInTheKernelSyntax) {
  using agv::config::parse_cpu_list;
  std::vector<int> cpus;
  std::string why;
  ASSERT_TRUE(parse_cpu_list("", &cpus, &why));
  EXPECT_TRUE(cpus.empty());
  ASSERT_TRUE(parse_cpu_list("  ", &cpus, &why));
  EXPECT_TRUE(cpus.empty());
  ASSERT_TRUE(parse_cpu_list("3", &cpus, &why));
  EXPECT_EQ(cpus, std::vector<int>({3}));
  ASSERT_TRUE(parse_cpu_list("2-3, 0", &cpus, &why)) << why;
  EXPECT_EQ(cpus, std::vector<int>({0, 2, 3}));  // sorted
  ASSERT_TRUE(parse_cpu_list("1,1-2,2", &cpus, &why));
  EXPECT_EQ(cpus, std::vector<int>({1, 2}));  // distinct
  ASSERT_TRUE(parse_cpu_list("1023", &cpus, &why));
  for (const char* bad :
       {"1024", "-1", "3-2", "a", "1,,2", "1,", "1-", "0x1", "1 2", "+1", "99999999999"}) {
    EXPECT_FALSE(parse_cpu_list(bad, &cpus, &why)) << bad;
    EXPECT_TRUE(cpus.empty()) << bad;
    EXPECT_NE(why.find("is not a CPU"), std::string::npos) << why;
  }
}

TEST(Config, LoopCpuKeys) {
  Config cfg;
  std::vector<std::string> errors;
  ASSERT_TRUE(agv::config::parse_config(
      std::string(kIntrinsics) +
          "loop:\n  realtime_cpus: \"1\"\n  vision_cpus: \"1-2\"\n  service_cpus: \"0,2-3\"\n",
      "", &cfg, &errors))
      << (errors.empty() ? "" : errors.front());
  EXPECT_EQ(cfg.loop.realtime_cpus, "1");
  EXPECT_EQ(cfg.loop.vision_cpus, "1-2");  // vision may share either
  EXPECT_EQ(cfg.loop.service_cpus, "0,2-3");
  EXPECT_TRUE(mentions(errors_for("loop:\n  realtime_cpus: \"1-\"\n"),
                       "loop.realtime_cpus: \"1-\" in \"1-\" is not a CPU"));
  EXPECT_TRUE(mentions(errors_for("loop:\n  service_cpus: \"x\"\n"), "loop.service_cpus"));
  EXPECT_TRUE(mentions(errors_for("loop:\n  vision_cpus: \"0-1-2\"\n"), "loop.vision_cpus"));
  // The point of the two lists is that they are apart.
  EXPECT_TRUE(mentions(errors_for("loop:\n  realtime_cpus: \"1-2\"\n  service_cpus: \"0,2\"\n"),
                       "loop.service_cpus: CPU 2 is also in loop.realtime_cpus"));
  // A YAML number is taken as its text.
  ASSERT_TRUE(agv::config::parse_config(std::string(kIntrinsics) + "loop:\n  realtime_cpus: 1\n",
                                        "", &cfg, &errors));
  EXPECT_EQ(cfg.loop.realtime_cpus, "1");
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
  EXPECT_EQ(cfg.fusion.odometry.sample_timing, Timing::kInstant);
  EXPECT_EQ(cfg.fusion.odometry.period_ns, 20'000'000);
  EXPECT_EQ(cfg.fusion.odometry.gap_ns, 80'000'000);
  EXPECT_DOUBLE_EQ(cfg.fusion.odometry.gap_yaw_rate_change_sigma_radps, 0.3);
  EXPECT_EQ(cfg.fusion.fix.max_lead_ns, 150'000'000);
  EXPECT_EQ(cfg.fusion.fix.held_capacity, 4u);
  EXPECT_FALSE(cfg.fusion.recovery.relocalize_from_single_fix);
  EXPECT_NEAR(cfg.fusion.recovery.relocalize_max_fix_sigma_rad, agv::deg_to_rad(1.0), 1e-12);
  EXPECT_EQ(cfg.fusion.recovery.kidnap_min_duration_ns, 1'500'000'000);
  EXPECT_TRUE(mentions(errors_for("fusion:\n  odom_sample_timing: mean\n"), "odom_sample_timing"));
  // Without calibration states the noise defaults cover the uncalibrated errors; explicit keys
  // still win, whatever their order in the file.
  Config plain;
  ASSERT_TRUE(agv::config::parse_config(
      std::string(kIntrinsics) +
          "fusion:\n  cross_track_sigma_mm_per_sqrt_m: 3\n  estimate_odometry_calibration: false\n",
      "", &plain, &errors));
  EXPECT_FALSE(plain.fusion.odometry.estimate_calibration);
  EXPECT_DOUBLE_EQ(plain.fusion.core.along_track_sigma_mm_per_sqrt_m, 5.0);
  EXPECT_DOUBLE_EQ(plain.fusion.core.cross_track_sigma_mm_per_sqrt_m, 3.0);
  // A gap shorter than one period cannot be told from normal sampling.
  EXPECT_TRUE(mentions(errors_for("fusion:\n  odom_period_ms: 20\n  odom_gap_ms: 10\n"), "fusion"));
}

// ---- Hostile configurations ------------------------------------------------------------------

std::string tmp_path(const std::string& name) {
  return (std::filesystem::temp_directory_path() /
          ("agv_test_config_" + std::to_string(::getpid()) + "_" + name))
      .string();
}

// A non-scalar key threw YAML::TypedBadConversion out of finish_map (abort, exit 134).
TEST(Config, NonScalarKeyIsANamedError) {
  EXPECT_TRUE(mentions(errors_for("[a]: 1"), "top level: key at line 1 is not a plain name"));
  EXPECT_TRUE(mentions(errors_for("camera:\n  {x: 1}: 2"),
                       "camera: key at line 2 is not a plain name (a mapping used as key)"));
  EXPECT_TRUE(mentions(errors_for(std::string(kIntrinsics) + "can:\n  odometry:\n    [1, 2]: x\n"),
                       "can.odometry: key at line 4 is not a plain name"));
}

// Without intrinsics, --check-config passed and the loop ran with fx = fy = 0.
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

// Duplicate keys and sections were accepted silently (the first one won).
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

// `--config /dev/zero` and `landmark.map: /dev/zero` grew memory without limit.
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

// ---- One key table for the checker, the defaults and docs/guide/config.md -------------------

namespace {

using agv::config::Key;
using agv::config::KeyType;
using agv::config::Value;

bool same_value(const Value& a, const Value& b) {
  if (a.index() != b.index()) return false;
  if (const auto* x = std::get_if<double>(&a)) {
    const double y = std::get<double>(b);
    return std::fabs(*x - y) <= 1e-9 * std::max(1.0, std::fabs(y));
  }
  return a == b;
}

// YAML for a set of dotted keys ("can.odometry.id" -> "0x123"), nested by section.
std::string yaml_of(const std::map<std::string, std::string>& keys) {
  std::string out;
  std::vector<std::string> open;  // sections of the previous key
  for (const auto& [path, value] : keys) {
    std::vector<std::string> parts;
    for (std::size_t start = 0;;) {
      const std::size_t dot = path.find('.', start);
      parts.push_back(path.substr(start, dot - start));
      if (dot == std::string::npos) break;
      start = dot + 1;
    }
    std::size_t common = 0;
    while (common < open.size() && common + 1 < parts.size() && open[common] == parts[common]) {
      ++common;
    }
    for (std::size_t i = common; i + 1 < parts.size(); ++i) {
      out += std::string(2 * i, ' ') + parts[i] + ":\n";
    }
    out += std::string(2 * (parts.size() - 1), ' ') + parts.back() + ": " + value + "\n";
    open.assign(parts.begin(), parts.end() - 1);
  }
  return out;
}

std::map<std::string, std::string> live_base() {
  return {{"intrinsics.fx", "769.23"},
          {"intrinsics.fy", "769.23"},
          {"intrinsics.cx", "319.5"},
          {"intrinsics.cy", "239.5"}};
}

std::string yaml_scalar(const Key& k, const Value& v) {
  if (const auto* d = std::get_if<double>(&v)) {
    std::ostringstream os;
    os.precision(17);
    os << *d;
    return os.str();
  }
  if (k.type == KeyType::kString) return "\"" + std::get<std::string>(v) + "\"";
  return agv::config::format_value(k, v);
}

// Values other than the default that the key accepts, most likely valid first.
std::vector<Value> other_values(const Key& k) {
  std::vector<Value> out;
  switch (k.type) {
    case KeyType::kNumber: {
      const double def = k.required_live ? 700.0 : std::get<double>(k.def);
      for (double v : {def * 0.5, def * 1.5, k.lo + 0.25 * (k.hi - k.lo),
                       k.lo + 0.1 * (k.hi - k.lo), k.lo, k.hi}) {
        if (v >= k.lo && v <= k.hi && v != def) out.emplace_back(v);
      }
      break;
    }
    case KeyType::kInteger:
    case KeyType::kCanId: {
      const auto def = std::get<std::int64_t>(k.def);
      const auto lo = static_cast<std::int64_t>(k.lo), hi = static_cast<std::int64_t>(k.hi);
      for (std::int64_t v : {def / 2, def * 2, def + 1, lo + (hi - lo) / 4, lo, hi, 0x123L}) {
        if (v >= lo && v <= hi && v != def) out.emplace_back(v);
      }
      break;
    }
    case KeyType::kBool:
      out.emplace_back(!std::get<bool>(k.def));
      break;
    case KeyType::kChoice:
      for (const auto& c : k.choices) {
        if (c != std::get<std::string>(k.def)) out.emplace_back(c);
      }
      break;
    case KeyType::kString:
      // CPU lists (loop.*_cpus) are checked for their syntax.
      out.emplace_back(std::string(k.name.find("_cpus") != std::string::npos ? "0" : "test_value"));
      break;
  }
  return out;
}

}  // namespace

TEST(Config, DocsMatchTheKeyTable) {
  std::ifstream f(std::string(AGV_SOURCE_DIR) + "/docs/guide/config.md", std::ios::binary);
  ASSERT_TRUE(f) << "docs/guide/config.md missing";
  std::stringstream committed;
  committed << f.rdbuf();
  EXPECT_TRUE(committed.str() == agv::config::config_doc())
      << "docs/guide/config.md differs from the key table; regenerate it with\n"
         "  build/default/tools/config-doc/agvloc-config-doc > docs/guide/config.md";
}

TEST(Config, EveryDocumentedKeyIsInTheTableAndBack) {
  std::ifstream f(std::string(AGV_SOURCE_DIR) + "/docs/guide/config.md");
  std::set<std::string> documented;
  for (std::string line; std::getline(f, line);) {
    if (line.rfind("| `", 0) != 0) continue;
    const std::string key = line.substr(3, line.find('`', 3) - 3);
    const bool removed =
        std::any_of(agv::config::removed_keys().begin(), agv::config::removed_keys().end(),
                    [&](const auto& r) { return r.name == key; });
    if (!removed) documented.insert(key);
  }
  std::set<std::string> table;
  for (const Key& k : agv::config::config_keys()) table.insert(k.name);
  EXPECT_EQ(documented, table);
  EXPECT_EQ(table.size(), agv::config::config_keys().size()) << "a key is in the table twice";
}

TEST(Config, DefaultsEqualTheTable) {
  const Config built_in;
  Config parsed;
  std::vector<std::string> errors;
  ASSERT_TRUE(agv::config::parse_config(kIntrinsics, "", &parsed, &errors));
  for (const Key& k : agv::config::config_keys()) {
    if (k.required_live) continue;
    EXPECT_TRUE(same_value(k.get(built_in), k.def))
        << k.name << ": struct default " << agv::config::format_value(k, k.get(built_in))
        << ", table " << agv::config::format_value(k, k.def);
    EXPECT_TRUE(same_value(k.get(parsed), k.def)) << k.name << " after parsing";
  }
}

TEST(Config, EveryKeyRoundTrips) {
  for (const Key& k : agv::config::config_keys()) {
    bool one_accepted = false;
    for (const Value& v : other_values(k)) {
      auto keys = live_base();
      // vision_priority must stay below realtime_priority.
      if (k.name == "loop.vision_priority") keys["loop.realtime_priority"] = "99";
      // An address that is not loopback needs allow_remote.
      if (k.name == "diag.bind_address") keys["diag.allow_remote"] = "true";
      // The second camera, enabled, needs its calibration and the site file.
      if (k.name == "ranging_camera.enabled") {
        keys["ranging_camera.intrinsics.fx"] = "1000";
        keys["ranging_camera.intrinsics.fy"] = "1000";
        keys["ranging_camera.site"] = "site.yaml";
      }
      keys[k.name] = yaml_scalar(k, v);
      Config cfg;
      std::vector<std::string> errors;
      if (!agv::config::parse_config(yaml_of(keys), "", &cfg, &errors)) continue;  // a relation
      one_accepted = true;
      EXPECT_TRUE(same_value(k.get(cfg), v))
          << k.name << ": wrote " << yaml_scalar(k, v) << ", read "
          << agv::config::format_value(k, k.get(cfg));
      EXPECT_FALSE(same_value(k.get(cfg), k.get(Config{}))) << k.name << " kept its default";
      // No two keys share a field (a row pointing at the wrong member shows up here). Turning
      // the calibration off changes four noise defaults by design (FusionOdometryTiming...).
      if (k.name != "fusion.estimate_odometry_calibration") {
        auto without = keys;
        without.erase(k.name);
        Config base;
        // kReplay: without k an intrinsics key may be missing.
        ASSERT_TRUE(agv::config::parse_config(yaml_of(without), "", &base, &errors,
                                              agv::config::ConfigUse::kReplay));
        for (const Key& other : agv::config::config_keys()) {
          if (&other == &k) continue;
          EXPECT_TRUE(same_value(other.get(cfg), other.get(base)))
              << "setting " << k.name << " changed " << other.name;
        }
      }
      break;
    }
    EXPECT_TRUE(one_accepted) << k.name << ": no non-default value accepted";
  }
}

TEST(Config, EveryKeyChecksItsType) {
  for (const Key& k : agv::config::config_keys()) {
    if (k.type == KeyType::kString) continue;  // any scalar is a string
    auto keys = live_base();
    keys[k.name] = "[1, 2]";
    const auto e = errors_for(yaml_of(keys));
    EXPECT_TRUE(mentions(e, k.name + ": expected")) << k.name;
  }
}

TEST(Config, VisionFieldsOnceRejectedAreKeys) {
  // docs/design/vision.md listed these as settings while the reader rejected them.
  for (const char* name :
       {"coarse_border_px", "corner_rotations", "ring_dark_fraction", "max_corner_peaks",
        "qr_retries", "qr_target_module_px", "direction_from_qr_when_logo_weak", "band_rel",
        "tukey_c", "ransac_iterations", "metric", "pose_method", "heading_method",
        "outside_margin_mm"}) {
    EXPECT_NE(agv::config::find_key(std::string("vision.") + name), nullptr) << name;
  }
  Config cfg;
  std::vector<std::string> errors;
  ASSERT_TRUE(agv::config::parse_config(
      std::string(kIntrinsics) + "vision:\n  metric: linear_ratio\n  pose_method: paper_corner_a\n"
                                 "  tukey_c: 3\n  ransac_iterations: 0\n",
      "", &cfg, &errors))
      << errors.front();
  EXPECT_EQ(cfg.vision.metric, agv::vision::MetricMode::kLinearRatio);
  EXPECT_EQ(cfg.vision.pose_method, agv::vision::PoseMethod::kPaperCornerA);
  EXPECT_DOUBLE_EQ(cfg.vision.tukey_c, 3.0);
  EXPECT_EQ(cfg.vision.ransac_iterations, 0);
  EXPECT_TRUE(mentions(errors_for("vision:\n  corner_rotations: 33\n"),
                       "vision.corner_rotations: value 33 outside the accepted range [1, 32]"));
  EXPECT_TRUE(mentions(errors_for("vision:\n  heading_method: median\n"),
                       "vision.heading_method: 'median' is not one of: inverse_variance, mean, "
                       "weighted_000"));
}

// `agvloc run --print-dbc`: the contract of the configured vehicle states its rates.
TEST(Config, DbcCycleTimesFromTheConfiguredRates) {
  Config cfg;
  std::vector<std::string> errors;
  ASSERT_TRUE(agv::config::parse_config(
      std::string(kIntrinsics) + "loop:\n  output_rate_hz: 50\n  heartbeat_rate_hz: 2\n", "", &cfg,
      &errors));
  const auto pc = agv::config::protocol_config(cfg);
  EXPECT_DOUBLE_EQ(pc.output_period_ms, 20.0);
  EXPECT_DOUBLE_EQ(pc.heartbeat_period_ms, 500.0);
  const std::string dbc = agv::protocol::render_dbc(pc);
  EXPECT_NE(dbc.find("BA_ \"GenMsgCycleTime\" BO_ 768 20;"), std::string::npos);   // AGV_PoseXY
  EXPECT_NE(dbc.find("BA_ \"GenMsgCycleTime\" BO_ 773 500;"), std::string::npos);  // heartbeat
}

TEST(Config, MapIdentityGateFromTheConfiguration) {
  Config cfg;
  std::vector<std::string> errors;
  ASSERT_TRUE(agv::config::parse_config(std::string(kIntrinsics) +
                                            "vision:\n  identity:\n    gate_chi2: 11.34\n"
                                            "    clear_chi2: 40\n    min_pair_modules: 30\n",
                                        "", &cfg, &errors));
  EXPECT_DOUBLE_EQ(cfg.vision.identity.gate_chi2, 11.34);
  EXPECT_DOUBLE_EQ(cfg.vision.identity.clear_chi2, 40.0);
  EXPECT_EQ(cfg.vision.identity.min_pair_modules, 30);
  EXPECT_DOUBLE_EQ(cfg.vision.identity.min_agreement, 0.70);  // default kept
  // A runner-up inside the gate cannot be "clear".
  EXPECT_TRUE(mentions(errors_for(std::string(kIntrinsics) +
                                  "vision:\n  identity:\n    gate_chi2: 30\n    clear_chi2: 20\n"),
                       "vision.identity.clear_chi2: value 20 must exceed "
                       "vision.identity.gate_chi2"));
}

// The core keeps a floor-only twin (RangingAidConfig::floor_check) exactly when a second camera
// is configured: a turned rack camera must not veto the floor camera's fixes.
TEST(Config, TheSecondCameraTurnsOnTheFloorCheck) {
  Config cfg;
  EXPECT_FALSE(agv::app::localizer_config(cfg).ranging.floor_check);
  cfg.ranging_camera.enabled = true;
  EXPECT_TRUE(agv::app::localizer_config(cfg).ranging.floor_check);
}

TEST(Config, OneOdometryTimeout) {
  Config cfg;
  std::vector<std::string> errors;
  ASSERT_TRUE(agv::config::parse_config(
      std::string(kIntrinsics) + "can:\n  odometry:\n    timeout_ms: 250\n", "", &cfg, &errors));
  // One field from the YAML to its users (the core's pose validity and the filter's flag).
  EXPECT_EQ(cfg.fusion.health.odom_timeout_ns, 250'000'000);
  EXPECT_EQ(agv::app::localizer_config(cfg).fusion.health.odom_timeout_ns, 250'000'000);
  // The key reads back the value it was given.
  const auto* key = agv::config::find_key("can.odometry.timeout_ms");
  ASSERT_NE(key, nullptr);
  EXPECT_DOUBLE_EQ(std::get<double>(key->get(cfg)), 250.0);
  const auto e = errors_for(std::string(kIntrinsics) + "fusion:\n  odom_timeout_ms: 100\n");
  EXPECT_TRUE(mentions(e, "fusion.odom_timeout_ms: removed key; use can.odometry.timeout_ms"));
  EXPECT_EQ(agv::config::find_key("fusion.odom_timeout_ms"), nullptr);
  // The camera's clock offset moved to the camera's section, same value and sign.
  const auto t = errors_for(std::string(kIntrinsics) + "odometry:\n  time_offset_ms: 12\n");
  EXPECT_TRUE(mentions(t, "odometry.time_offset_ms: removed key; use camera.time_offset_ms"));
  EXPECT_EQ(agv::config::find_key("odometry.time_offset_ms"), nullptr);
}

TEST(Config, OdometryCorrectionKeysReachTheLocalizer) {
  Config cfg;
  std::vector<std::string> errors;
  ASSERT_TRUE(agv::config::parse_config(std::string(kIntrinsics) +
                                            "odometry:\n  speed_scale: 0.98\n  yaw_rate_scale: "
                                            "1.015\n  yaw_rate_bias_degps: -0.3\n  "
                                            "yaw_per_metre_deg: 0.46\ncamera:\n  "
                                            "time_offset_ms: 20.5\n",
                                        "", &cfg, &errors));
  const auto lc = agv::app::localizer_config(cfg);
  EXPECT_DOUBLE_EQ(lc.odometry.speed_scale, 0.98);
  EXPECT_DOUBLE_EQ(lc.odometry.yaw_rate_scale, 1.015);
  EXPECT_NEAR(lc.odometry.yaw_rate_bias_radps, -0.3 * M_PI / 180.0, 1e-15);
  EXPECT_NEAR(lc.odometry.yaw_per_metre_rad, 0.46 * M_PI / 180.0, 1e-15);
  EXPECT_DOUBLE_EQ(lc.fusion.slip.wheel_track_mm, 500.0);  // can.odometry.track_width_mm's default
  EXPECT_EQ(lc.time_base.camera_offset_ns, 20'500'000);
  // Defaults: no correction.
  Config def;
  ASSERT_TRUE(agv::config::parse_config(kIntrinsics, "", &def, &errors));
  const auto ld = agv::app::localizer_config(def);
  EXPECT_EQ(ld.odometry.speed_scale, 1.0);
  EXPECT_EQ(ld.odometry.yaw_rate_scale, 1.0);
  EXPECT_EQ(ld.odometry.yaw_rate_bias_radps, 0.0);
  EXPECT_EQ(ld.odometry.yaw_per_metre_rad, 0.0);
  EXPECT_EQ(ld.time_base.camera_offset_ns, 0);
  EXPECT_TRUE(mentions(errors_for(std::string(kIntrinsics) + "odometry:\n  speed_scale: 0\n"),
                       "odometry.speed_scale: value 0 outside the accepted range"));
}

namespace {

// Keeps the receive filters the output loop installs.
class FilterBus final : public agv::hal::CanBus {
 public:
  agv::hal::CanStatus send(const agv::hal::CanFrame&) override { return agv::hal::CanStatus::kOk; }
  agv::hal::CanStatus receive(agv::hal::CanFrame*, std::int64_t) override {
    return agv::hal::CanStatus::kTimeout;
  }
  agv::hal::CanStatus set_filters(const agv::hal::CanFilter* f, std::size_t n) override {
    filters.assign(f, f + n);
    return agv::hal::CanStatus::kOk;
  }
  agv::hal::CanBusState state() const override { return agv::hal::CanBusState::kErrorActive; }
  agv::hal::CanErrorCounters error_counters() const override { return {}; }
  agv::hal::CanStats stats() const override { return {}; }
  const char* last_error() const override { return ""; }
  std::vector<agv::hal::CanFilter> filters;
};

}  // namespace

TEST(Config, GyroAndImuKeysReachTheLocalizerAndTheReceiveFilters) {
  Config cfg;
  std::vector<std::string> errors;
  ASSERT_TRUE(agv::config::parse_config(std::string(kIntrinsics) +
                                            "can:\n  gyro:\n    enabled: true\n    id: 0x2A0\n"
                                            "    protected: false\n    timeout_ms: 40\n"
                                            "imu:\n  scale: 1.01\n  bias_degps: 0.2\n"
                                            "  time_offset_ms: -3.5\n",
                                        "", &cfg, &errors))
      << errors.front();
  const auto lc = agv::app::localizer_config(cfg);
  EXPECT_TRUE(lc.protocol.gyro.enabled);
  EXPECT_EQ(lc.protocol.gyro.can_id, 0x2A0u);
  EXPECT_FALSE(lc.protocol.gyro.protected_e2e);
  EXPECT_EQ(lc.gyro_timeout_ns, 40'000'000);
  EXPECT_DOUBLE_EQ(lc.gyro.scale, 1.01);
  EXPECT_NEAR(lc.gyro.bias_radps, 0.2 * M_PI / 180.0, 1e-15);
  EXPECT_EQ(lc.time_base.gyro_offset_ns, -3'500'000);
  // The output loop installs one receive filter per enabled input: odometry and gyro.
  agv::localizer::Localizer core(lc);
  FilterBus bus;
  agv::adapters::SteppedClock clock;
  agv::app::FixRing fixes;
  agv::app::OutputLoop loop(core, &bus, clock, nullptr, fixes, 0);
  ASSERT_EQ(bus.filters.size(), 2u);
  EXPECT_EQ(bus.filters[0].id, 0x311u);  // v_omega: MC_OdomTwist
  EXPECT_EQ(bus.filters[1].id, 0x2A0u);

  // Defaults: no gyro (one filter), no correction, 100 ms timeout.
  Config def;
  ASSERT_TRUE(agv::config::parse_config(kIntrinsics, "", &def, &errors));
  const auto ld = agv::app::localizer_config(def);
  EXPECT_FALSE(ld.protocol.gyro.enabled);
  EXPECT_EQ(ld.protocol.gyro.can_id, 0u);
  EXPECT_TRUE(ld.protocol.gyro.protected_e2e);
  EXPECT_EQ(ld.gyro_timeout_ns, 100'000'000);
  EXPECT_EQ(ld.gyro.scale, 1.0);
  EXPECT_EQ(ld.gyro.bias_radps, 0.0);
  EXPECT_EQ(ld.time_base.gyro_offset_ns, 0);
  agv::localizer::Localizer core_def(ld);
  FilterBus bus_def;
  agv::app::OutputLoop loop_def(core_def, &bus_def, clock, nullptr, fixes, 0);
  ASSERT_EQ(bus_def.filters.size(), 1u);
  EXPECT_EQ(bus_def.filters[0].id, 0x311u);
  EXPECT_TRUE(mentions(errors_for(std::string(kIntrinsics) + "imu:\n  scale: 3\n"),
                       "imu.scale: value 3 outside the accepted range"));
}
