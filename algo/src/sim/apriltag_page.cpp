// tag36h11 landmarks for the simulator and the generator (docs/design/landmark.md "AprilTag
// landmark"): the cells come from libapriltag's own family table and renderer (apriltag_to_image),
// so the printed and simulated tags are exactly what the detector decodes.
#include <apriltag/apriltag.h>
#include <apriltag/tag36h11.h>

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <memory>
#include <sstream>

#include "agv/sim/render.hpp"
#include "svg_number.hpp"

namespace agv::sim {

namespace {

// apriltag_to_image() of tag36h11: 10 x 10 cells, a white ring of one cell around the 8 x 8
// black square.
constexpr int kTagCells = 10;
constexpr int kWhiteRingCells = 1;

// image_u8_destroy() is exported by libapriltag-utils only, not by libapriltag; the image of
// apriltag_to_image() is two calloc blocks (image_u8_create_stride), freed here the same way.
void free_image(image_u8_t* im) {
  if (!im) return;
  std::free(im->buf);
  std::free(im);
}

bool tag_cells(std::uint32_t id, std::vector<std::uint8_t>* cells, std::string* error) {
  std::unique_ptr<apriltag_family_t, void (*)(apriltag_family_t*)> fam(tag36h11_create(),
                                                                       tag36h11_destroy);
  if (id >= fam->ncodes) {
    if (error) *error = "tag36h11 has ids 0.." + std::to_string(fam->ncodes - 1);
    return false;
  }
  image_u8_t* im = apriltag_to_image(fam.get(), static_cast<int>(id));
  if (!im || im->width != kTagCells || im->height != kTagCells) {
    free_image(im);
    if (error) *error = "unexpected tag36h11 image from libapriltag";
    return false;
  }
  cells->assign(static_cast<size_t>(kTagCells * kTagCells), 0);
  for (int r = 0; r < kTagCells; ++r) {
    for (int c = 0; c < kTagCells; ++c) {
      (*cells)[static_cast<size_t>(r * kTagCells + c)] = im->buf[r * im->stride + c] < 128 ? 1 : 0;
    }
  }
  free_image(im);
  return true;
}

// Black cells of one tag whose centre is at (cx, cy) in the SVG's mm coordinates (page
// orientation: row 0 at the top).
void append_tag_svg(std::ostringstream& os, const AprilTagGeometry& g,
                    const std::vector<std::uint8_t>& cells, double cx, double cy) {
  const double m = g.module_mm();
  const double x0 = cx - kTagCells * m / 2.0, y0 = cy - kTagCells * m / 2.0;
  os << "  <g fill=\"#000\">\n";
  for (int r = 0; r < kTagCells; ++r) {
    int c = 0;
    while (c < kTagCells) {
      if (!cells[static_cast<size_t>(r * kTagCells + c)]) {
        ++c;
        continue;
      }
      int e = c;
      while (e < kTagCells && cells[static_cast<size_t>(r * kTagCells + e)]) ++e;
      os << "    <rect x=\"" << svg_number(x0 + c * m) << "\" y=\"" << svg_number(y0 + r * m)
         << "\" width=\"" << svg_number((e - c) * m) << "\" height=\"" << svg_number(m) << "\"/>\n";
      c = e;
    }
  }
  os << "  </g>\n";
}

bool valid_size(const AprilTagGeometry& g, std::string* error) {
  if (g.size_mm > 0.0 && std::isfinite(g.size_mm) && g.margin_mm >= 0.0 &&
      std::isfinite(g.margin_mm)) {
    return true;
  }
  if (error) *error = "tag size must be positive and the margin not negative";
  return false;
}

}  // namespace

bool LandmarkPattern::make_tag(const AprilTagGeometry& geometry, std::uint32_t id,
                               LandmarkPattern* out, std::string* error) {
  if (!valid_size(geometry, error)) return false;
  LandmarkPattern p;
  if (!tag_cells(id, &p.tag_cells_, error)) return false;
  p.tag_cells_n_ = kTagCells;
  p.tag_geometry_ = geometry;
  p.geometry_.size_mm = geometry.size_mm;
  p.module_mm_ = geometry.module_mm();
  p.payload_ = "tag36h11/" + std::to_string(id);
  *out = std::move(p);
  return true;
}

PageInk LandmarkPattern::tag_at(Vec2 uv) const {
  const double au = std::abs(uv.x), av = std::abs(uv.y);
  if (!(au < tag_geometry_.page_half_mm() && av < tag_geometry_.page_half_mm())) {
    return PageInk::kOutside;
  }
  const double oh = tag_geometry_.outer_half_mm();
  if (!(au < oh && av < oh)) return PageInk::kWhite;
  const int c =
      std::min(AprilTagGeometry::kModules - 1, static_cast<int>((uv.x + oh) / module_mm_)) +
      kWhiteRingCells;
  const int r =
      std::min(AprilTagGeometry::kModules - 1, static_cast<int>((uv.y + oh) / module_mm_)) +
      kWhiteRingCells;
  return tag_cells_[static_cast<size_t>(r * tag_cells_n_ + c)] ? PageInk::kBlack : PageInk::kWhite;
}

bool make_tag_scene(const LandmarkMap& map, const AprilTagGeometry& geometry, Scene* out,
                    std::string* error) {
  Scene s;
  s.geometry.size_mm = geometry.size_mm;
  for (const auto& [id, e] : map.entries) {
    SceneLandmark l;
    l.id = id;
    l.world_pose = e.pose;
    if (!LandmarkPattern::make_tag(geometry, id, &l.pattern, error)) {
      if (error) *error = "landmark " + std::to_string(id) + ": " + *error;
      return false;
    }
    s.landmarks.push_back(std::move(l));
  }
  *out = std::move(s);
  return true;
}

std::string tag_svg(const AprilTagGeometry& geometry, std::uint32_t id) {
  std::vector<std::uint8_t> cells;
  if (!valid_size(geometry, nullptr) || !tag_cells(id, &cells, nullptr)) return {};
  const double side = 2.0 * geometry.page_half_mm();
  std::ostringstream os;
  os << "<?xml version=\"1.0\" encoding=\"UTF-8\"?>\n"
     << "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"" << svg_number(side) << "mm\" height=\""
     << svg_number(side) << "mm\" viewBox=\"0 0 " << svg_number(side) << " " << svg_number(side)
     << "\" shape-rendering=\"crispEdges\">\n"
     << "  <!-- agvloc landmark, tag36h11 id " << id << ", black square "
     << svg_number(geometry.size_mm) << " mm; print at 100% scale -->\n"
     << "  <rect x=\"0\" y=\"0\" width=\"" << svg_number(side) << "\" height=\"" << svg_number(side)
     << "\" fill=\"#fff\"/>\n";
  append_tag_svg(os, geometry, cells, side / 2, side / 2);
  os << "</svg>\n";
  return os.str();
}

std::string tag_sheet_svg(const AprilTagGeometry& geometry, const LandmarkMap& map, int columns) {
  if (columns < 1 || map.entries.empty() || !valid_size(geometry, nullptr)) return {};
  const SheetGrid g = sheet_grid(2.0 * geometry.page_half_mm() + 10.0,
                                 static_cast<int>(map.entries.size()), columns);
  std::ostringstream os;
  svg_sheet_open(os, g, "agvloc tag36h11 sheet, black square " + svg_number(geometry.size_mm));
  int i = 0;
  std::vector<std::uint8_t> cells;
  for (const auto& [id, e] : map.entries) {
    if (!tag_cells(id, &cells, nullptr)) return {};
    const double cx = g.cx(i), cy = g.cy(i);
    append_tag_svg(os, geometry, cells, cx, cy);
    char cap[160];
    std::snprintf(cap, sizeof cap, "tag36h11 id %u  x %.1f  y %.1f  heading %.2f deg",
                  static_cast<unsigned>(id), e.pose.x_mm, e.pose.y_mm,
                  rad_to_deg(wrap_angle_rad(e.pose.theta_rad)));
    svg_caption(os, cx, cy + g.cell_w / 2 - 2.0, cap);
    ++i;
  }
  os << "</svg>\n";
  return os.str();
}

}  // namespace agv::sim
