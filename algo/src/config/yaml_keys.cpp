#include "agv/config/yaml_keys.hpp"

#include <yaml-cpp/yaml.h>

namespace agv::config {

namespace {

std::string line_text(const YAML::Node& n) { return "line " + std::to_string(n.Mark().line + 1); }

bool walk(const YAML::Node& map, const std::string& path, std::vector<YamlEntry>* out,
          std::string* error) {
  for (const auto& kv : map) {
    const YAML::Node k = kv.first, v = kv.second;
    if (!k.IsScalar()) {
      *error = line_text(k) + ": " + (path.empty() ? "top level" : path) +
               ": a key that is not a plain name";
      return false;
    }
    const std::string key = path.empty() ? k.Scalar() : path + "." + k.Scalar();
    if (v.IsMap()) {
      if (!walk(v, key, out, error)) return false;
    } else if (v.IsScalar()) {
      out->push_back({key, v.Scalar(), v.Mark().line + 1});
    } else if (!v.IsNull()) {
      *error = line_text(v) + ": " + key + ": a list, where the configuration has only values";
      return false;
    }
  }
  return true;
}

}  // namespace

bool yaml_entries(const std::string& text, std::vector<YamlEntry>* out, std::string* error) {
  try {
    const YAML::Node root = YAML::Load(text);
    if (root.IsNull()) return true;  // empty or only comments
    if (!root.IsMap()) {
      *error = line_text(root) + ": top level: expected a mapping of sections (camera:, ...)";
      return false;
    }
    return walk(root, "", out, error);
  } catch (const YAML::Exception& e) {
    *error = "line " + std::to_string(e.mark.line + 1) + ": YAML syntax error: " + e.msg;
    return false;
  }
}

}  // namespace agv::config
