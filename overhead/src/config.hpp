// agvloc-overhead's configuration (docs/guide/overhead.md "Configuration"): one YAML file, read
// through a key table in the style of the vehicle's (algo/include/agv/config/keys.hpp): every key
// has a type, range, unit, default and one line of documentation; the checker, the defaults and
// the guide's key table come from that one table. Unknown or duplicate keys are errors naming the
// key and the line.
#pragma once

#include <cstdint>
#include <functional>
#include <map>
#include <string>
#include <variant>
#include <vector>

#include "agv/overhead/search.hpp"
#include "agv/overhead/tag_detect.hpp"
#include "agv/overhead/tracker.hpp"

namespace agv::overhead_app {

struct MqttOutput {
  bool enabled = false;
  std::string broker_host = "localhost";
  int port = 1883;
  std::string interface_name = "agvloc-overhead";
  std::string manufacturer = "agvloc";
  std::string version = "2.1.0";
  std::string map_id;  // empty: the site's name
};

struct OverheadConfig {
  overhead::TrackerParams tracker;
  overhead::SearchParams search;
  overhead::TagDetectParams detect;
  double output_rate_hz = 30.0;
  MqttOutput mqtt;
  // cameras.<id>.latency_ms: exposure to the frame's arrival at the tracker, by camera id.
  std::map<std::string, double> camera_latency_ms;
};

enum class KeyType { kNumber, kInteger, kBool, kString, kChoice };
using Value = std::variant<bool, std::int64_t, double, std::string>;

struct Key {
  std::string name;  // "tracker.gate_chi2"
  KeyType type = KeyType::kNumber;
  double lo = 0.0, hi = 0.0;
  std::vector<std::string> choices;
  std::string unit;
  Value def;
  std::string doc;
  std::function<Value(const OverheadConfig&)> get;
  std::function<void(OverheadConfig&, const Value&)> set;
};

const std::vector<Key>& config_keys();

// cameras.<id>.latency_ms (not in the table: one per camera id).
inline constexpr double kMaxCameraLatencyMs = 1000.0;

// Parses a configuration text. False with one line per problem in *errors ("line 4:
// tracker.gate_chi2: value 0 outside the accepted range 1..1000"). Keys missing from the text keep
// their defaults.
bool parse_config(const std::string& text, OverheadConfig* out, std::vector<std::string>* errors);

// Reads and parses a file (a regular file of at most 1 MiB); errors prefixed with the path.
bool load_config(const std::string& path, OverheadConfig* out, std::vector<std::string>* errors);

// A name usable as one MQTT topic level (not empty, no '/', '+', '#', NUL or control character).
bool topic_level_ok(const std::string& s);

std::string format_value(const Key& key, const Value& v);
std::string format_range(const Key& key);
// The key table as Markdown, the part of docs/guide/overhead.md between its
// "<!-- keys: begin -->" and "<!-- keys: end -->" markers.
std::string config_keys_doc();

}  // namespace agv::overhead_app
