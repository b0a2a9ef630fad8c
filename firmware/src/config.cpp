#include "config.hpp"

#include <cstdio>
#include <filesystem>

#include "agv/recording/recording.hpp"

namespace agv::config {

bool load_config(const std::string& path, Config* out, std::vector<std::string>* errors,
                 ConfigUse use) {
  std::string text, read_error;
  if (!recording::read_file_bounded(path, kMaxConfigBytes, &text, &read_error)) {
    errors->push_back(read_error);
    return false;
  }
  out->source = path;
  const std::string dir = std::filesystem::path(path).parent_path().string();
  if (!parse_config(text, dir, out, errors, use)) {
    for (auto& e : *errors) e = path + ": " + e;
    return false;
  }
  return true;
}

bool load_config_or_report(const std::string& path, const char* who, Config* out, ConfigUse use) {
  std::vector<std::string> errors;
  if (load_config(path, out, &errors, use)) return true;
  for (const auto& e : errors) std::fprintf(stderr, "%s: config: %s\n", who, e.c_str());
  return false;
}

bool load_map_file(const std::string& path, LandmarkMap* map, std::string* error) {
  std::string text, e;
  if (!recording::read_file_bounded(path, kMaxMapBytes, &text, &e)) {
    *error = e;
    return false;
  }
  if (!parse_landmark_map(text, map, &e)) {
    *error = path + ": " + e;
    return false;
  }
  return true;
}

}  // namespace agv::config
