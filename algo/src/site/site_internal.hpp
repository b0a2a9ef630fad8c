// Between the site file's reader (site_parse.cpp: YAML -> Site, keys, types, ranges) and its
// checker (site_check*.cpp: polygons, overlaps, cameras, fleet): where each element was in the
// file, so that a semantic error names the line, and the error list with its cap.
#pragma once

#include <cstddef>
#include <string>
#include <vector>

#include "agv/site/site_file.hpp"

namespace agv::site::detail {

// 1-based lines of the site file's elements (0: not in the file).
struct SiteLines {
  int root = 0;
  int outline = 0;
  int floor_map = 0;
  std::vector<int> obstacles, obstacle_outlines;
  std::vector<int> wall_landmarks;
  std::vector<int> cameras;
  std::vector<int> fleet, fleet_footprints;
};

// Collects errors up to limits.max_errors; one more line then says that some were left out (a
// hostile file can hold millions, and each costs a string).
class ErrorList {
 public:
  ErrorList(std::vector<SiteError>* out, std::size_t max_errors) : out_(out), max_(max_errors) {}
  void add(const std::string& key, int line, const std::string& message);
  bool full() const { return full_; }
  bool empty() const { return out_->empty(); }
  std::size_t count() const { return out_->size(); }

 private:
  std::vector<SiteError>* out_;
  std::size_t max_;
  bool full_ = false;
};

// Reads the YAML tree into *site (keys, types, ranges, sizes). Polygons are read as written;
// check_site normalises them.
void read_site_yaml(std::string_view yaml_text, std::string_view floor_map_text,
                    const SiteLimits& limits, Site* site, SiteLines* lines, ErrorList* errors);

// The semantic checks; normalises the polygons (closing vertex dropped, clockwise reoriented).
void check_site(const SiteLimits& limits, const SiteLines& lines, Site* site, ErrorList* errors);

// "%g" with enough digits to tell values apart in a message.
std::string fmt_number(double v);

}  // namespace agv::site::detail
