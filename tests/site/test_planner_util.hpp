// Independent checks for the route planner's tests: geometry written here, not the planner's
// predicates, so that a wrong predicate in the planner cannot hide its own mistakes.
#pragma once

#include <algorithm>
#include <cmath>
#include <limits>
#include <vector>

#include "agv/site/planner.hpp"

namespace agv::site::test {

inline Polygon rect(double x0, double y0, double x1, double y1) {
  return {{{x0, y0}, {x1, y0}, {x1, y1}, {x0, y1}}};
}

inline Obstacle rack(const std::string& id, double x0, double y0, double x1, double y1) {
  Obstacle o;
  o.id = id;
  o.outline = rect(x0, y0, x1, y1);
  return o;
}

inline double seg_dist(Vec2 p, Vec2 c, Vec2 d) {
  const double dx = d.x - c.x, dy = d.y - c.y, l2 = dx * dx + dy * dy;
  double t = l2 > 0 ? ((p.x - c.x) * dx + (p.y - c.y) * dy) / l2 : 0.0;
  t = std::clamp(t, 0.0, 1.0);
  return std::hypot(p.x - c.x - t * dx, p.y - c.y - t * dy);
}

// Even-odd rule over a ring.
inline bool inside_ring(const std::vector<Vec2>& v, Vec2 p) {
  bool in = false;
  for (std::size_t i = 0, j = v.size() - 1; i < v.size(); j = i++) {
    if ((v[i].y > p.y) != (v[j].y > p.y) &&
        p.x < v[j].x + (p.y - v[j].y) * (v[i].x - v[j].x) / (v[i].y - v[j].y)) {
      in = !in;
    }
  }
  return in;
}

inline double boundary_dist(const std::vector<Vec2>& v, Vec2 p) {
  double d = std::numeric_limits<double>::infinity();
  for (std::size_t i = 0; i < v.size(); ++i)
    d = std::min(d, seg_dist(p, v[i], v[(i + 1) % v.size()]));
  return d;
}

// The true clearance of p: distance to the nearest raw obstacle or wall (negative outside the
// outline or inside an obstacle).
inline double clearance_mm(const Site& s, Vec2 p) {
  if (!inside_ring(s.outline.vertices_mm, p)) return -1.0;
  double d = boundary_dist(s.outline.vertices_mm, p);
  for (const Obstacle& o : s.obstacles) {
    if (inside_ring(o.outline.vertices_mm, p)) return -1.0;
    d = std::min(d, boundary_dist(o.outline.vertices_mm, p));
  }
  return d;
}

// The smallest clearance along a polyline sampled every step_mm.
inline double min_clearance_mm(const Site& s, const std::vector<Vec2>& pts, double step_mm) {
  double m = std::numeric_limits<double>::infinity();
  for (std::size_t i = 0; i + 1 < pts.size(); ++i) {
    const double l = std::hypot(pts[i + 1].x - pts[i].x, pts[i + 1].y - pts[i].y);
    const int n = std::max(1, static_cast<int>(std::ceil(l / step_mm)));
    for (int k = 0; k <= n; ++k) {
      const double t = static_cast<double>(k) / n;
      m = std::min(m, clearance_mm(s, {pts[i].x + t * (pts[i + 1].x - pts[i].x),
                                       pts[i].y + t * (pts[i + 1].y - pts[i].y)}));
    }
  }
  if (pts.size() == 1) m = clearance_mm(s, pts[0]);
  return m;
}

inline double polyline_length(const std::vector<Vec2>& pts) {
  double l = 0.0;
  for (std::size_t i = 0; i + 1 < pts.size(); ++i) {
    l += std::hypot(pts[i + 1].x - pts[i].x, pts[i + 1].y - pts[i].y);
  }
  return l;
}

}  // namespace agv::site::test
