// Minimal SVG trajectory plot for `agvloc-desk report` (no plotting dependency): polylines in
// world mm, equal axis scale, grid, legend.
#pragma once

#include <string>
#include <vector>

#include "agv/common/geometry.hpp"

namespace agv::plot {

struct Series {
  std::string label;
  std::string color;  // any SVG colour
  std::vector<Vec2> points_mm;
  bool dashed = false;
};

struct Marker {
  Vec2 p_mm;
  double heading_rad = 0.0;
  std::string label;
};

// Writes the plot; false (with *error) when the file cannot be written.
bool write_trajectory_svg(const std::string& path, const std::string& title,
                          const std::vector<Series>& series, const std::vector<Marker>& landmarks,
                          std::string* error);

}  // namespace agv::plot
