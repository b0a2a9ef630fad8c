#include "agv/recording/site_file.hpp"

#include <filesystem>

#include "agv/recording/recording.hpp"
#include "agv/site/site_file.hpp"

namespace agv::recording {

bool read_site_file(const std::string& path, site::Site* out, std::vector<std::string>* errors) {
  namespace fs = std::filesystem;
  const site::SiteLimits limits;
  std::string text, err;
  if (!read_file_bounded(path, limits.max_text_bytes, &text, &err)) {
    errors->push_back(err);
    return false;
  }
  std::string map_name, map_text;
  if (!site::site_floor_map_file(text, &map_name, &err)) {
    errors->push_back(path + ": " + err);
    return false;
  }
  if (!map_name.empty()) {
    fs::path map_path(map_name);
    if (map_path.is_relative()) map_path = fs::path(path).parent_path() / map_path;
    if (!read_file_bounded(map_path.lexically_normal().string(), limits.max_text_bytes, &map_text,
                           &err)) {
      errors->push_back(path + ": floor_map.file: " + err);
      return false;
    }
  }
  std::vector<site::SiteError> found;
  if (site::parse_site(text, map_text, out, &found, limits)) return true;
  for (const site::SiteError& e : found) errors->push_back(path + ": " + e.to_string());
  return false;
}

}  // namespace agv::recording
