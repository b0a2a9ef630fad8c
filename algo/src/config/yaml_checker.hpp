// Strict YAML reading for the configuration: every key is known, typed and range-checked, and
// every error names the full key path and the accepted range.
#pragma once

#include <yaml-cpp/yaml.h>

#include <cstdint>
#include <map>
#include <set>
#include <string>
#include <vector>

namespace agv::config {

class YamlChecker {
 public:
  // Reads `key` from map `node` under path `path` ("can.odometry"). Missing keys keep *out
  // (the default). Records an error and leaves *out unchanged on a bad type or range.
  void number(const YAML::Node& node, const std::string& path, const char* key, double lo,
              double hi, double* out);
  void integer(const YAML::Node& node, const std::string& path, const char* key, std::int64_t lo,
               std::int64_t hi, std::int64_t* out);
  void boolean(const YAML::Node& node, const std::string& path, const char* key, bool* out);
  void string(const YAML::Node& node, const std::string& path, const char* key, std::string* out);
  void choice(const YAML::Node& node, const std::string& path, const char* key,
              const std::vector<std::string>& allowed, std::string* out);
  // Returns the sub-map `key` (or an undefined node). Errors if it is present but not a map.
  YAML::Node section(const YAML::Node& node, const std::string& path, const char* key);
  // Records "missing (required: why)" when map `node` has no `key`.
  void require(const YAML::Node& node, const std::string& path, const char* key,
               const std::string& why);
  // Call after reading a map: every key not asked for is reported as unknown (or, when it was
  // removed, with its replacement), a key that is not a scalar (`[a]: 1`) and a key given twice
  // are errors too.
  void finish_map(const YAML::Node& node, const std::string& path);
  // A key that no longer exists: finish_map names `replacement` instead of "unknown key".
  void removed(const std::string& path, const std::string& replacement);

  void error(const std::string& path, const std::string& what);
  const std::vector<std::string>& errors() const { return errors_; }

 private:
  static std::string join(const std::string& path, const char* key);
  std::set<std::string> seen_;
  std::map<std::string, std::string> removed_;
  std::vector<std::string> errors_;
};

}  // namespace agv::config
