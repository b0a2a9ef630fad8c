#include "yaml_checker.hpp"

#include <cmath>
#include <map>
#include <sstream>

namespace agv::config {

std::string YamlChecker::join(const std::string& path, const char* key) {
  return path.empty() ? std::string(key) : path + "." + key;
}

void YamlChecker::error(const std::string& path, const std::string& what) {
  errors_.push_back(path + ": " + what);
}

namespace {
std::string fmt(double v) {
  std::ostringstream os;
  os << v;
  return os.str();
}
}  // namespace

void YamlChecker::number(const YAML::Node& node, const std::string& path, const char* key,
                         double lo, double hi, double* out) {
  const std::string p = join(path, key);
  seen_.insert(p);
  if (!node.IsMap() || !node[key]) return;
  const YAML::Node v = node[key];
  double d = 0.0;
  if (!v.IsScalar() || !YAML::convert<double>::decode(v, d) || !std::isfinite(d)) {
    error(p, "expected a number in [" + fmt(lo) + ", " + fmt(hi) + "]");
    return;
  }
  if (d < lo || d > hi) {
    error(p, "value " + fmt(d) + " outside the accepted range [" + fmt(lo) + ", " + fmt(hi) + "]");
    return;
  }
  *out = d;
}

void YamlChecker::integer(const YAML::Node& node, const std::string& path, const char* key,
                          std::int64_t lo, std::int64_t hi, std::int64_t* out) {
  const std::string p = join(path, key);
  seen_.insert(p);
  if (!node.IsMap() || !node[key]) return;
  const YAML::Node v = node[key];
  long long i = 0;
  if (!v.IsScalar() || !YAML::convert<long long>::decode(v, i)) {
    // yaml-cpp decodes 0x.. hex as integers too; anything else is a type error.
    error(p, "expected an integer in [" + std::to_string(lo) + ", " + std::to_string(hi) + "]");
    return;
  }
  if (i < lo || i > hi) {
    error(p, "value " + std::to_string(i) + " outside the accepted range [" + std::to_string(lo) +
                 ", " + std::to_string(hi) + "]");
    return;
  }
  *out = i;
}

void YamlChecker::boolean(const YAML::Node& node, const std::string& path, const char* key,
                          bool* out) {
  const std::string p = join(path, key);
  seen_.insert(p);
  if (!node.IsMap() || !node[key]) return;
  bool b = false;
  if (!node[key].IsScalar() || !YAML::convert<bool>::decode(node[key], b)) {
    error(p, "expected true or false");
    return;
  }
  *out = b;
}

void YamlChecker::string(const YAML::Node& node, const std::string& path, const char* key,
                         std::string* out) {
  const std::string p = join(path, key);
  seen_.insert(p);
  if (!node.IsMap() || !node[key]) return;
  if (!node[key].IsScalar()) {
    error(p, "expected a string");
    return;
  }
  *out = node[key].as<std::string>();
}

void YamlChecker::choice(const YAML::Node& node, const std::string& path, const char* key,
                         const std::vector<std::string>& allowed, std::string* out) {
  std::string s = *out;
  const size_t before = errors_.size();
  string(node, path, key, &s);
  if (errors_.size() != before) return;
  for (const auto& a : allowed) {
    if (a == s) {
      *out = s;
      return;
    }
  }
  std::string list;
  for (const auto& a : allowed) list += (list.empty() ? "" : ", ") + a;
  error(join(path, key), "'" + s + "' is not one of: " + list);
}

YAML::Node YamlChecker::section(const YAML::Node& node, const std::string& path, const char* key) {
  const std::string p = join(path, key);
  seen_.insert(p);
  if (!node.IsMap() || !node[key]) return YAML::Node(YAML::NodeType::Undefined);
  const YAML::Node s = node[key];
  if (!s.IsMap()) {
    error(p, "expected a mapping (key: value lines)");
    return YAML::Node(YAML::NodeType::Undefined);
  }
  return s;
}

void YamlChecker::require(const YAML::Node& node, const std::string& path, const char* key,
                          const std::string& why) {
  if (!node.IsMap() || !node[key]) error(join(path, key), "missing (required: " + why + ")");
}

void YamlChecker::removed(const std::string& path, const std::string& replacement) {
  removed_[path] = replacement;
}

void YamlChecker::finish_map(const YAML::Node& node, const std::string& path) {
  if (!node.IsMap()) return;
  std::map<std::string, int> lines;  // key -> line of its first occurrence
  for (const auto& kv : node) {
    const int line = kv.first.Mark().is_null() ? 0 : kv.first.Mark().line + 1;
    if (!kv.first.IsScalar()) {
      // `[a]: 1` or `{x: 1}: 2`: a key must be a plain name, never a sequence or a mapping.
      error(path.empty() ? "top level" : path, "key at line " + std::to_string(line) +
                                                   " is not a plain name (a " +
                                                   (kv.first.IsSequence() ? "sequence"
                                                    : kv.first.IsMap()    ? "mapping"
                                                                          : "null") +
                                                   " used as key)");
      continue;
    }
    const std::string k = kv.first.Scalar();
    const std::string p = path.empty() ? k : path + "." + k;
    const auto [first, inserted] = lines.emplace(k, line);
    if (!inserted) {
      // yaml-cpp keeps both entries and lookups return the first: never let one silently win.
      error(p, "duplicate key at line " + std::to_string(line) + " (first at line " +
                   std::to_string(first->second) + ")");
      continue;
    }
    if (seen_.count(p)) continue;
    const auto gone = removed_.find(p);
    if (gone != removed_.end()) {
      error(p, "removed key; use " + gone->second + " instead");
    } else {
      error(p, "unknown key");
    }
  }
}

}  // namespace agv::config
