// Strict reading of the site file's YAML: a mapping's keys are checked against the accepted ones
// (unknown keys with a did-you-mean, duplicates, keys that are not plain names), and values are
// typed and range-checked. Every error names the key path and the line.
#pragma once

#include <yaml-cpp/yaml.h>

#include <cstdint>
#include <map>
#include <string>
#include <vector>

#include "site_internal.hpp"

namespace agv::site::detail {

struct ReadContext {
  ErrorList* errors = nullptr;
  const SiteLimits* limits = nullptr;
  std::size_t vertices_read = 0;  // over every polygon: aliases can repeat one many times
};

// 1-based line of a node, 0 when it has none.
int line_of(const YAML::Node& n);

// The entries of one mapping. A node that is not a mapping is an error (once, here); the
// lookups then find nothing.
class Fields {
 public:
  Fields(ReadContext* ctx, const YAML::Node& node, std::string path,
         const std::vector<const char*>& allowed);
  bool is_map() const { return is_map_; }
  // The value of key, or an undefined node when absent.
  YAML::Node get(const char* key) const;
  bool has(const char* key) const { return entries_.count(key) != 0; }
  std::string path(const char* key) const;
  int line() const { return line_; }
  // "missing (required)" when absent.
  bool require(const char* key);

  bool number(const char* key, double lo, double hi, double* out, bool lo_open = false);
  bool integer(const char* key, std::int64_t lo, std::int64_t hi, std::int64_t* out);
  bool text(const char* key, std::string* out);

 private:
  ReadContext* ctx_;
  std::string path_;
  int line_ = 0;
  bool is_map_ = false;
  std::map<std::string, YAML::Node> entries_;
};

bool read_number(ReadContext* ctx, const YAML::Node& n, const std::string& path, double lo,
                 double hi, double* out, bool lo_open = false);
// A polygon: a sequence of [x_mm, y_mm] pairs.
bool read_polygon(ReadContext* ctx, const YAML::Node& n, const std::string& path, Polygon* out);
// A sequence of at most max items (each then read by the caller).
bool read_list(ReadContext* ctx, const YAML::Node& n, const std::string& path, std::size_t max);

// The accepted key closest to an unknown one (edit distance <= 2), or "".
std::string did_you_mean(const std::string& key, const std::vector<const char*>& allowed);

}  // namespace agv::site::detail
