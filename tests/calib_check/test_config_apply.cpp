// agvloc-desk config apply: the intrinsics and vehicle snippets were merged by hand
// (a second `camera:` or `mounting:` section is a duplicate key). Now one command merges them
// into the configuration, keeps its comments, refuses conflicts and unknown keys by name, and
// writes only a result the configuration checker accepts.
#include <gtest/gtest.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include "../support/desk_command.hpp"
#include "../support/fresh_dir.hpp"
#include "agv/config/config.hpp"
#include "calib_intrinsics.hpp"
#include "commands.hpp"
#include "config_apply.hpp"

namespace fs = std::filesystem;
using agv::desk::config_apply::Merged;
using agv::desk::config_apply::Text;

namespace {

// The shape of firmware/config/agvloc.yaml: block sections, comments after values.
const std::string kBase =
    "# vehicle 7\n"
    "camera:\n"
    "  driver: v4l2             # the test machine has no libcamera\n"
    "  id: /dev/video0\n"
    "  width: 640\n"
    "  height: 480\n"
    "\n"
    "intrinsics:                # first guess from the data sheet\n"
    "  fx: 769.2307692\n"
    "  fy: 769.2307692\n"
    "  cx: 319.5\n"
    "  cy: 239.5\n"
    "\n"
    "mounting:\n"
    "  offset_x_mm: 250.0       # taped\n"
    "  offset_y_mm: 0.0\n"
    "  yaw_deg: 0.0             # image axes relative to the vehicle\n"
    "  height_mm: 200.0\n"
    "\n"
    "can:\n"
    "  interface: can0\n"
    "  odometry:\n"
    "    mode: v_omega\n";

// What `calibrate intrinsics` writes (its own generator).
std::string intrinsics_snippet(double fx) {
  agv::desk::calib::Result r;
  r.intrinsics.width_px = 640;
  r.intrinsics.height_px = 480;
  r.intrinsics.fx = fx;
  r.intrinsics.fy = 770.5;
  r.intrinsics.cx = 321.25;
  r.intrinsics.cy = 238.75;
  r.intrinsics.k1 = -0.12;
  r.usable = 28;
  r.rms_px = 0.058;
  return agv::desk::calib::config_snippet(r, "board/frames");
}

// What `calibrate vehicle` writes (format of cmd_calibrate_vehicle.cpp).
const std::string kVehicleSnippet =
    "# agvloc-desk calibrate vehicle calib1 (docs/guide/config.md keys)\n"
    "# Only parameters the drive determined are written; the others keep their value.\n"
    "mounting:\n"
    "  offset_x_mm: 253.6981  # sigma 0.0061 mm\n"
    "  offset_y_mm: -4.1930  # sigma 0.0120 mm\n"
    "  yaw_deg: 1.2905  # sigma 0.0040 deg\n"
    "  height_mm: 201.4977  # sigma 0.0021 mm\n"
    "  roll_deg: 0.8002  # sigma 0.0010 deg\n"
    "  # pitch_deg: not determined (trades off against offset_x_mm)\n"
    "odometry:\n"
    "  speed_scale: 1.020012  # sigma 0.000110\n"
    "  yaw_rate_scale: 0.985020  # sigma 0.000090\n"
    "  yaw_rate_bias_degps: 0.2999  # sigma 0.0010 deg/s\n"
    "camera:\n"
    "  time_offset_ms: 12.0210  # sigma 0.0500 ms\n";

std::string errors_text(const std::vector<std::string>& errors) {
  std::string s;
  for (const auto& e : errors) s += e + "\n";
  return s;
}

agv::config::Config parsed(const std::string& text) {
  agv::config::Config cfg;
  std::vector<std::string> errors;
  EXPECT_TRUE(agv::config::parse_config(text, "", &cfg, &errors)) << errors_text(errors) << text;
  return cfg;
}

fs::path fresh_dir(const std::string& name) {
  return agv::test_support::fresh_dir("cfgapply", name);
}

std::string slurp(const fs::path& p) {
  std::ifstream f(p, std::ios::binary);
  return std::string(std::istreambuf_iterator<char>(f), {});
}

// The rest of the line that starts with `start`, without the padding after it.
std::string line_of(const std::string& text, const std::string& start) {
  const std::string t = "\n" + text;
  const size_t at = t.find("\n" + start);
  if (at == std::string::npos) return "(no line " + start + ")";
  size_t from = at + 1 + start.size();
  while (from < t.size() && t[from] == ' ') ++from;
  return t.substr(from, t.find('\n', from) - from);
}

struct ApplyRun {
  int rc;
  std::string out, err;
};

ApplyRun apply(std::vector<std::string> args) {
  testing::internal::CaptureStdout();
  testing::internal::CaptureStderr();
  const int rc =
      agv::testsupport::run_command(agv::desk::config_apply_command, "apply", std::move(args));
  return {rc, testing::internal::GetCapturedStdout(), testing::internal::GetCapturedStderr()};
}

}  // namespace

TEST(ConfigApply, BothSnippetsMergeIntoTheConfigurationKeepingItsComments) {
  Merged m;
  std::vector<std::string> errors;
  ASSERT_TRUE(agv::desk::config_apply::merge(
      {"vehicle.yaml", kBase},
      {{"intrinsics.yaml", intrinsics_snippet(771.125)}, {"vc.yaml", kVehicleSnippet}}, &m,
      &errors))
      << errors_text(errors);
  EXPECT_TRUE(m.comments_kept);
  for (const char* kept :
       {"# vehicle 7\n", "  driver: v4l2             # the test machine has no libcamera\n",
        "intrinsics:                # first guess from the data sheet\n",
        "  offset_x_mm: 253.6981       # taped\n",
        "  yaw_deg: 1.2905             # image axes relative to the vehicle\n"}) {
    EXPECT_NE(m.text.find(kept), std::string::npos) << kept << "\n" << m.text;
  }
  const agv::config::Config cfg = parsed(m.text);
  EXPECT_EQ(cfg.camera_model.intrinsics.fx, 771.125);
  EXPECT_EQ(cfg.camera_model.intrinsics.k1, -0.12);  // new key in a section
  EXPECT_NEAR(cfg.camera_model.mount.roll_rad, 0.8002 * M_PI / 180.0, 1e-15);  // new key
  EXPECT_EQ(cfg.camera_model.mount.pitch_rad, 0.0);  // not determined: unchanged
  EXPECT_EQ(cfg.odometry.speed_scale, 1.020012);     // new section
  EXPECT_EQ(cfg.camera.time_offset_ms, 12.021);      // into the base's camera section
  EXPECT_EQ(cfg.camera.camera.id, "/dev/video0");
  ASSERT_FALSE(m.changes.empty());
  EXPECT_EQ(m.changes[0].key, "camera.width");
  EXPECT_EQ(m.changes[0].before, "640");
  EXPECT_EQ(m.changes[0].from, "intrinsics.yaml:6");
}

TEST(ConfigApply, FlowSectionsAndAnEmptyBaseAreEditedToo) {
  Merged m;
  std::vector<std::string> errors;
  ASSERT_TRUE(agv::desk::config_apply::merge(
      {"b.yaml",
       "intrinsics: {fx: 700, fy: 700, cx: 319.5, cy: 239.5}  # guess\n"
       "mounting: {height_mm: 200}\n"},
      {{"s.yaml", "intrinsics:\n  fx: 771\n  k1: -0.1\nmounting:\n  yaw_deg: 1.5\n"}}, &m, &errors))
      << errors_text(errors);
  EXPECT_TRUE(m.comments_kept) << m.text;
  EXPECT_NE(m.text.find("# guess"), std::string::npos) << m.text;
  const agv::config::Config cfg = parsed(m.text);
  EXPECT_EQ(cfg.camera_model.intrinsics.fx, 771.0);
  EXPECT_EQ(cfg.camera_model.intrinsics.k1, -0.1);
  EXPECT_NEAR(cfg.camera_model.mount.yaw_rad, 1.5 * M_PI / 180.0, 1e-15);

  ASSERT_TRUE(agv::desk::config_apply::merge({"empty.yaml", "# nothing yet\n"},
                                             {{"s.yaml", intrinsics_snippet(770.0)}}, &m, &errors))
      << errors_text(errors);
  EXPECT_EQ(parsed(m.text).camera_model.intrinsics.cy, 238.75);
}

TEST(ConfigApply, ConflictsAndUnknownKeysAreRefusedByName) {
  Merged m;
  std::vector<std::string> errors;
  // The same key from two snippets: refused when the values differ, fine when they agree.
  EXPECT_FALSE(agv::desk::config_apply::merge(
      {"vehicle.yaml", kBase},
      {{"a.yaml", intrinsics_snippet(771.125)}, {"b.yaml", intrinsics_snippet(772.5)}}, &m,
      &errors));
  EXPECT_EQ(errors_text(errors),
            "intrinsics.fx: a.yaml:9 sets 771.125, b.yaml:9 sets 772.5: apply one of them\n");
  errors.clear();
  EXPECT_TRUE(agv::desk::config_apply::merge(
      {"vehicle.yaml", kBase},
      {{"a.yaml", "mounting: {yaw_deg: 1.50}\n"}, {"b.yaml", "mounting:\n  yaw_deg: 1.5\n"}}, &m,
      &errors))
      << errors_text(errors);

  errors.clear();
  EXPECT_FALSE(agv::desk::config_apply::merge(
      {"vehicle.yaml", kBase},
      {{"s.yaml", "mounting:\n  offset_z_mm: 3\n  yaw_deg: 1\n  yaw_deg: 2\n"}}, &m, &errors));
  const std::string e = errors_text(errors);
  EXPECT_NE(e.find("s.yaml:2: mounting.offset_z_mm: not a configuration key"), std::string::npos)
      << e;
  EXPECT_NE(e.find("s.yaml:4: mounting.yaw_deg: given twice (first at line 3)"), std::string::npos)
      << e;
}

TEST(ConfigApply, CommandWritesOnlyWhatTheCheckerAcceptsAndNeverOverwritesSilently) {
  const fs::path d = fresh_dir("cmd");
  std::ofstream(d / "vehicle.yaml") << kBase;
  std::ofstream(d / "intrinsics.yaml") << intrinsics_snippet(771.125);
  std::ofstream(d / "vc.yaml") << kVehicleSnippet;
  const std::string base = (d / "vehicle.yaml").string(), out = (d / "merged.yaml").string();

  ApplyRun r = apply(
      {"--config", base, (d / "intrinsics.yaml").string(), (d / "vc.yaml").string(), "--out", out});
  ASSERT_EQ(r.rc, 0) << r.err;
  EXPECT_EQ(line_of(r.out, "  mounting.yaw_deg "),
            "0.0 -> 1.2905  [" + (d / "vc.yaml").string() + ":6]")
      << r.out;
  EXPECT_EQ(line_of(r.out, "  mounting.roll_deg "),
            "0.8002 (new)  [" + (d / "vc.yaml").string() + ":8]")
      << r.out;
  EXPECT_EQ(line_of(r.out, "  camera.width "),
            "640 (unchanged)  [" + (d / "intrinsics.yaml").string() + ":6]")
      << r.out;
  EXPECT_NE(r.out.find("8 changed, 10 new, 2 unchanged; wrote " + out), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("  mounting: offset_x_mm 253.698, offset_y_mm -4.193, yaw_deg 1.2905"),
            std::string::npos)
      << r.out;  // the --check-config summary of the result
  const std::string merged = slurp(out);
  EXPECT_EQ(merged.rfind("# agvloc-desk config apply --config " + base, 0), 0u) << merged;
  EXPECT_EQ(parsed(merged).odometry.yaw_rate_scale, 0.98502);
  EXPECT_EQ(slurp(base), kBase);  // the input is never touched

  // An existing --out, or --out = --config, needs --force.
  r = apply({"--config", base, (d / "vc.yaml").string(), "--out", out});
  EXPECT_EQ(r.rc, 2);
  EXPECT_NE(r.err.find("--out " + out + " exists; write elsewhere, or pass --force"),
            std::string::npos)
      << r.err;
  r = apply({"--config", base, (d / "vc.yaml").string(), "--out", base});
  EXPECT_EQ(r.rc, 2);
  EXPECT_NE(r.err.find("is the --config file"), std::string::npos) << r.err;
  EXPECT_EQ(slurp(base), kBase);
  r = apply({"--config", base, (d / "vc.yaml").string(), "--out", out, "--force"});
  EXPECT_EQ(r.rc, 0) << r.err;

  // A result --check-config would refuse (a speed scale of 0.327, as calibrate vehicle once
  // wrote, here by hand): named with the snippet that set it, nothing written.
  std::ofstream(d / "bad.yaml") << "odometry:\n  speed_scale: 0.327\n";
  const std::string out2 = (d / "merged2.yaml").string();
  r = apply({"--config", base, (d / "bad.yaml").string(), "--out", out2});
  EXPECT_EQ(r.rc, 2);
  EXPECT_NE(r.err.find("odometry.speed_scale"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("(set by " + (d / "bad.yaml").string() + ":2)"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("nothing written"), std::string::npos) << r.err;
  EXPECT_FALSE(fs::exists(out2));
  fs::remove_all(d);
}
