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

bool check_can_localize(const Config& cfg, const LandmarkMap* map,
                        std::vector<std::string>* errors) {
  const size_t before = errors->size();
  if (cfg.vision.family == LandmarkFamily::kTag36h11) {
    if (!map || map->entries.empty()) {
      errors->push_back(
          "landmark.family tag36h11 needs landmark.map: a tag carries only its id, the pose "
          "comes from the map (without one every tag is \"not in the map\")");
    } else {
      std::string ids;
      int n = 0;
      for (const auto& [id, e] : map->entries) {
        if (id <= kTag36h11MaxId) continue;
        if (n++ < 5) ids += (ids.empty() ? "" : ", ") + std::to_string(id);
      }
      if (n > 0) {
        errors->push_back("landmark.map " + cfg.map_file + ": " + std::to_string(n) +
                          " id(s) above " + std::to_string(kTag36h11MaxId) + " (" + ids +
                          (n > 5 ? ", ..." : "") +
                          "), which tag36h11 does not have: those landmarks can never be seen");
      }
    }
  }
  return errors->size() == before;
}

}  // namespace agv::config
