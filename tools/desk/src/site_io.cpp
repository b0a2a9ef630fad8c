// Loading a site file from disk (site_io.hpp).
#include "site_io.hpp"

#include <filesystem>
#include <fstream>
#include <sstream>
#include <vector>

#include "agv/site/site_file.hpp"
#include "desk_input.hpp"

namespace agv::desk {

namespace {

bool read_bounded_site_text(const std::string& path, std::uintmax_t max_bytes, std::string* text,
                            std::string* error) {
  if (!input::regular_file(path, max_bytes, error)) return false;
  std::ifstream f(path, std::ios::binary);
  std::ostringstream os;
  os << f.rdbuf();
  if (!f) {
    *error = path + ": cannot be read";
    return false;
  }
  *text = os.str();
  if (text->size() > max_bytes) {  // grew since it was measured
    *error = path + ": more than " + std::to_string(max_bytes) + " bytes";
    return false;
  }
  return true;
}

}  // namespace

bool load_site(const std::string& path, agv::site::Site* out, std::string* error_lines) {
  const agv::site::SiteLimits limits;
  error_lines->clear();
  std::string text, error;
  if (!read_bounded_site_text(path, limits.max_text_bytes, &text, &error)) {
    *error_lines = error + "\n";
    return false;
  }
  std::string map_name, map_text;
  if (!agv::site::site_floor_map_file(text, &map_name, &error)) {
    *error_lines = path + ": " + error + "\n";
    return false;
  }
  if (!map_name.empty()) {
    std::filesystem::path map_path(map_name);
    if (map_path.is_relative()) map_path = std::filesystem::path(path).parent_path() / map_path;
    if (!read_bounded_site_text(map_path.lexically_normal().string(), limits.max_text_bytes,
                                &map_text, &error)) {
      *error_lines = path + ": floor_map.file: " + error + "\n";
      return false;
    }
  }
  std::vector<agv::site::SiteError> errors;
  if (agv::site::parse_site(text, map_text, out, &errors, limits)) return true;
  for (const auto& e : errors) *error_lines += path + ": " + e.to_string() + "\n";
  return false;
}

}  // namespace agv::desk
