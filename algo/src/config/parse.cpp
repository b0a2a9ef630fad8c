// parse_config: walks the key table (keys.hpp) over the YAML tree. Everything key-specific is in
// the table; what is here is the walk, the relations between keys and the final validations.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <string>

#include "agv/config/cpu_list.hpp"
#include "agv/config/keys.hpp"
#include "key_builders.hpp"
#include "yaml_checker.hpp"

namespace agv::config {

namespace {

std::string leaf_of(const std::string& path) { return path.substr(path.rfind('.') + 1); }
std::string parent_of(const std::string& path) {
  const auto dot = path.rfind('.');
  return dot == std::string::npos ? std::string() : path.substr(0, dot);
}

// Reads one key into cfg. The value goes through get and set even when the key is absent, so a
// unit conversion is applied the same way whether a key is given or defaulted.
void read_key(YamlChecker& c, const YAML::Node& n, const Key& k, Config* cfg) {
  const std::string sec = k.section();
  const std::string leaf = k.leaf();
  const char* key = leaf.c_str();
  Value v = k.get(*cfg);
  switch (k.type) {
    case KeyType::kNumber:
      c.number(n, sec, key, k.lo, k.hi, &std::get<double>(v));
      break;
    case KeyType::kInteger:
      c.integer(n, sec, key, static_cast<std::int64_t>(k.lo), static_cast<std::int64_t>(k.hi),
                &std::get<std::int64_t>(v));
      break;
    case KeyType::kCanId:
      c.integer(n, sec, key, static_cast<std::int64_t>(k.lo),
                cfg->can.extended_ids ? kCanExtendedIdMax : static_cast<std::int64_t>(k.hi),
                &std::get<std::int64_t>(v));
      break;
    case KeyType::kBool:
      c.boolean(n, sec, key, &std::get<bool>(v));
      break;
    case KeyType::kString:
      c.string(n, sec, key, &std::get<std::string>(v));
      break;
    case KeyType::kChoice:
      c.choice(n, sec, key, k.choices, &std::get<std::string>(v));
      break;
  }
  k.set(*cfg, v);
}

void read_section(YamlChecker& c, const YAML::Node& parent, const Section& s, ConfigUse use,
                  Config* cfg) {
  const std::string leaf = leaf_of(s.path);
  const YAML::Node n = c.section(parent, parent_of(s.path), leaf.c_str());
  if (use == ConfigUse::kLive) {
    // No default: a wrong focal length scales every fix, so a missing calibration is an error.
    std::vector<std::string> required;
    for (const Key& k : config_keys()) {
      if (k.required_live && k.section() == s.path) required.push_back(k.leaf());
    }
    if (!required.empty()) {
      if (!parent.IsMap() || !parent[leaf]) {
        std::string list;
        for (const auto& r : required) list += (list.empty() ? "" : ", ") + r;
        c.error(s.path, "missing section (" + list + " are required: " + s.required_why + ")");
      } else if (n.IsMap()) {
        for (const auto& r : required) c.require(n, s.path, r.c_str(), s.required_why);
      }
    }
  }
  for (const Key& k : config_keys()) {
    if (k.section() == s.path) read_key(c, n, k, cfg);
  }
  for (const Section& child : config_sections()) {
    if (parent_of(child.path) == s.path) read_section(c, n, child, use, cfg);
  }
  c.finish_map(n, s.path);
}

std::string num_text(double v) {
  char b[32];
  std::snprintf(b, sizeof b, "%g", v);
  return b;
}

std::string ms_text(std::int64_t ns) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%g", static_cast<double>(ns) / 1e6);
  return buf;
}

// A Linux network interface name (dev_valid_name): 1..15 bytes (IFNAMSIZ 16 with the NUL), no
// '/', ':', whitespace or NUL, not "." or "..". Anything else never opens, and the live loop
// would retry it forever.
void check_can_interface(YamlChecker& c, const std::string& name) {
  constexpr size_t kMaxIfName = 15;
  std::string why;
  if (name.empty() || name.size() > kMaxIfName) {
    why = std::to_string(name.size()) + " characters, a Linux interface name has 1.." +
          std::to_string(kMaxIfName);
  } else if (name == "." || name == "..") {
    why = "not an interface name";
  } else {
    for (const char ch : name) {
      const auto u = static_cast<unsigned char>(ch);
      if (ch == '/' || ch == ':' || u <= 0x20 || u == 0x7f) {
        why =
            "contains a character an interface name cannot have ('/', ':', a space or control "
            "character)";
        break;
      }
    }
  }
  if (!why.empty()) c.error("can.interface", why);
}

// Relations between keys (each value is already in its own range here).
void check_relations(YamlChecker& c, const Config& cfg) {
  const LoopSection& s = cfg.loop;
  if (s.vision_priority > 0 && s.vision_priority >= s.realtime_priority) {
    c.error("loop.vision_priority", "value " + std::to_string(s.vision_priority) +
                                        " must be below loop.realtime_priority (" +
                                        std::to_string(s.realtime_priority) +
                                        ") so vision can never delay the fixed-rate output");
  }
  std::vector<int> rt_cpus, vision_cpus, service_cpus;
  std::string why;
  if (!parse_cpu_list(s.realtime_cpus, &rt_cpus, &why)) c.error("loop.realtime_cpus", why);
  if (!parse_cpu_list(s.vision_cpus, &vision_cpus, &why)) c.error("loop.vision_cpus", why);
  if (!parse_cpu_list(s.service_cpus, &service_cpus, &why)) c.error("loop.service_cpus", why);
  for (const int cpu : service_cpus) {
    if (std::find(rt_cpus.begin(), rt_cpus.end(), cpu) != rt_cpus.end()) {
      c.error("loop.service_cpus", "CPU " + std::to_string(cpu) +
                                       " is also in loop.realtime_cpus; the services would share "
                                       "a core with the output thread");
      break;
    }
  }
  const double half_period_us = 0.5e6 / s.output_rate_hz;
  if (static_cast<double>(s.spin_before_deadline_us) > half_period_us) {
    c.error("loop.spin_before_deadline_us",
            "value " + std::to_string(s.spin_before_deadline_us) +
                " exceeds half the output period (" +
                std::to_string(static_cast<int>(half_period_us)) + " us at loop.output_rate_hz " +
                std::to_string(static_cast<int>(s.output_rate_hz)) + ")");
  }
  const fusion::EkfConfig& f = cfg.fusion;
  // Every replayed fix would arrive later than fusion accepts: all "too old", zero fixes fused.
  if (cfg.replay_fix_delay_ms * 1e6 > static_cast<double>(f.fix.max_delay_ns)) {
    c.error("replay.fix_delay_ms", "value " + ms_text(std::llround(cfg.replay_fix_delay_ms * 1e6)) +
                                       " exceeds fusion.max_fix_delay_ms (" +
                                       ms_text(f.fix.max_delay_ns) +
                                       "): every replayed fix would be dropped as too old");
  }
  const vision::MapIdentityConfig& id = cfg.vision.identity;
  if (!(id.clear_chi2 > id.gate_chi2)) {
    c.error("vision.identity.clear_chi2",
            "value " + num_text(id.clear_chi2) + " must exceed vision.identity.gate_chi2 (" +
                num_text(id.gate_chi2) + "): a runner-up inside the gate would count as clear");
  }
  check_can_interface(c, cfg.can.interface);
  const detail::KeyError key_error = [&c](const std::string& key, const std::string& what) {
    c.error(key, what);
  };
  detail::check_vda5050_values(cfg, key_error);
  detail::check_diag_values(cfg, key_error);
  detail::check_ranging_camera_values(cfg, key_error);
  // One gyro source: a CAN gyro enabled beside another source would be fused twice or not at all.
  if (cfg.can.gyro_enabled && cfg.imu.source != ImuSource::kCan) {
    c.error("imu.source", std::string("'") + imu_source_name(cfg.imu.source) +
                              "' with can.gyro.enabled: true; choose one gyro source (imu.source: "
                              "can for AGV_Gyro)");
  }
  if (cfg.imu.source == ImuSource::kIio && cfg.imu.iio_device.empty()) {
    c.error("imu.iio_device", "missing: imu.source iio needs the IIO device's name");
  }
  // The configuration's own names for what fusion::validate would name by its struct fields.
  if (f.odometry.gap_ns < f.odometry.period_ns) {
    c.error("fusion.odom_gap_ms", "value " + ms_text(f.odometry.gap_ns) +
                                      " must be at least fusion.odom_period_ms (" +
                                      ms_text(f.odometry.period_ns) + ")");
    return;  // fusion::validate would say it again by the struct's field names
  }
  const std::string err = fusion::validate(cfg.fusion);
  if (!err.empty()) c.error("fusion", err);
}

bool parse_root(const YAML::Node& root, const std::string& base_dir, ConfigUse use, Config* out,
                std::vector<std::string>* errors) {
  if (!root.IsMap()) {
    errors->push_back("top level: expected a mapping of sections (camera:, can:, ...)");
    return false;
  }
  Config cfg = *out;
  YamlChecker c;
  for (const RemovedKey& r : removed_keys()) c.removed(r.name, r.replacement);
  for (const Section& s : config_sections()) {
    if (parent_of(s.path).empty()) read_section(c, root, s, use, &cfg);
  }
  cfg.camera_model.intrinsics.width_px = cfg.camera.camera.width_px;
  cfg.camera_model.intrinsics.height_px = cfg.camera.camera.height_px;
  cfg.ranging_camera.intrinsics.width_px = cfg.ranging_camera.camera.width_px;
  cfg.ranging_camera.intrinsics.height_px = cfg.ranging_camera.camera.height_px;
  if (!cfg.map_file.empty() && !base_dir.empty() &&
      std::filesystem::path(cfg.map_file).is_relative()) {
    cfg.map_file = (std::filesystem::path(base_dir) / cfg.map_file).lexically_normal().string();
  }
  for (std::string* f :
       {&cfg.vda5050.password_file, &cfg.vda5050.tls_ca_file, &cfg.ranging_camera.site_file}) {
    if (!f->empty() && !base_dir.empty() && std::filesystem::path(*f).is_relative()) {
      *f = (std::filesystem::path(base_dir) / *f).lexically_normal().string();
    }
  }
  check_relations(c, cfg);
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

protocol::ProtocolConfig protocol_config(const Config& cfg) {
  protocol::ProtocolConfig p;
  p.base_id = cfg.can.base_id;
  p.extended_ids = cfg.can.extended_ids;
  p.odometry.mode = cfg.can.odometry_mode;
  p.odometry.can_id = cfg.can.odometry_id;
  p.odometry.extended_id = cfg.can.extended_ids;
  p.odometry.protected_e2e = cfg.can.odometry_protected;
  p.odometry.track_width_mm = cfg.fusion.slip.wheel_track_mm;
  p.odometry.speed_scale = cfg.can.wheel_speed_scale;
  p.output_period_ms = 1000.0 / cfg.loop.output_rate_hz;
  p.heartbeat_period_ms = 1000.0 / cfg.loop.heartbeat_rate_hz;
  p.gyro.enabled = cfg.can.gyro_enabled;
  p.gyro.can_id = cfg.can.gyro_id;
  p.gyro.protected_e2e = cfg.can.gyro_protected;
  return p;
}

}  // namespace agv::config
