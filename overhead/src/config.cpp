// The configuration checker: the text's scalars (agv::config::yaml_entries, with their lines)
// checked one by one against the key table.
#include "config.hpp"

#include <charconv>
#include <cmath>
#include <cstdio>
#include <map>
#include <system_error>

#include "agv/config/yaml_keys.hpp"
#include "agv/recording/recording.hpp"

namespace agv::overhead_app {

namespace {

constexpr std::uintmax_t kMaxConfigBytes = 1u << 20;

std::string fmt_number(double v) {
  char buf[64];
  std::snprintf(buf, sizeof buf, "%.10g", v);
  return buf;
}

bool parse_double(const std::string& s, double* out) {
  const char* end = s.data() + s.size();
  const auto r = std::from_chars(s.data(), end, *out);
  return r.ec == std::errc() && r.ptr == end && std::isfinite(*out);
}

bool parse_int(const std::string& s, std::int64_t* out) {
  const char* end = s.data() + s.size();
  const auto r = std::from_chars(s.data(), end, *out);
  return r.ec == std::errc() && r.ptr == end;
}

// The scalar as the key's type; "" on success, else what is wrong.
template <typename Cfg>
std::string convert(const KeyOf<Cfg>& k, const std::string& s, Value* v) {
  switch (k.type) {
    case KeyType::kNumber: {
      double d = 0.0;
      if (!parse_double(s, &d)) return "expected a number in " + format_range(k);
      if (d < k.lo || d > k.hi) {
        return "value " + s + " outside the accepted range " + format_range(k);
      }
      *v = d;
      return "";
    }
    case KeyType::kInteger: {
      std::int64_t i = 0;
      if (!parse_int(s, &i)) return "expected an integer in " + format_range(k);
      if (static_cast<double>(i) < k.lo || static_cast<double>(i) > k.hi) {
        return "value " + s + " outside the accepted range " + format_range(k);
      }
      *v = i;
      return "";
    }
    case KeyType::kBool:
      if (s != "true" && s != "false") return "expected true or false";
      *v = (s == "true");
      return "";
    case KeyType::kChoice:
      for (const std::string& c : k.choices) {
        if (c == s) return (*v = s, "");
      }
      return "'" + s + "' is not one of: " + format_range(k);
    case KeyType::kString:
      *v = s;
      return "";
  }
  return "unsupported key type";
}

template <typename Cfg>
const KeyOf<Cfg>* find_in(const std::vector<KeyOf<Cfg>>& keys, const std::string& name) {
  for (const KeyOf<Cfg>& k : keys) {
    if (k.name == name) return &k;
  }
  return nullptr;
}

// cameras.<id>.<leaf>: sets the camera's key; "" on success, else what is wrong. *is_camera is
// false when `key` is not of that shape (then nothing is done).
std::string set_camera_key(const std::string& key, const std::string& scalar, OverheadConfig* cfg,
                           bool* is_camera) {
  static const std::string head = "cameras.";
  const std::size_t dot = key.rfind('.');
  *is_camera = key.compare(0, head.size(), head) == 0 && dot > head.size();
  if (!*is_camera) return "";
  const std::string id = key.substr(head.size(), dot - head.size());
  if (id.find('.') != std::string::npos) return "unknown key";
  const CameraKey* k = find_in(camera_keys(), key.substr(dot + 1));
  if (!k) return "unknown key";
  Value v;
  const std::string what = convert(*k, scalar, &v);
  if (what.empty()) k->set(cfg->cameras[id], v);
  return what;
}

// The configured parts of every topic published to or subscribed to (topics.hpp).
void check_topic_names(const OverheadConfig& c, std::vector<std::string>* errors) {
  const auto check = [&](const char* key, const std::string& v, const std::string& why,
                         bool prefix = false) {
    if (!why.empty()) errors->push_back(topic_error(key, v, why, prefix));
  };
  check("output.mqtt.interface_name", c.mqtt.interface_name,
        topic_first_level_problem(c.mqtt.interface_name));
  check("output.mqtt.manufacturer", c.mqtt.manufacturer, topic_level_problem(c.mqtt.manufacturer));
  check("detections.topic_prefix", c.detections.topic_prefix,
        topic_prefix_problem(c.detections.topic_prefix), true);
  check("orders.interface_name", c.orders.interface_name,
        topic_first_level_problem(c.orders.interface_name));
}

// Keys that only mean something together.
void check_combinations(const OverheadConfig& c, std::vector<std::string>* errors) {
  if (c.orders.subscribe && !c.tracker.route_prior)
    errors->push_back(
        "orders.subscribe: true needs tracker.route_prior: true (the orders are "
        "the route prior's routes)");
  const std::string route = overhead::validate(c.tracker.route);
  if (!route.empty()) errors->push_back("tracker.route: " + route);
}

}  // namespace

bool parse_config(const std::string& text, OverheadConfig* out, std::vector<std::string>* errors) {
  std::vector<config::YamlEntry> entries;
  std::string err;
  if (!config::yaml_entries(text, &entries, &err)) {
    errors->push_back(err);
    return false;
  }
  OverheadConfig cfg;
  std::map<std::string, int> first_line;
  const std::size_t before = errors->size();
  for (const config::YamlEntry& e : entries) {
    const std::string where = "line " + std::to_string(e.line) + ": " + e.key + ": ";
    const auto [it, fresh] = first_line.emplace(e.key, e.line);
    if (!fresh) {
      errors->push_back(where + "duplicate key (first at line " + std::to_string(it->second) + ")");
      continue;
    }
    bool is_camera = false;
    const std::string cam_error = set_camera_key(e.key, e.value, &cfg, &is_camera);
    if (is_camera) {
      if (!cam_error.empty()) errors->push_back(where + cam_error);
      continue;
    }
    const Key* k = find_in(config_keys(), e.key);
    if (!k) {
      errors->push_back(where + "unknown key");
      continue;
    }
    Value v;
    const std::string what = convert(*k, e.value, &v);
    if (!what.empty()) {
      errors->push_back(where + what);
      continue;
    }
    k->set(cfg, v);
  }
  if (errors->size() == before) check_topic_names(cfg, errors);
  if (errors->size() == before) check_combinations(cfg, errors);
  if (errors->size() != before) return false;
  *out = cfg;
  return true;
}

bool load_config(const std::string& path, OverheadConfig* out, std::vector<std::string>* errors) {
  std::string text, err;
  if (!recording::read_file_bounded(path, kMaxConfigBytes, &text, &err)) {
    errors->push_back(err);
    return false;
  }
  std::vector<std::string> found;
  if (parse_config(text, out, &found)) return true;
  for (const std::string& f : found) errors->push_back(path + ": " + f);
  return false;
}

std::string format_value(const Value& v) {
  if (const auto* d = std::get_if<double>(&v)) return fmt_number(*d);
  if (const auto* i = std::get_if<std::int64_t>(&v)) return std::to_string(*i);
  if (const auto* b = std::get_if<bool>(&v)) return *b ? "true" : "false";
  const std::string& s = std::get<std::string>(v);
  return s.empty() ? "\"\"" : s;
}

template <typename Cfg>
std::string format_range(const KeyOf<Cfg>& key) {
  switch (key.type) {
    case KeyType::kNumber:
    case KeyType::kInteger:
      return fmt_number(key.lo) + ".." + fmt_number(key.hi);
    case KeyType::kBool:
      return "true, false";
    case KeyType::kString:
      return "string";
    case KeyType::kChoice: {
      std::string s;
      for (const std::string& c : key.choices) s += (s.empty() ? "" : ", ") + c;
      return s;
    }
  }
  return "";
}
template std::string format_range(const Key& key);
template std::string format_range(const CameraKey& key);

namespace {

template <typename Cfg>
std::string doc_row(const std::string& name, const KeyOf<Cfg>& k) {
  return "| `" + name + "` | " + format_value(k.def) + " | " + format_range(k) + " | " + k.unit +
         " | " + k.doc + " |\n";
}

}  // namespace

std::string config_keys_doc() {
  std::string out =
      "| key | default | range | unit | meaning / trade-off |\n|---|---|---|---|---|\n";
  for (const Key& k : config_keys()) out += doc_row(k.name, k);
  for (const CameraKey& k : camera_keys()) out += doc_row("cameras.<id>." + k.name, k);
  return out;
}

}  // namespace agv::overhead_app
