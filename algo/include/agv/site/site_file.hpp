// The site file (site.yaml, docs/guide/site.md): parsed from text and checked. Pure: the caller
// reads the file and, when the site names a floor-landmark map file, reads that and passes its
// text too (tools/desk/src/site_io.hpp does both for the desk tool).
#pragma once

#include <cstddef>
#include <string>
#include <string_view>
#include <vector>

#include "agv/site/site.hpp"

namespace agv::site {

// Bounds that keep a hostile or broken file from costing unbounded memory or time.
struct SiteLimits {
  std::size_t max_text_bytes = 8u << 20;
  std::size_t max_obstacles = 20000;
  std::size_t max_vertices_per_polygon = 4096;
  std::size_t max_wall_landmarks = 20000;
  std::size_t max_cameras = 256;
  std::size_t max_fleet = 4096;
  double max_extent_mm = 1e7;  // 10 km: any coordinate beyond is an error
  // Over every polygon of the file (YAML aliases can repeat one polygon many times).
  std::size_t max_total_vertices = 1000000;
  // Errors reported; one more line then says that there were more.
  std::size_t max_errors = 200;
};

// One problem with a site file: "<key path> (line N): <what is wrong>".
struct SiteError {
  std::string key;  // e.g. "obstacles[3].outline"
  int line = 0;     // 1-based line in the site file; 0 when not known
  std::string message;
  std::string to_string() const;
};

// Parses and checks the site text. floor_map_text: the contents of the file named by
// floor_map.file (empty when the site names none). Returns true when there is no error; *errors
// gets every error found (not just the first). *out is complete only on success.
bool parse_site(std::string_view yaml_text, std::string_view floor_map_text, Site* out,
                std::vector<SiteError>* errors, const SiteLimits& limits = {});

// The floor_map.file entry of a site text, or "" (so the caller knows what to read before
// parse_site). False with *error when the text is not YAML.
bool site_floor_map_file(std::string_view yaml_text, std::string* file, std::string* error);

// Findings about a valid site that are allowed but worth a look (docs/guide/site.md,
// "Warnings"): "<key path>: <what>" each. No line numbers: the site may not come from a file.
std::vector<std::string> site_warnings(const Site& site);

// Writes a site as site-file YAML (round trip: parse_site(write_site(s)) == s).
std::string write_site(const Site& site);

}  // namespace agv::site
