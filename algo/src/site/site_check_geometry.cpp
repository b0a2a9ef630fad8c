// Polygon normalisation and predicates for the site checks (site_check_geometry.hpp).
#include "site_check_geometry.hpp"

#include <algorithm>
#include <cmath>

#include "agv/site/site_geometry.hpp"

namespace agv::site::detail {

BgPolygon to_bg(const Polygon& p) {
  BgPolygon out;
  auto& ring = out.outer();
  ring.reserve(p.vertices_mm.size() + 1);
  for (const Vec2& v : p.vertices_mm) ring.emplace_back(v.x, v.y);
  if (!p.vertices_mm.empty()) ring.push_back(ring.front());
  return out;
}

namespace {
bool same(Vec2 a, Vec2 b) { return a.x == b.x && a.y == b.y; }

std::string failure_text(bg::validity_failure_type f) {
  switch (f) {
    case bg::failure_few_points:
      return "fewer than 3 distinct vertices";
    case bg::failure_wrong_topological_dimension:
      return "zero area (its vertices lie on one line)";
    case bg::failure_spikes:
      return "has a spike (an edge that doubles back along the one before)";
    case bg::failure_self_intersections:
      return "self-intersecting (two edges cross or touch)";
    case bg::failure_invalid_coordinate:
      return "has a non-finite coordinate";
    default:
      return "not a simple polygon";
  }
}
}  // namespace

std::string normalise_polygon(Polygon* p) {
  auto& v = p->vertices_mm;
  // A repeated vertex (the closing one written out, or a doubled point) adds nothing.
  v.erase(std::unique(v.begin(), v.end(), same), v.end());
  while (v.size() > 1 && same(v.front(), v.back())) v.pop_back();
  if (v.size() < 3) {
    return "needs at least 3 distinct vertices (has " + std::to_string(v.size()) + ")";
  }
  const double area = signed_area_mm2(*p);
  if (!(std::abs(area) >= 1.0)) {
    // A symmetric bow tie's two lobes cancel: say what is really wrong with it.
    if (bg::intersects(to_bg(*p))) return failure_text(bg::failure_self_intersections);
    return "zero area (below 1 mm^2)";
  }
  if (area < 0.0) std::reverse(v.begin(), v.end());  // clockwise as written: fine, reoriented
  bg::validity_failure_type failure = bg::no_failure;
  if (!bg::is_valid(to_bg(*p), failure)) return failure_text(failure);
  return "";
}

bool interiors_intersect(const BgPolygon& a, const BgPolygon& b) {
  return bg::relate(a, b, bg::de9im::mask("T********"));
}

double boundary_distance_mm(const BgPolygon& poly, Vec2 p) {
  const bg::model::linestring<BgPoint> ring(poly.outer().begin(), poly.outer().end());
  return bg::distance(BgPoint(p.x, p.y), ring);
}

}  // namespace agv::site::detail
