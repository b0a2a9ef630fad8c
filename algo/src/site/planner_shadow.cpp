// Shadows of convex holes for the visibility graph's pair loop (planner_shadow.hpp).
#include "planner_shadow.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

namespace agv::site::plan_detail {

RingTable make_ring_table(const std::vector<Vec2>& pts, const std::vector<std::uint32_t>& prev,
                          const std::vector<std::uint32_t>& next) {
  RingTable t;
  const auto n = static_cast<std::uint32_t>(pts.size());
  t.ring_of.assign(n, 0);
  // Rings are stored one after the other: a ring starts where prev does not point one back.
  for (std::uint32_t i = 0; i < n; ++i) {
    if (i == 0 || prev[i] != i - 1) {
      t.first.push_back(i);
      t.size.push_back(0);
    }
    t.ring_of[i] = static_cast<std::uint32_t>(t.first.size() - 1);
    ++t.size.back();
  }
  t.convex_hole.assign(t.first.size(), 0);
  t.max_x.assign(t.first.size(), -std::numeric_limits<double>::infinity());
  for (std::uint32_t i = 0; i < n; ++i)
    t.max_x[t.ring_of[i]] = std::max(t.max_x[t.ring_of[i]], pts[i].x);
  for (std::size_t r = 0; r < t.first.size(); ++r) {
    bool convex = t.size[r] >= 3;
    for (std::uint32_t k = 0; convex && k < t.size[r]; ++k) {
      const std::uint32_t i = t.first[r] + k;
      const Vec2 e_in = pd_sub(pts[i], pts[prev[i]]), e_out = pd_sub(pts[next[i]], pts[i]);
      const double l = pd_norm(e_in) * pd_norm(e_out);
      // Strictly clockwise at every vertex (the node test's threshold), so the ring bounds a
      // convex region of positive area outside the free space.
      convex = l > 0.0 && pd_cross(e_in, e_out) < -1e-9 * l;
    }
    // Clockwise turns alone also fit a ring that winds several times: require one turn.
    double turn = 0.0;
    for (std::uint32_t k = 0; convex && k < t.size[r]; ++k) {
      const std::uint32_t i = t.first[r] + k;
      const Vec2 e_in = pd_sub(pts[i], pts[prev[i]]), e_out = pd_sub(pts[next[i]], pts[i]);
      turn += std::atan2(pd_cross(e_in, e_out), pd_dot(e_in, e_out));
    }
    t.convex_hole[r] = convex && std::abs(turn + 2.0 * kPi) < 1e-6;
  }
  return t;
}

bool make_shadow(const RingTable& rings, const std::vector<Vec2>& pts, std::uint32_t ring, Vec2 p,
                 Shadow* out) {
  const std::uint32_t first = rings.first[ring], m = rings.size[ring];
  // Strictly outside (by far more than any tolerance of the segment test): on the outer side
  // (the left, the ring runs clockwise) of some edge.
  bool outside = false;
  for (std::uint32_t k = 0; k < m && !outside; ++k) {
    const Vec2 a = pts[first + k], b = pts[first + (k + 1) % m];
    const Vec2 ab = pd_sub(b, a);
    const double side = pd_cross(ab, pd_sub(p, a));  // > 1 mm * |ab|, without a square root
    outside = side > 0.0 && side * side > pd_dot(ab, ab);
  }
  if (!outside) return false;
  // Seen from outside a convex polygon, its vertices span under half a turn: the running
  // extremes by cross product are the tangent vertices.
  Vec2 r = pd_sub(pts[first], p), l = r;
  for (std::uint32_t k = 1; k < m; ++k) {
    const Vec2 d = pd_sub(pts[first + k], p);
    if (pd_cross(r, d) < 0.0) r = d;
    if (pd_cross(l, d) > 0.0) l = d;
  }
  if (pd_cross(r, l) <= 0.0) return false;
  out->r = r, out->l = l, out->t1 = r, out->chord = pd_sub(l, r);
  out->r_norm = pd_norm(r), out->l_norm = pd_norm(l), out->chord_norm = pd_norm(out->chord);
  return true;
}

}  // namespace agv::site::plan_detail
