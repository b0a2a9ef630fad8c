// Shadows for the visibility graph's pair loop: seen from a node u, a convex hole of the free
// space (an inflated rack standing alone) hides everything strictly inside the cone of its two
// tangent rays and strictly beyond the chord between the tangent vertices: a segment from u to
// such a point crosses the chord between its ends, i.e. passes through the hole's interior, so
// the segment test would refuse it. Whole cells of candidate partners lying in one shadow are
// skipped before any pair in them is looked at. Not an API.
#pragma once

#include <cstdint>
#include <vector>

#include "planner_internal.hpp"

namespace agv::site::plan_detail {

// The free space's rings as index ranges into the flattened boundary, and which of them are
// strictly convex holes (every vertex a node, turning clockwise): only those cast shadows.
struct RingTable {
  std::vector<std::uint32_t> ring_of;      // per boundary vertex
  std::vector<std::uint32_t> first, size;  // per ring
  std::vector<std::uint8_t> convex_hole;   // per ring
  std::vector<double> max_x;               // per ring: its largest x (mm)
};

RingTable make_ring_table(const std::vector<Vec2>& pts, const std::vector<std::uint32_t>& prev,
                          const std::vector<std::uint32_t>& next);

// One hole's shadow seen from u, in coordinates relative to u: the cone from ray r
// counter-clockwise to ray l (under half a turn), cut by the chord t1 -> t2.
struct Shadow {
  Vec2 r, l, t1, chord;
  double r_norm = 0.0, l_norm = 0.0, chord_norm = 0.0;

  // Whether the point q (relative to u) lies in the shadow with a margin of margin_mm.
  bool hides(Vec2 q, double margin_mm) const {
    return pd_cross(r, q) > margin_mm * r_norm && pd_cross(q, l) > margin_mm * l_norm &&
           pd_cross(chord, pd_sub(q, t1)) < -margin_mm * chord_norm;
  }

  // Whether the convex hull of the points c[0..3] (relative to u) lies in the shadow with a
  // margin of margin_mm: inside the cone and beyond the chord (the side away from u).
  bool covers(const Vec2 (&c)[4], double margin_mm) const {
    for (const Vec2& q : c) {
      if (pd_cross(r, q) <= margin_mm * r_norm || pd_cross(q, l) <= margin_mm * l_norm) {
        return false;
      }
      // u (the origin) lies on the left of t1 -> t2 (the near side): beyond means right.
      if (pd_cross(chord, pd_sub(q, t1)) >= -margin_mm * chord_norm) return false;
    }
    return true;
  }
};

// The shadow of convex hole `ring` seen from p; false when p is not strictly outside it (then it
// hides nothing that the cone test could prove).
bool make_shadow(const RingTable& rings, const std::vector<Vec2>& pts, std::uint32_t ring, Vec2 p,
                 Shadow* out);

}  // namespace agv::site::plan_detail
