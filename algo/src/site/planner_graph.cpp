// The planner's predicates (point and segment in the free space, exact up to kOnLineMm, robust
// to segments that slide along edges or pass through vertices) over a uniform grid of the free
// space's edges, and the visibility graph over the vertices where the free space is reflex.
#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <utility>
#include <vector>

#include "planner_internal.hpp"

namespace agv::site {

using plan_detail::kOnLineMm;
using plan_detail::pd_cross;
using plan_detail::pd_dot;
using plan_detail::pd_norm;
using plan_detail::pd_sub;

void RoutePlanner::Impl::build_grid() {
  double x0 = std::numeric_limits<double>::max(), y0 = x0, x1 = -x0, y1 = -x0;
  for (const Vec2& p : pts) {
    x0 = std::min(x0, p.x), y0 = std::min(y0, p.y), x1 = std::max(x1, p.x), y1 = std::max(y1, p.y);
  }
  const double area = std::max(1.0, (x1 - x0) * (y1 - y0));
  // About two edges per cell: a blocked segment usually stops within its first few cells.
  cell_mm = std::max(1.0, std::sqrt(2.0 * area / std::max<std::size_t>(1, pts.size())));
  grid_x0 = x0 - 1.0, grid_y0 = y0 - 1.0;
  grid_nx = std::max(1, static_cast<int>(std::ceil((x1 - grid_x0 + 1.0) / cell_mm)));
  grid_ny = std::max(1, static_cast<int>(std::ceil((y1 - grid_y0 + 1.0) / cell_mm)));
  const std::size_t cells = static_cast<std::size_t>(grid_nx) * static_cast<std::size_t>(grid_ny);
  auto cell_range = [&](double lo, double hi, double o, int n) {
    const int a = static_cast<int>(std::floor((lo - kOnLineMm - o) / cell_mm));
    const int b = static_cast<int>(std::floor((hi + kOnLineMm - o) / cell_mm));
    return std::pair<int, int>{std::clamp(a, 0, n - 1), std::clamp(b, 0, n - 1)};
  };
  std::vector<std::uint32_t> count(cells + 1, 0);
  for (int pass = 0; pass < 2; ++pass) {
    std::vector<std::uint32_t> fill;
    if (pass == 1) fill.assign(cell_start.begin(), cell_start.end() - 1);
    for (std::uint32_t e = 0; e < pts.size(); ++e) {
      const Vec2 a = pts[e], b = pts[next[e]];
      const auto [i0, i1] = cell_range(std::min(a.x, b.x), std::max(a.x, b.x), grid_x0, grid_nx);
      const auto [j0, j1] = cell_range(std::min(a.y, b.y), std::max(a.y, b.y), grid_y0, grid_ny);
      for (int j = j0; j <= j1; ++j) {
        for (int i = i0; i <= i1; ++i) {
          const std::size_t c = static_cast<std::size_t>(j) * grid_nx + i;
          if (pass == 0) {
            ++count[c + 1];
          } else {
            cell_edges[fill[c]++] = e;
          }
        }
      }
    }
    if (pass == 0) {
      for (std::size_t c = 0; c < cells; ++c) count[c + 1] += count[c];
      cell_start = count;
      cell_edges.assign(cell_start.back(), 0);
    }
  }
}

bool RoutePlanner::Impl::enters_obstacle(std::uint32_t i, Vec2 v) const {
  const Vec2 c = pts[i];
  const Vec2 u_out = pd_sub(pts[next[i]], c), u_back = pd_sub(pts[prev[i]], c);
  const double lv = pd_norm(v), lo = pd_norm(u_out), lb = pd_norm(u_back);
  if (lv <= 0.0 || lo <= 0.0 || lb <= 0.0) return false;
  const double tol = 1e-12;
  const double turn = pd_cross(pd_sub(c, pts[prev[i]]), u_out) / (lo * lb);
  const double s_out = pd_cross(u_out, v) / (lo * lv), s_back = pd_cross(v, u_back) / (lb * lv);
  if (turn > tol) return s_out < -tol || s_back < -tol;  // free cone narrower than a half-plane
  if (turn < -tol) {
    const double s1 = pd_cross(u_back, v) / (lb * lv), s2 = pd_cross(v, u_out) / (lo * lv);
    return s1 > tol && s2 > tol;  // strictly inside the obstacle's cone
  }
  if (pd_dot(u_out, u_back) > 0.0) return true;  // a spike back along itself: no free cone
  return s_out < -tol;
}

bool RoutePlanner::Impl::tangent_at(std::uint32_t i, Vec2 v) const {
  const Vec2 c = pts[i];
  const double lv = pd_norm(v);
  if (lv <= 0.0) return true;
  const double tol = kOnLineMm * lv;
  const double sp = pd_cross(v, pd_sub(pts[prev[i]], c)), sn = pd_cross(v, pd_sub(pts[next[i]], c));
  return !((sp > tol && sn < -tol) || (sp < -tol && sn > tol));
}

namespace {

int sign_tol(double v, double tol) { return v > tol ? 1 : (v < -tol ? -1 : 0); }

// Position of p along a->b as a fraction of its length (p assumed on the line).
double param_on(Vec2 a, Vec2 b, Vec2 p) {
  const Vec2 d = pd_sub(b, a);
  return pd_dot(pd_sub(p, a), d) / pd_dot(d, d);
}

}  // namespace

bool RoutePlanner::Impl::edge_blocks(Vec2 a, Vec2 b, double lab, std::uint32_t e) const {
  const Vec2 ab = pd_sub(b, a);
  const double tol_ab = kOnLineMm * lab, t_eps = kOnLineMm / lab;
  const Vec2 c = pts[e], d = pts[next[e]];
  const int s1 = sign_tol(pd_cross(ab, pd_sub(c, a)), tol_ab);
  const int s2 = sign_tol(pd_cross(ab, pd_sub(d, a)), tol_ab);
  if (s1 * s2 > 0) return false;
  const Vec2 cd = pd_sub(d, c);
  const double lcd = pd_norm(cd);
  if (lcd <= 0.0) return false;
  const double tol_cd = kOnLineMm * lcd;
  const int s3 = sign_tol(pd_cross(cd, pd_sub(a, c)), tol_cd);
  const int s4 = sign_tol(pd_cross(cd, pd_sub(b, c)), tol_cd);
  if (s1 * s2 < 0 && s3 * s4 < 0) return true;  // proper crossing
  if (s1 == 0) {  // the vertex c touches the segment: leave and arrive through its free cone
    const double t = param_on(a, b, c);
    if (t >= -t_eps && t <= 1.0 + t_eps) {
      if (t > t_eps && enters_obstacle(e, pd_sub(a, c))) return true;
      if (t < 1.0 - t_eps && enters_obstacle(e, ab)) return true;
    }
  }
  // An endpoint inside the edge (not at a vertex): the segment must leave to the free side.
  const double ta = param_on(c, d, a), tb = param_on(c, d, b), te = kOnLineMm / lcd;
  if (s3 == 0 && ta > te && ta < 1.0 - te && s4 < 0) return true;
  if (s4 == 0 && tb > te && tb < 1.0 - te && s3 < 0) return true;
  return false;
}

bool RoutePlanner::Impl::segment_clear(Vec2 a, Vec2 b, std::uint32_t* blocker) const {
  const Vec2 ab = pd_sub(b, a);
  const double lab = pd_norm(ab);
  if (lab <= kOnLineMm) return true;
  const double tol_ab = kOnLineMm * lab;
  // Columns of cells from a towards b; in each, the rows the segment spans (widened by the
  // tolerance, so a segment through a cell corner sees the edges of all four cells).
  const int ia =
      std::clamp(static_cast<int>(std::floor((a.x - grid_x0) / cell_mm)), 0, grid_nx - 1);
  const int ib =
      std::clamp(static_cast<int>(std::floor((b.x - grid_x0) / cell_mm)), 0, grid_nx - 1);
  const int di = ib >= ia ? 1 : -1;
  for (int i = ia;; i += di) {
    double xl = grid_x0 + i * cell_mm - kOnLineMm, xr = xl + cell_mm + 2 * kOnLineMm;
    xl = std::max(xl, std::min(a.x, b.x)), xr = std::min(xr, std::max(a.x, b.x));
    double yl, yr;
    if (std::abs(ab.x) < 1e-12) {
      yl = a.y, yr = b.y;
    } else {
      yl = a.y + ab.y * (xl - a.x) / ab.x, yr = a.y + ab.y * (xr - a.x) / ab.x;
    }
    const double ylo = std::min(yl, yr) - kOnLineMm, yhi = std::max(yl, yr) + kOnLineMm;
    const int j0 =
        std::clamp(static_cast<int>(std::floor((ylo - grid_y0) / cell_mm)), 0, grid_ny - 1);
    const int j1 =
        std::clamp(static_cast<int>(std::floor((yhi - grid_y0) / cell_mm)), 0, grid_ny - 1);
    for (int jj = 0; jj <= j1 - j0; ++jj) {
      const int j = ab.y >= 0 ? j0 + jj : j1 - jj;
      const std::size_t c = static_cast<std::size_t>(j) * grid_nx + i;
      for (std::uint32_t k = cell_start[c]; k < cell_start[c + 1]; ++k) {
        const std::uint32_t e = cell_edges[k];
        if (may_block(a, ab, tol_ab, e) && edge_blocks(a, b, lab, e)) {
          if (blocker) *blocker = e;
          return false;
        }
      }
    }
    if (i == ib) break;
  }
  return true;
}

bool RoutePlanner::Impl::point_free(Vec2 p) const {
  // Even-odd count over every edge; a point on an edge is free (the free space is closed).
  bool inside = false;
  for (std::uint32_t e = 0; e < pts.size(); ++e) {
    const Vec2 c = pts[e], d = pts[next[e]];
    const Vec2 cd = pd_sub(d, c);
    const double l2 = pd_dot(cd, cd);
    const double t = l2 > 0.0 ? std::clamp(pd_dot(pd_sub(p, c), cd) / l2, 0.0, 1.0) : 0.0;
    if (pd_norm(pd_sub(p, {c.x + t * cd.x, c.y + t * cd.y})) <= kOnLineMm) return true;
    if ((c.y > p.y) != (d.y > p.y) && p.x < c.x + (p.y - c.y) * cd.x / cd.y) inside = !inside;
  }
  return inside;
}

bool RoutePlanner::Impl::segment_free(Vec2 a, Vec2 b) const {
  return point_free(a) && point_free(b) && segment_clear(a, b);
}

namespace {

// Nodes bucketed by a coarse grid (CSR), so that a node's candidate partners can be taken cell by
// cell, skipping the cells that lie wholly inside the node's non-tangent double cone.
//
// Within a cell the nodes are sorted into kAngleBins bins by where their tangent interval
// starts: the directions of lines that can touch a node without cutting between its ring
// neighbours form one interval of line angles (less than 180 degrees wide, widened by the tangent
// test's tolerance). Seen from a node u, a cell covers a small range of line angles, so only the
// bins whose nodes' intervals can reach that range are visited.
constexpr int kAngleBins = 32;
constexpr double kBinWidth = 2.0 / kAngleBins;  // in pseudo-angle units (a half turn is 2)

struct NodeCells {
  double x0 = 0.0, y0 = 0.0, size = 1.0;
  int nx = 1, ny = 1;
  std::vector<std::uint32_t> start, nodes;  // per cell and bin: start[c * kAngleBins + b]
  std::vector<double> widest;               // per cell: its nodes' widest tangent interval
};

// The direction of v as a pseudo-angle in [0, 4) (the "diamond angle": monotonic in the angle,
// a quarter turn is 1, no trigonometry). v must not be zero.
double pseudo_angle(Vec2 v) {
  if (v.y >= 0.0) return v.x >= 0.0 ? v.y / (v.x + v.y) : 1.0 - v.x / (v.y - v.x);
  return v.x < 0.0 ? 2.0 - v.y / (-v.x - v.y) : 3.0 + v.x / (v.x - v.y);
}

double wrap2(double a) { return a - 2.0 * std::floor(a * 0.5); }

// A node's tangent interval of line pseudo-angles [start, start + width] (modulo 2): from its
// outgoing edge counter-clockwise to its incoming one, widened like TangentWedges. Width 2: every
// direction (a degenerate or tiny corner).
std::pair<double, double> tangent_interval(Vec2 tp, Vec2 tn) {
  const double lmin = std::min(pd_norm(tp), pd_norm(tn));
  const double widen = lmin > 0.0 ? 4.0 * kOnLineMm / lmin + 1e-9 : 1.0;
  if (widen >= 0.01) return {0.0, 2.0};
  // The pseudo-angle changes at most as fast as the angle: widening by the angle suffices.
  const double a = wrap2(pseudo_angle(tn)), b = wrap2(pseudo_angle(tp));
  const double width = wrap2(b - a) + 2.0 * widen;
  if (width >= 2.0) return {0.0, 2.0};
  return {wrap2(a - widen), width};
}

// The bins to visit for a cell whose corners relative to u are c[0..3] (first bin, count): those
// holding nodes whose interval (at most `widest` wide) can meet the range of line directions
// from u into the cell.
std::pair<int, int> bins_to_visit(const Vec2 (&c)[4], double widest) {
  const std::pair<int, int> all{0, kAngleBins};
  if (c[0].x <= 0.0 && c[3].x >= 0.0 && c[0].y <= 0.0 && c[3].y >= 0.0) return all;
  // Seen from outside, the box spans under half a turn: pseudo-angles within 2 of the first.
  const double a0 = pseudo_angle(c[0]);
  double lo = 0.0, hi = 0.0;
  for (int k = 1; k < 4; ++k) {
    double d = pseudo_angle(c[k]) - a0;
    if (d > 2.0) d -= 4.0;
    if (d < -2.0) d += 4.0;
    lo = std::min(lo, d), hi = std::max(hi, d);
  }
  const double from = a0 + lo - widest - 1e-9, span = hi - lo + widest + 2e-9;
  if (span >= 2.0 - kBinWidth) return all;
  const int first = std::min(kAngleBins - 1, static_cast<int>(wrap2(from) / kBinWidth));
  const int last = static_cast<int>(std::floor((wrap2(from) + span) / kBinWidth));
  return {first, std::min(kAngleBins, last - first + 1)};
}

NodeCells bucket_nodes(const std::vector<Vec2>& pos, const std::vector<Vec2>& to_prev,
                       const std::vector<Vec2>& to_next) {
  NodeCells g;
  double x1 = -std::numeric_limits<double>::max(), y1 = x1;
  g.x0 = g.y0 = std::numeric_limits<double>::max();
  for (const Vec2& p : pos) {
    g.x0 = std::min(g.x0, p.x), g.y0 = std::min(g.y0, p.y);
    x1 = std::max(x1, p.x), y1 = std::max(y1, p.y);
  }
  if (pos.empty()) g.x0 = g.y0 = x1 = y1 = 0.0;
  // About 32 nodes per cell (spread over the angle bins): the cone test per cell then costs less
  // than the pairs it skips.
  const double area = std::max(1.0, (x1 - g.x0) * (y1 - g.y0));
  g.size = std::max(1.0, std::sqrt(32.0 * area / std::max<std::size_t>(1, pos.size())));
  g.nx = std::max(1, static_cast<int>((x1 - g.x0) / g.size) + 1);
  g.ny = std::max(1, static_cast<int>((y1 - g.y0) / g.size) + 1);
  std::vector<std::uint32_t> cell(pos.size());
  const std::size_t cells = static_cast<std::size_t>(g.nx) * g.ny;
  g.start.assign(cells * kAngleBins + 1, 0);
  g.widest.assign(cells, 0.0);
  for (std::size_t k = 0; k < pos.size(); ++k) {
    const int i = std::min(g.nx - 1, static_cast<int>((pos[k].x - g.x0) / g.size));
    const int j = std::min(g.ny - 1, static_cast<int>((pos[k].y - g.y0) / g.size));
    const auto [from, width] = tangent_interval(to_prev[k], to_next[k]);
    const int bin = std::min(kAngleBins - 1, static_cast<int>(from / kBinWidth));
    const auto c = static_cast<std::size_t>(j * g.nx + i);
    g.widest[c] = std::max(g.widest[c], width);
    cell[k] = static_cast<std::uint32_t>(c * kAngleBins + bin);
    ++g.start[cell[k] + 1];
  }
  for (std::size_t c = 0; c + 1 < g.start.size(); ++c) g.start[c + 1] += g.start[c];
  g.nodes.resize(pos.size());
  std::vector<std::uint32_t> fill(g.start.begin(), g.start.end() - 1);
  for (std::size_t k = 0; k < pos.size(); ++k)
    g.nodes[fill[cell[k]]++] = static_cast<std::uint32_t>(k);
  return g;
}

// The x-extent of wedge {s a + t b : s, t >= 0} (a to b counter-clockwise, under 180 deg) within
// the strip ya <= y <= yb; false when they do not meet. Infinite ends where the wedge holds +-x.
bool wedge_strip_extent(Vec2 a, Vec2 b, double ya, double yb, double* lo, double* hi) {
  double x0 = std::numeric_limits<double>::infinity(), x1 = -x0;
  if (ya <= 0.0 && yb >= 0.0) x0 = x1 = 0.0;
  for (const Vec2 r : {a, b}) {
    for (const double y : {ya, yb}) {
      if (r.y == 0.0) continue;
      const double t = y / r.y;
      if (t > 0.0) x0 = std::min(x0, t * r.x), x1 = std::max(x1, t * r.x);
    }
  }
  const double inf = std::numeric_limits<double>::infinity();
  if (pd_cross(a, {1.0, 0.0}) >= 0.0 && pd_cross({1.0, 0.0}, b) >= 0.0) x1 = inf;
  if (pd_cross(a, {-1.0, 0.0}) >= 0.0 && pd_cross({-1.0, 0.0}, b) >= 0.0) x0 = -inf;
  if (x0 > x1) return false;
  *lo = x0, *hi = x1;
  return true;
}

// Rotates v by angle (counter-clockwise).
Vec2 rotate(Vec2 v, double angle) {
  const double c = std::cos(angle), s = std::sin(angle);
  return {c * v.x - s * v.y, s * v.x + c * v.y};
}

// The tangent directions at a node (ring offsets tp, tn): two wedges, bounded by the ring edges
// and their extensions, widened by the tangent test's tolerance (as an angle) and a margin for
// rounding. columns() gives, per row of cells, the column spans that the wedges reach.
struct TangentWedges {
  std::array<std::pair<Vec2, Vec2>, 2> w;
  bool usable = false;  // false: every cell of every row

  static TangentWedges make(Vec2 tp, Vec2 tn) {
    TangentWedges t;
    const double lmin = std::min(pd_norm(tp), pd_norm(tn));
    const double widen = lmin > 0.0 ? 4.0 * kOnLineMm / lmin + 1e-9 : 1.0;
    t.w = {std::pair{tn, Vec2{-tp.x, -tp.y}}, std::pair{tp, Vec2{-tn.x, -tn.y}}};
    t.usable = widen < 0.01;
    for (auto& [a, b] : t.w) {
      if (pd_cross(a, b) < 0.0) std::swap(a, b);
      a = rotate(a, -widen), b = rotate(b, widen);
      if (pd_cross(a, b) <= 0.0) t.usable = false;  // a half-plane or more: no use
    }
    return t;
  }

  // Up to two column spans {first, last} of row cj (an empty span has first > last), disjoint.
  std::array<std::pair<int, int>, 2> columns(const NodeCells& cells, Vec2 p, int cj) const {
    std::array<std::pair<int, int>, 2> cols{std::pair{0, cells.nx - 1}, std::pair{1, 0}};
    if (!usable) return cols;
    const double ya = cells.y0 + cj * cells.size - 1.0 - p.y, yb = ya + cells.size + 2.0;
    for (int k = 0; k < 2; ++k) {
      double lo, hi;
      cols[k] = {1, 0};
      if (!wedge_strip_extent(w[k].first, w[k].second, ya, yb, &lo, &hi)) continue;
      const double fl = std::floor((lo - 1.0 + p.x - cells.x0) / cells.size);
      const double fh = std::floor((hi + 1.0 + p.x - cells.x0) / cells.size);
      if (fh < 0.0 || fl > cells.nx - 1) continue;
      cols[k] = {static_cast<int>(std::max(0.0, fl)),
                 static_cast<int>(std::min<double>(cells.nx - 1, fh))};
    }
    if (cols[0].first > cols[0].second) std::swap(cols[0], cols[1]);
    if (cols[1].first <= cols[1].second && cols[1].first <= cols[0].second + 1 &&
        cols[0].first <= cols[1].second + 1) {  // overlapping: visit each cell once
      cols[0] = {std::min(cols[0].first, cols[1].first), std::max(cols[0].second, cols[1].second)};
      cols[1] = {1, 0};
    }
    return cols;
  }
};

enum Tangency { kNotTangent, kTangent, kNearlyTangent };

// Not tangent when sp and sn have strictly opposite signs beyond the tolerance kOnLineMm * |v|
// (tol2 its square: no square root per pair). Tangent when both ring neighbours lie strictly on
// one side: then v cannot point into the obstacle at a node (its cone is under 180 degrees and
// v lies outside it), so only nearly tangent directions need the obstacle-side test.
Tangency tangency(Vec2 v, Vec2 tp, Vec2 tn, double tol2) {
  const double sp = pd_cross(v, tp), sn = pd_cross(v, tn);
  const bool sp_big = sp * sp > tol2, sn_big = sn * sn > tol2;
  if (!sp_big || !sn_big) return kNearlyTangent;
  return (sp > 0.0) == (sn > 0.0) ? kTangent : kNotTangent;
}

}  // namespace

void RoutePlanner::Impl::build_graph() {
  for (std::uint32_t i = 0; i < pts.size(); ++i) {
    const Vec2 e_in = pd_sub(pts[i], pts[prev[i]]), e_out = pd_sub(pts[next[i]], pts[i]);
    const double l = pd_norm(e_in) * pd_norm(e_out);
    if (l > 0.0 && pd_cross(e_in, e_out) < -1e-9 * l) node_vertex.push_back(i);
  }
  const std::size_t n = node_vertex.size();
  std::vector<Vec2> pos(n), to_prev(n), to_next(n);
  for (std::size_t k = 0; k < n; ++k) {
    const std::uint32_t i = node_vertex[k];
    pos[k] = pts[i], to_prev[k] = pd_sub(pts[prev[i]], pts[i]),
    to_next[k] = pd_sub(pts[next[i]], pts[i]);
  }
  const NodeCells cells = bucket_nodes(pos, to_prev, to_next);
  // The nodes' data in cell order, side by side, for the pair loop.
  std::vector<Vec2> cpos(n), cprev(n), cnext(n);
  for (std::size_t k = 0; k < n; ++k) {
    const std::uint32_t w = cells.nodes[k];
    cpos[k] = pos[w], cprev[k] = to_prev[w], cnext[k] = to_next[w];
  }
  // Per node, the last edges that blocked a segment from it: segments from one node in nearby
  // directions are mostly blocked by the same few edges, and any edge that blocks is proof.
  constexpr int kRecent = 4;
  constexpr std::uint32_t kNone = std::numeric_limits<std::uint32_t>::max();
  std::vector<std::array<std::uint32_t, kRecent>> recent(n);
  for (auto& r : recent) r.fill(kNone);
  auto remember = [&](std::uint32_t k, std::uint32_t e) {
    if (recent[k][0] == e) return;
    std::copy_backward(recent[k].begin(), recent[k].end() - 1, recent[k].end());
    recent[k][0] = e;
  };
  std::vector<std::pair<std::uint32_t, std::uint32_t>> edges;
  std::vector<plan_detail::EdgeWeight> weights;
  for (std::uint32_t u = 0; u < n; ++u) {
    const Vec2 p = pos[u], tp = to_prev[u], tn = to_next[u];
    const double tnorm = pd_norm(tp) + pd_norm(tn) + 1.0;  // scales the cell test's margin
    const TangentWedges wedges = TangentWedges::make(tp, tn);
    // Each pair is taken from the node it leaves forwards (+x first, then +y, then the higher
    // index for coincident nodes): v is exactly -v seen from the other end, so exactly one end
    // takes it, and the columns wholly behind the node (by a 1 mm margin) are never visited.
    const int ci_min =
        std::max(0, static_cast<int>(std::floor((p.x - 1.0 - cells.x0) / cells.size)));
    for (int cj = 0; cj < cells.ny; ++cj) {
      auto cols = wedges.columns(cells, p, cj);
      for (auto& span : cols) span.first = std::max(span.first, ci_min);
      for (int ci = cols[0].first, span = 0; span < 2; ++ci) {
        if (ci > cols[span].second) {
          if (++span == 2) break;
          ci = cols[span].first - 1;
          continue;
        }
        // A cell wholly inside one open half of the double cone where the line through u cuts
        // between its ring neighbours holds no tangent partner (the cell is convex, the cone
        // too; the margin covers the tangent test's tolerance and rounding).
        const double xl = cells.x0 + ci * cells.size - 1.0 - p.x, xh = xl + cells.size + 2.0;
        const double yl = cells.y0 + cj * cells.size - 1.0 - p.y, yh = yl + cells.size + 2.0;
        const Vec2 corner[4] = {{xl, yl}, {xh, yl}, {xl, yh}, {xh, yh}};
        const double reach =
            std::max(std::abs(xl), std::abs(xh)) + std::max(std::abs(yl), std::abs(yh));
        const double tol = 4.0 * kOnLineMm * reach * tnorm;
        int pos_side = 0, neg_side = 0;
        for (const Vec2& c : corner) {
          const double sp = pd_cross(c, tp), sn = pd_cross(c, tn);
          pos_side += sp > tol && sn < -tol;
          neg_side += sp < -tol && sn > tol;
        }
        if (pos_side == 4 || neg_side == 4) continue;
        const std::size_t c = static_cast<std::size_t>(cj) * cells.nx + ci;
        const auto [bin0, bins] = bins_to_visit(corner, cells.widest[c]);
        for (int bi = 0; bi < bins; ++bi) {
          const std::size_t cb =
              c * kAngleBins + static_cast<std::size_t>((bin0 + bi) % kAngleBins);
          for (std::uint32_t k = cells.start[cb]; k < cells.start[cb + 1]; ++k) {
            const Vec2 v = pd_sub(cpos[k], p);
            if (v.x < 0.0 || (v.x == 0.0 && (v.y < 0.0 || (v.y == 0.0 && cells.nodes[k] <= u))))
              continue;
            const double tol2 = kOnLineMm * kOnLineMm * pd_dot(v, v);
            const Tangency tu = tangency(v, tp, tn, tol2);
            if (tu == kNotTangent) continue;
            const Tangency tw = tangency(v, cprev[k], cnext[k], tol2);
            if (tw == kNotTangent) continue;
            const std::uint32_t w = cells.nodes[k];
            if ((tu == kNearlyTangent && enters_obstacle(node_vertex[u], v)) ||
                (tw == kNearlyTangent && enters_obstacle(node_vertex[w], {-v.x, -v.y})))
              continue;
            const double l = pd_norm(v);
            const auto cached = [&](std::uint32_t e) {
              return e != kNone && may_block(p, v, kOnLineMm * l, e) &&
                     edge_blocks(p, cpos[k], l, e);
            };
            bool seen = false;
            for (int r = 0; r < kRecent && !seen; ++r)
              seen = cached(recent[u][r]) || cached(recent[w][r]);
            if (seen) continue;
            std::uint32_t e = kNone;
            if (!segment_clear(p, cpos[k], &e)) {
              remember(u, e), remember(w, e);
              continue;
            }
            edges.emplace_back(u, w);
            edges.emplace_back(w, u);
            weights.push_back({l});
            weights.push_back({l});
          }
        }
      }
    }
  }
  edge_count = edges.size() / 2;
  graph = plan_detail::Graph(boost::edges_are_unsorted_multi_pass, edges.begin(), edges.end(),
                             weights.begin(), static_cast<std::uint32_t>(n));
}

bool RoutePlanner::build(const Site& site, const PlannerParams& params, RoutePlanner* out,
                         std::string* error) {
  auto impl = std::make_unique<Impl>();
  impl->params = params;
  if (!plan_detail::make_free_space(site, params, &impl->free, error)) return false;
  impl->obstacles = site.obstacles;
  impl->outline = site.outline;
  for (const std::vector<Vec2>& ring : impl->free.rings) {
    const auto base = static_cast<std::uint32_t>(impl->pts.size());
    const auto m = static_cast<std::uint32_t>(ring.size());
    for (std::uint32_t k = 0; k < m; ++k) {
      impl->pts.push_back(ring[k]);
      impl->prev.push_back(base + (k + m - 1) % m);
      impl->next.push_back(base + (k + 1) % m);
    }
  }
  for (const std::uint32_t j : impl->next) impl->pts_next.push_back(impl->pts[j]);
  impl->build_grid();
  impl->build_graph();
  out->impl_ = std::move(impl);
  return true;
}

RoutePlanner::RoutePlanner() = default;
RoutePlanner::~RoutePlanner() = default;
RoutePlanner::RoutePlanner(RoutePlanner&&) noexcept = default;
RoutePlanner& RoutePlanner::operator=(RoutePlanner&&) noexcept = default;

bool RoutePlanner::point_free(Vec2 p_mm) const { return impl_ && impl_->point_free(p_mm); }
bool RoutePlanner::segment_free(Vec2 a_mm, Vec2 b_mm) const {
  return impl_ && impl_->segment_free(a_mm, b_mm);
}
const std::vector<Polygon>& RoutePlanner::inflated() const {
  static const std::vector<Polygon> kNone;
  return impl_ ? impl_->free.inflated : kNone;
}
std::vector<std::vector<Vec2>> RoutePlanner::free_boundary() const {
  return impl_ ? impl_->free.rings : std::vector<std::vector<Vec2>>{};
}
std::size_t RoutePlanner::vertex_count() const { return impl_ ? impl_->node_vertex.size() : 0; }
std::size_t RoutePlanner::edge_count() const { return impl_ ? impl_->edge_count : 0; }

}  // namespace agv::site
