// Drawing a site (docs/guide/site.md): the outline, obstacles by kind, floor landmarks, wall
// landmarks with the direction they face, each ceiling camera's view of the floor, the fleet as
// a legend; optionally routes (polylines) and extra polygons (a planner's inflated obstacles).
// The same drawing as SVG or as a raster image (PNG), x right and y up like the site frame.
#pragma once

#include <string>
#include <vector>

#include "agv/site/site.hpp"

namespace cv {
class Mat;
}

namespace agv::desk {

// Scale of the drawing: output pixels (SVG user units) per metre of the site.
inline constexpr double kSiteDrawDefaultPxPerM = 50.0;
// A raster image larger than this on a side is refused (memory: 16384^2 x 3 bytes = 805 MB).
inline constexpr int kSiteDrawMaxPngSidePx = 16384;

std::string site_svg(const agv::site::Site& site, const std::vector<std::vector<Vec2>>& routes,
                     const std::vector<agv::site::Polygon>& extra_polygons,
                     double px_per_m = kSiteDrawDefaultPxPerM);

// The drawing rasterised into *out (8-bit BGR). False with *error when it would be larger than
// kSiteDrawMaxPngSidePx on a side.
bool site_png(const agv::site::Site& site, const std::vector<std::vector<Vec2>>& routes,
              const std::vector<agv::site::Polygon>& extra_polygons, double px_per_m, cv::Mat* out,
              std::string* error);

}  // namespace agv::desk
