#include "config.hpp"

#include <cstdio>
#include <filesystem>

#include "agv/recording/recording.hpp"
#include "yaml_checker.hpp"

namespace agv::config {

namespace {

void read_camera(YamlChecker& c, const YAML::Node& root, CameraSection* s) {
  const YAML::Node n = c.section(root, "", "camera");
  c.choice(n, "camera", "driver", {"libcamera", "v4l2", "replay"}, &s->driver);
  c.string(n, "camera", "id", &s->camera.id);
  c.string(n, "camera", "model", &s->camera.model);
  c.integer(n, "camera", "width", 16, 8192, &s->camera.width_px);
  c.integer(n, "camera", "height", 16, 8192, &s->camera.height_px);
  c.number(n, "camera", "fps", 1.0, 240.0, &s->camera.fps);
  c.integer(n, "camera", "exposure_us", 10, 100000, &s->camera.exposure_us);
  c.number(n, "camera", "analogue_gain", 1.0, 64.0, &s->camera.analogue_gain);
  std::string pf = "auto";
  c.choice(n, "camera", "pixel_format", {"auto", "gray", "yuv"}, &pf);
  s->camera.pixel_format = pf == "gray"  ? hal::PixelFormatPreference::kGray
                           : pf == "yuv" ? hal::PixelFormatPreference::kYuv
                                         : hal::PixelFormatPreference::kAuto;
  c.integer(n, "camera", "buffer_count", 2, 16, &s->camera.buffer_count);
  c.integer(n, "camera", "readout_us", 0, 100000, &s->camera.readout_us);
  c.number(n, "camera", "timeout_ms", 10.0, 60000.0, &s->timeout_ms);
  c.finish_map(n, "camera");
}

void read_intrinsics(YamlChecker& c, const YAML::Node& root, CameraModel* m, bool required) {
  const YAML::Node n = c.section(root, "", "intrinsics");
  auto& k = m->intrinsics;
  if (required) {
    // No default: a wrong focal length scales every fix, so a missing calibration is an error.
    const std::string why = "the camera calibration, docs/camera.md";
    if (!root["intrinsics"]) {
      c.error("intrinsics", "missing section (fx, fy, cx, cy are required: " + why + ")");
    } else if (n.IsMap()) {
      for (const char* key : {"fx", "fy", "cx", "cy"}) c.require(n, "intrinsics", key, why);
    }
  }
  c.number(n, "intrinsics", "fx", 1.0, 1e6, &k.fx);
  c.number(n, "intrinsics", "fy", 1.0, 1e6, &k.fy);
  c.number(n, "intrinsics", "cx", -1e5, 1e5, &k.cx);
  c.number(n, "intrinsics", "cy", -1e5, 1e5, &k.cy);
  c.number(n, "intrinsics", "k1", -10.0, 10.0, &k.k1);
  c.number(n, "intrinsics", "k2", -10.0, 10.0, &k.k2);
  c.number(n, "intrinsics", "p1", -1.0, 1.0, &k.p1);
  c.number(n, "intrinsics", "p2", -1.0, 1.0, &k.p2);
  c.number(n, "intrinsics", "k3", -10.0, 10.0, &k.k3);
  c.finish_map(n, "intrinsics");
}

void read_mounting(YamlChecker& c, const YAML::Node& root, CameraMount* m) {
  const YAML::Node n = c.section(root, "", "mounting");
  c.number(n, "mounting", "offset_x_mm", -5000.0, 5000.0, &m->offset_x_mm);
  c.number(n, "mounting", "offset_y_mm", -5000.0, 5000.0, &m->offset_y_mm);
  double yaw_deg = rad_to_deg(m->yaw_rad);
  c.number(n, "mounting", "yaw_deg", -180.0, 180.0, &yaw_deg);
  m->yaw_rad = deg_to_rad(yaw_deg);
  c.number(n, "mounting", "height_mm", 10.0, 5000.0, &m->height_mm);
  c.finish_map(n, "mounting");
}

void read_can(YamlChecker& c, const YAML::Node& root, CanSection* s) {
  const YAML::Node n = c.section(root, "", "can");
  c.string(n, "can", "interface", &s->interface);
  c.boolean(n, "can", "extended_ids", &s->extended_ids);
  std::int64_t base = s->base_id;
  c.integer(n, "can", "base_id", 0, s->extended_ids ? 0x1FFFFFFF : 0x7FF, &base);
  s->base_id = static_cast<std::uint32_t>(base);
  const YAML::Node o = c.section(n, "can", "odometry");
  c.choice(o, "can.odometry", "mode", {"v_omega", "wheels"}, &s->odometry_mode);
  std::int64_t oid = s->odometry_id;
  c.integer(o, "can.odometry", "id", 0, s->extended_ids ? 0x1FFFFFFF : 0x7FF, &oid);
  s->odometry_id = static_cast<std::uint32_t>(oid);
  c.boolean(o, "can.odometry", "protected", &s->odometry_protected);
  c.number(o, "can.odometry", "track_width_mm", 50.0, 5000.0, &s->track_width_mm);
  c.number(o, "can.odometry", "wheel_speed_scale", 0.5, 2.0, &s->wheel_speed_scale);
  c.number(o, "can.odometry", "timeout_ms", 5.0, 10000.0, &s->odometry_timeout_ms);
  c.finish_map(o, "can.odometry");
  c.finish_map(n, "can");
}

void read_loop(YamlChecker& c, const YAML::Node& root, LoopSection* s) {
  const YAML::Node n = c.section(root, "", "loop");
  c.number(n, "loop", "output_rate_hz", 1.0, 1000.0, &s->output_rate_hz);
  c.number(n, "loop", "heartbeat_rate_hz", 0.1, 100.0, &s->heartbeat_rate_hz);
  c.integer(n, "loop", "realtime_priority", 0, 99, &s->realtime_priority);
  c.integer(n, "loop", "vision_priority", 0, 98, &s->vision_priority);
  c.integer(n, "loop", "spin_before_deadline_us", 0, 2000, &s->spin_before_deadline_us);
  c.boolean(n, "loop", "lock_memory", &s->lock_memory);
  c.number(n, "loop", "log_period_s", 0.0, 3600.0, &s->log_period_s);
  c.boolean(n, "loop", "pose_on_fix", &s->pose_on_fix);
  c.finish_map(n, "loop");
  // Relations between keys (each value is already in its own range here).
  if (s->vision_priority > 0 && s->vision_priority >= s->realtime_priority) {
    c.error("loop.vision_priority", "value " + std::to_string(s->vision_priority) +
                                        " must be below loop.realtime_priority (" +
                                        std::to_string(s->realtime_priority) +
                                        ") so vision can never delay the fixed-rate output");
  }
  const double half_period_us = 0.5e6 / s->output_rate_hz;
  if (static_cast<double>(s->spin_before_deadline_us) > half_period_us) {
    c.error("loop.spin_before_deadline_us",
            "value " + std::to_string(s->spin_before_deadline_us) +
                " exceeds half the output period (" +
                std::to_string(static_cast<int>(half_period_us)) + " us at loop.output_rate_hz " +
                std::to_string(static_cast<int>(s->output_rate_hz)) + ")");
  }
}

}  // namespace

namespace {

bool parse_root(const YAML::Node& root, const std::string& base_dir, ConfigUse use, Config* out,
                std::vector<std::string>* errors) {
  Config cfg = *out;
  YamlChecker c;
  if (!root.IsMap()) {
    errors->push_back("top level: expected a mapping of sections (camera:, can:, ...)");
    return false;
  }
  read_camera(c, root, &cfg.camera);
  cfg.camera_model.intrinsics.width_px = cfg.camera.camera.width_px;
  cfg.camera_model.intrinsics.height_px = cfg.camera.camera.height_px;
  read_intrinsics(c, root, &cfg.camera_model, use == ConfigUse::kLive);
  read_mounting(c, root, &cfg.camera_model.mount);
  const YAML::Node lm = c.section(root, "", "landmark");
  c.number(lm, "landmark", "size_mm", 10.0, 1000.0, &cfg.landmark_size_mm);
  c.string(lm, "landmark", "map", &cfg.map_file);
  c.finish_map(lm, "landmark");
  if (!cfg.map_file.empty() && !base_dir.empty() &&
      std::filesystem::path(cfg.map_file).is_relative()) {
    cfg.map_file = (std::filesystem::path(base_dir) / cfg.map_file).lexically_normal().string();
  }
  read_can(c, root, &cfg.can);
  read_loop(c, root, &cfg.loop);
  read_algo_sections(c, root, &cfg);
  if (c.errors().empty()) {
    const std::string perr = protocol::validate(protocol_config(cfg));
    if (!perr.empty()) c.error("can", perr);
  }
  c.finish_map(root, "");
  if (!c.errors().empty()) {
    *errors = c.errors();
    return false;
  }
  *out = cfg;
  return true;
}

}  // namespace

bool parse_config(const std::string& yaml_text, const std::string& base_dir, Config* out,
                  std::vector<std::string>* errors, ConfigUse use) {
  YAML::Node root;
  try {
    root = YAML::Load(yaml_text);
  } catch (const YAML::Exception& e) {
    errors->push_back("YAML syntax error at line " + std::to_string(e.mark.line + 1) + ": " +
                      e.msg);
    return false;
  }
  try {
    return parse_root(root, base_dir, use, out, errors);
  } catch (const std::exception& e) {
#ifdef FUZZING_BUILD_MODE_UNSAFE_FOR_PRODUCTION
    throw;  // fuzz_config: an exception here is a finding (the checker should have named it)
#endif
    // The checker never lets yaml-cpp throw on any input the fuzzer found; should a new yaml-cpp
    // do so, it is still a configuration error and not an abort.
    errors->push_back(std::string("cannot read the configuration: ") + e.what());
    return false;
  }
}

bool load_config_or_report(const std::string& path, const char* who, Config* out, ConfigUse use) {
  std::vector<std::string> errors;
  if (load_config(path, out, &errors, use)) return true;
  for (const auto& e : errors) std::fprintf(stderr, "%s: config: %s\n", who, e.c_str());
  return false;
}

bool load_map_file(const std::string& path, LandmarkMap* map, std::string* error) {
  std::string text, e;
  if (!recording::read_file_bounded(path, kMaxMapBytes, &text, &e)) {
    *error = e;
    return false;
  }
  if (!parse_landmark_map(text, map, &e)) {
    *error = path + ": " + e;
    return false;
  }
  return true;
}

bool load_config(const std::string& path, Config* out, std::vector<std::string>* errors,
                 ConfigUse use) {
  std::string text, read_error;
  if (!recording::read_file_bounded(path, kMaxConfigBytes, &text, &read_error)) {
    errors->push_back(read_error);
    return false;
  }
  out->source = path;
  const std::string dir = std::filesystem::path(path).parent_path().string();
  if (!parse_config(text, dir, out, errors, use)) {
    for (auto& e : *errors) e = path + ": " + e;
    return false;
  }
  return true;
}

}  // namespace agv::config
