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

#include "agv/overhead/reacquire.hpp"
#include "agv/overhead/search.hpp"
#include "agv/overhead/tag_detect.hpp"
#include "agv/overhead/tracker.hpp"
#include "agv/overhead/tray_fit.hpp"
#include "topics.hpp"

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

// Per-camera detector processes (`detect`) and the tracker fed by them (`run
// --detections-from-broker`) meet on the output.mqtt broker under
// <topic_prefix>/detections/<camera>.
struct DetectionsBus {
  std::string topic_prefix = "agvloc-overhead";
};

// orders.*: `run` subscribes to <interface_name>/+/+/+/order on the output.mqtt broker and hands
// each fleet vehicle's order to the tracker as its route (order_intake.hpp).
struct OrdersIn {
  bool subscribe = false;
  std::string interface_name = "uagv";
};

// diag.*: the diagnostics page and /metrics of `run` (drivers/http, as the vehicle's).
struct DiagOutput {
  bool enabled = false;
  std::string bind_address = "127.0.0.1";
  int port = 8090;
  bool allow_remote = false;
  int max_clients = 4;
  int threads = 1;
  int view_width_px = 960;  // /camera/<index>.png: frames downscaled to at most this width
};

// cameras.<id>.*: one ceiling camera of the site (matched by id). The live settings are used by
// `run` and `record`, latency_ms by `replay` only (live frames are processed as they really
// arrive). driver: v4l2, libcamera or aravis.
struct CameraSettings {
  double latency_ms = 0.0;
  std::string driver = "v4l2";
  std::string device;  // empty: `run` does not open this camera
  double fps = 30.0;
  std::int64_t exposure_us = 500;
  double analogue_gain = 1.0;
};

struct OverheadConfig {
  overhead::TrackerParams tracker;
  overhead::SearchParams search;
  overhead::TagDetectParams detect;
  // How far the trays' tops depart from level at their height (widens every tag fix).
  overhead::TrayPlaneSigma tray_plane{0.0087, 2.0};
  bool tray_fit = true;  // the tray's box for a tracked vehicle whose tag is covered
  overhead::TrayFitParams tray;
  // classical (tray_fit.hpp) or learned (tray_net.hpp, the ONNX model at tray_model_path).
  std::string tray_method = "classical";
  std::string tray_model_path;
  // Vehicles lost while their tags were hidden, searched for with the model of tray_model_path
  // (with either tray method).
  // Off unless asked for: a rendered fleet run restarted covered vehicles from other vehicles'
  // boxes (docs/design/overhead.md, "Twenty vehicles, half the trays loaded").
  overhead::ReacquireParams reacquire{.enabled = false};
  // Fleet tag ids whose codes are fewer bits apart are refused with the site (identity).
  int min_tag_distance = 12;
  double output_rate_hz = 30.0;
  MqttOutput mqtt;
  DetectionsBus detections;
  OrdersIn orders;
  DiagOutput diag;
  std::map<std::string, CameraSettings> cameras;  // by camera id
};

enum class KeyType { kNumber, kInteger, kBool, kString, kChoice };
using Value = std::variant<bool, std::int64_t, double, std::string>;

// One key of a table whose values are stored in a Cfg.
template <typename Cfg>
struct KeyOf {
  std::string name;  // "tracker.gate_chi2"; for a camera key the leaf ("latency_ms")
  KeyType type = KeyType::kNumber;
  double lo = 0.0, hi = 0.0;
  std::vector<std::string> choices;
  std::string unit;
  Value def;
  std::string doc;
  std::function<Value(const Cfg&)> get;
  std::function<void(Cfg&, const Value&)> set;
};
using Key = KeyOf<OverheadConfig>;
using CameraKey = KeyOf<CameraSettings>;

const std::vector<Key>& config_keys();
// cameras.<id>.<leaf>, for every camera id of the site.
const std::vector<CameraKey>& camera_keys();

// Parses a configuration text. False with one line per problem in *errors ("line 4:
// tracker.gate_chi2: value 0 outside the accepted range 1..1000"). Keys missing from the text keep
// their defaults.
bool parse_config(const std::string& text, OverheadConfig* out, std::vector<std::string>* errors);

// Reads and parses a file (a regular file of at most 1 MiB); errors prefixed with the path.
bool load_config(const std::string& path, OverheadConfig* out, std::vector<std::string>* errors);

std::string format_value(const Value& v);
template <typename Cfg>
std::string format_range(const KeyOf<Cfg>& key);
// The key table as Markdown, the part of docs/guide/overhead.md between its
// "<!-- keys: begin -->" and "<!-- keys: end -->" markers.
std::string config_keys_doc();

}  // namespace agv::overhead_app
