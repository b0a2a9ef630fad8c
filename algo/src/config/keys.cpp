#include "agv/config/keys.hpp"

#include <cstdio>
#include <sstream>

#include "key_builders.hpp"

namespace agv::config {

std::string Key::section() const { return name.substr(0, name.rfind('.')); }
std::string Key::leaf() const { return name.substr(name.rfind('.') + 1); }

const std::vector<Key>& config_keys() {
  static const std::vector<Key> keys = [] {
    std::vector<Key> k;
    detail::add_vehicle_keys(&k);
    detail::add_vision_keys(&k);
    detail::add_fusion_keys(&k);
    detail::add_replay_keys(&k);
    detail::add_vda5050_keys(&k);
    detail::add_diag_keys(&k);
    detail::add_ranging_camera_keys(&k);
    return k;
  }();
  return keys;
}

const std::vector<RemovedKey>& removed_keys() {
  // One odometry timeout: the filter's odometry flag and the pose validity used to
  // have separate timeouts that could disagree.
  // The camera's clock offset is the camera's (one time base): the same value and sign. One
  // track width for the CAN decoding and the fusion's slip lever arm.
  static const std::vector<RemovedKey> removed = {
      {"fusion.odom_timeout_ms", "can.odometry.timeout_ms"},
      {"odometry.time_offset_ms", "camera.time_offset_ms"},
      {"fusion.wheel_track_mm", "can.odometry.track_width_mm"},
  };
  return removed;
}

const Key* find_key(const std::string& name) {
  for (const Key& k : config_keys()) {
    if (k.name == name) return &k;
  }
  return nullptr;
}

namespace {

std::string fmt_number(double v) {
  std::ostringstream os;
  os << v;
  return os.str();
}

std::string hex(std::int64_t v) {
  char buf[24];
  std::snprintf(buf, sizeof buf, "0x%llX", static_cast<unsigned long long>(v));
  return buf;
}

}  // namespace

std::string format_value(const Key& key, const Value& v) {
  if (const auto* d = std::get_if<double>(&v)) return fmt_number(*d);
  if (const auto* i = std::get_if<std::int64_t>(&v)) {
    return key.type == KeyType::kCanId && *i != 0 ? hex(*i) : std::to_string(*i);
  }
  if (const auto* b = std::get_if<bool>(&v)) return *b ? "true" : "false";
  const std::string& s = std::get<std::string>(v);
  return s.empty() ? "\"\"" : s;
}

std::string format_range(const Key& key) {
  switch (key.type) {
    case KeyType::kNumber:
    case KeyType::kInteger:
      return fmt_number(key.lo) + ".." + fmt_number(key.hi);
    case KeyType::kCanId:
      return "0.." + hex(static_cast<std::int64_t>(key.hi)) + " (0.." + hex(kCanExtendedIdMax) +
             " with can.extended_ids)";
    case KeyType::kBool:
      return "true, false";
    case KeyType::kString:
      return "string";
    case KeyType::kChoice: {
      std::string s;
      for (const auto& c : key.choices) s += (s.empty() ? "" : ", ") + c;
      return s;
    }
  }
  return "";
}

}  // namespace agv::config
