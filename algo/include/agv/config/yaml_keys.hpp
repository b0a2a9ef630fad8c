// The keys a YAML configuration text sets, by dotted name ("can.odometry.track_width_mm"), with
// the scalar as written and its line. For what needs to know which keys a file gives rather than
// the values a Config ends up with: replay's precedence of --config over meta.yaml, and merging
// calibration snippets into a configuration (agvloc-desk config apply). Pure: no file access.
#pragma once

#include <string>
#include <vector>

namespace agv::config {

struct YamlEntry {
  std::string key;    // dotted path of the scalar
  std::string value;  // the scalar, unquoted
  int line = 0;       // 1-based line of the value
};

// Every scalar of a tree of mappings, in document order; a key without a value (`mounting:`
// followed only by comments) gives no entry. False with *error naming the line on a YAML syntax
// error, a top level that is not a mapping, a sequence, or a key that is not a plain name.
bool yaml_entries(const std::string& text, std::vector<YamlEntry>* out, std::string* error);

}  // namespace agv::config
