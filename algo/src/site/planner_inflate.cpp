// The planner's free space: every obstacle and every wall inflated by the vehicle radius plus the
// clearance (Minkowski sum with a disc), overlapping ones merged, the result subtracted from the
// outline. The disc is approximated by a circumscribed polygon: straight edges keep exactly the
// offset distance, each corner arc of angle phi becomes k = ceil(phi / arc_step) tangent chords
// whose vertices lie at R / cos(phi / 2k), so the approximation never cuts into the exact offset.
#include <algorithm>
#include <boost/geometry.hpp>
#include <cmath>
#include <numeric>
#include <string>
#include <vector>

#include "planner_internal.hpp"

namespace agv::site::plan_detail {

namespace bg = boost::geometry;
using BPt = bg::model::d2::point_xy<double>;
using BPoly = bg::model::polygon<BPt, false, true>;  // counter-clockwise, closed
using BMulti = bg::model::multi_polygon<BPoly>;

namespace {

double signed_area_mm2(const std::vector<Vec2>& v) {
  double a = 0.0;
  for (std::size_t i = 0; i < v.size(); ++i) a += pd_cross(v[i], v[(i + 1) % v.size()]);
  return 0.5 * a;
}

bool is_convex_ccw(const std::vector<Vec2>& v) {
  const std::size_t n = v.size();
  for (std::size_t i = 0; i < n; ++i) {
    const Vec2 e_in = pd_sub(v[i], v[(i + n - 1) % n]), e_out = pd_sub(v[(i + 1) % n], v[i]);
    if (pd_cross(e_in, e_out) < -1e-9 * pd_norm(e_in) * pd_norm(e_out)) return false;
  }
  return true;
}

// Minkowski sum of a convex counter-clockwise polygon (two vertices: a segment) with the
// circumscribed polygonal disc of radius r.
std::vector<Vec2> inflate_convex(const std::vector<Vec2>& v, double r, double step_rad) {
  std::vector<Vec2> out;
  const std::size_t n = v.size();
  for (std::size_t i = 0; i < n; ++i) {
    const Vec2 e_in = pd_sub(v[i], v[(i + n - 1) % n]), e_out = pd_sub(v[(i + 1) % n], v[i]);
    const double th_in = std::atan2(-e_in.x, e_in.y);  // outward normal of a ccw edge
    const double th_out = std::atan2(-e_out.x, e_out.y);
    double phi = std::remainder(th_out - th_in, 2.0 * kPi);
    if (phi < -1e-12) phi += 2.0 * kPi;  // a segment's end turns by +pi, never -pi
    if (phi < 1e-12) {
      out.push_back({v[i].x + r * std::cos(th_in), v[i].y + r * std::sin(th_in)});
      continue;
    }
    const int k = std::max(1, static_cast<int>(std::ceil(phi / step_rad - 1e-9)));
    const double d = phi / k, rv = r / std::cos(0.5 * d);
    for (int j = 0; j < k; ++j) {
      const double th = th_in + (j + 0.5) * d;
      out.push_back({v[i].x + rv * std::cos(th), v[i].y + rv * std::sin(th)});
    }
  }
  return out;
}

BPoly to_bpoly(const std::vector<Vec2>& v) {
  BPoly p;
  for (const Vec2& q : v) p.outer().push_back(BPt(q.x, q.y));
  bg::correct(p);
  return p;
}

std::vector<Vec2> from_ring(const BPoly::ring_type& r) {
  std::vector<Vec2> out;
  for (std::size_t i = 0; i + 1 < r.size(); ++i) out.push_back({r[i].x(), r[i].y()});
  return out;
}

// The inflated shape of one polygon as convex pieces: itself when convex, else the polygon plus
// a capsule per edge (the Minkowski sum of a simple polygon is the union of those).
void inflated_pieces(std::vector<Vec2> v, double r, double step_rad, std::vector<BPoly>* out) {
  if (signed_area_mm2(v) < 0.0) std::reverse(v.begin(), v.end());
  if (is_convex_ccw(v)) {
    out->push_back(to_bpoly(inflate_convex(v, r, step_rad)));
    return;
  }
  out->push_back(to_bpoly(v));
  for (std::size_t i = 0; i < v.size(); ++i) {
    out->push_back(to_bpoly(inflate_convex({v[i], v[(i + 1) % v.size()]}, r, step_rad)));
  }
}

bool polygon_ok(const Polygon& p, const std::string& what, std::string* error) {
  if (p.vertices_mm.size() < 3) {
    *error = what + ": fewer than 3 vertices";
    return false;
  }
  for (const Vec2& q : p.vertices_mm) {
    if (!std::isfinite(q.x) || !std::isfinite(q.y)) {
      *error = what + ": a vertex is not finite";
      return false;
    }
  }
  if (std::abs(signed_area_mm2(p.vertices_mm)) < 1e-6) {
    *error = what + ": zero area";
    return false;
  }
  return true;
}

std::size_t find_root(std::vector<std::size_t>& parent, std::size_t i) {
  while (parent[i] != i) i = parent[i] = parent[parent[i]];
  return i;
}

// Unions pieces whose boxes overlap, component by component (most racks stand alone, and a
// union of everything at once costs far more than the few real overlaps).
BMulti merge_pieces(const std::vector<BPoly>& pieces) {
  using Box = bg::model::box<BPt>;
  const std::size_t n = pieces.size();
  std::vector<Box> boxes(n);
  for (std::size_t i = 0; i < n; ++i) boxes[i] = bg::return_envelope<Box>(pieces[i]);
  std::vector<std::size_t> order(n), parent(n);
  std::iota(order.begin(), order.end(), 0);
  std::iota(parent.begin(), parent.end(), 0);
  std::sort(order.begin(), order.end(), [&](std::size_t a, std::size_t b) {
    return boxes[a].min_corner().x() < boxes[b].min_corner().x();
  });
  for (std::size_t a = 0; a < n; ++a) {  // sweep along x
    const Box& ba = boxes[order[a]];
    for (std::size_t b = a + 1; b < n; ++b) {
      const Box& bb = boxes[order[b]];
      if (bb.min_corner().x() > ba.max_corner().x()) break;
      if (bb.min_corner().y() > ba.max_corner().y() || bb.max_corner().y() < ba.min_corner().y()) {
        continue;
      }
      parent[find_root(parent, order[a])] = find_root(parent, order[b]);
    }
  }
  std::vector<BMulti> groups(n);
  for (std::size_t i = 0; i < n; ++i) {
    BMulti& g = groups[find_root(parent, i)];
    if (g.empty()) {
      g.push_back(pieces[i]);
    } else {
      BMulti merged;
      bg::union_(g, pieces[i], merged);
      g.swap(merged);
    }
  }
  BMulti all;
  for (BMulti& g : groups) {
    for (BPoly& p : g) all.push_back(std::move(p));
  }
  return all;
}

}  // namespace

bool make_free_space(const Site& site, const PlannerParams& params, FreeSpace* out,
                     std::string* error) {
  const double r = params.vehicle_radius_mm + params.clearance_mm;
  if (!(r >= 0.0) || !std::isfinite(r) || !(params.arc_step_rad > 0.01) ||
      !(params.arc_step_rad <= kPi / 2)) {
    *error = "planner: radius + clearance must be finite and >= 0, arc_step_rad in (0.01, pi/2]";
    return false;
  }
  if (!polygon_ok(site.outline, "outline", error)) return false;
  std::vector<BPoly> pieces;
  for (const Obstacle& o : site.obstacles) {
    if (!polygon_ok(o.outline, "obstacle " + o.id, error)) return false;
    if (r > 0.0) {
      inflated_pieces(o.outline.vertices_mm, r, params.arc_step_rad, &pieces);
    } else {
      pieces.push_back(to_bpoly(o.outline.vertices_mm));
    }
  }
  const std::size_t obstacle_pieces = pieces.size();
  const std::vector<Vec2>& w = site.outline.vertices_mm;
  for (std::size_t i = 0; r > 0.0 && i < w.size(); ++i) {  // walls: a capsule per edge
    pieces.push_back(
        to_bpoly(inflate_convex({w[i], w[(i + 1) % w.size()]}, r, params.arc_step_rad)));
  }
  const BMulti obstacles_only =
      merge_pieces(std::vector<BPoly>(pieces.begin(), pieces.begin() + obstacle_pieces));
  const BMulti forbidden = merge_pieces(pieces);
  BMulti free_mp;
  bg::difference(to_bpoly(w), forbidden, free_mp);
  out->rings.clear();
  out->inflated.clear();
  for (const BPoly& p : free_mp) {
    out->rings.push_back(from_ring(p.outer()));
    for (const auto& h : p.inners()) out->rings.push_back(from_ring(h));
  }
  for (const BPoly& p : obstacles_only) out->inflated.push_back({from_ring(p.outer())});
  if (out->rings.empty()) {
    *error = "planner: no free space left inside the outline after inflating by " +
             std::to_string(r) + " mm";
    return false;
  }
  return true;
}

}  // namespace agv::site::plan_detail
