
// The visibility graph's edges: every pair of nodes whose line is tangent at both ends and whose
// segment is free. Candidate partners are taken cell by cell from a coarse grid of the nodes,
// only in the directions where a node can be tangent, and cells hidden behind a convex hole are
// skipped whole (planner_shadow.hpp).
#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <utility>
#include <vector>

#include "planner_internal.hpp"
#include "planner_shadow.hpp"

namespace agv::site {

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

// Per node, the last edges that blocked a segment from it: segments from one node in nearby
// directions are mostly blocked by the same few edges, and any edge that blocks is proof.
constexpr int kRecent = 4;
constexpr std::uint32_t kNoEdge = std::numeric_limits<std::uint32_t>::max();
// Shadows are taken from the convex holes with an edge within this many cells of the edge grid
// around a node (the racks next to it hide most of the site), and from every hole that blocks
// a segment tested from it. One cell (3 x 3 cells, about 4 m across on the benchmark's site)
// did best: 0 cost 0.4 % more instructions, 2 cost 3.6 % more, 3 cost 12 % more.
constexpr int kShadowReachCells = 1;
// A cell is skipped only when it lies this far inside a shadow: far above the segment test's
// tolerance, so every pair in it is refused by a proper crossing of the hole's boundary.
constexpr double kShadowMarginMm = 1.0;

// The pair loop. Planner is RoutePlanner::Impl (private to RoutePlanner, hence a parameter).
template <class Planner>
class EdgeFinder {
 public:
  explicit EdgeFinder(const Planner& m) : m_(m), n_(m.node_vertex.size()) {
    pos_.resize(n_), to_prev_.resize(n_), to_next_.resize(n_);
    for (std::size_t k = 0; k < n_; ++k) {
      const std::uint32_t i = m.node_vertex[k];
      pos_[k] = m.pts[i], to_prev_[k] = pd_sub(m.pts[m.prev[i]], m.pts[i]),
      to_next_[k] = pd_sub(m.pts[m.next[i]], m.pts[i]);
    }
    cells_ = bucket_nodes(pos_, to_prev_, to_next_);
    // The nodes' data in cell order, side by side, for the pair loop.
    cpos_.resize(n_), cprev_.resize(n_), cnext_.resize(n_);
    for (std::size_t k = 0; k < n_; ++k) {
      const std::uint32_t w = cells_.nodes[k];
      cpos_[k] = pos_[w], cprev_[k] = to_prev_[w], cnext_[k] = to_next_[w];
    }
    recent_.resize(n_);
    for (auto& r : recent_) r.fill(kNoEdge);
    rings_ = plan_detail::make_ring_table(m.pts, m.prev, m.next);
    ring_seen_from_.assign(rings_.first.size(), kNoEdge);
  }

  void run() {
    for (std::uint32_t u = 0; u < n_; ++u) from_node(u);
  }

  std::vector<std::pair<std::uint32_t, std::uint32_t>> edges;
  std::vector<plan_detail::EdgeWeight> weights;

 private:
  void from_node(std::uint32_t u);
  bool hidden(const Vec2 (&corner)[4]) const {
    for (const plan_detail::Shadow& s : shadows_) {
      if (s.covers(corner, kShadowMarginMm)) return true;
    }
    return false;
  }
  void gather_shadows(std::uint32_t u);
  void add_shadow(std::uint32_t ring);
  void remember(std::uint32_t k, std::uint32_t e) {
    if (recent_[k][0] == e) return;
    std::copy_backward(recent_[k].begin(), recent_[k].end() - 1, recent_[k].end());
    recent_[k][0] = e;
  }
  void visit_cell(std::uint32_t u, std::size_t c, const Vec2 (&corner)[4]);
  void try_pair(std::uint32_t u, std::uint32_t k);

  const Planner& m_;
  std::size_t n_;
  std::vector<Vec2> pos_, to_prev_, to_next_, cpos_, cprev_, cnext_;
  NodeCells cells_;
  std::vector<std::array<std::uint32_t, kRecent>> recent_;
  plan_detail::RingTable rings_;
  // The node whose pairs are being taken: its position, ring offsets and ring, and the shadows
  // of the holes seen from it.
  Vec2 p_, tp_, tn_;
  std::uint32_t own_ring_ = 0;
  std::uint32_t u_ = kNoEdge;
  std::vector<std::uint32_t> ring_seen_from_;  // per ring: the last node that took its shadow
  std::vector<plan_detail::Shadow> shadows_;
};

template <class Planner>
void EdgeFinder<Planner>::add_shadow(std::uint32_t ring) {
  // Pairs are taken towards +x only (from_node): a hole wholly behind p hides none of them.
  if (ring_seen_from_[ring] == u_ || !rings_.convex_hole[ring] || ring == own_ring_ ||
      rings_.max_x[ring] < p_.x)
    return;
  ring_seen_from_[ring] = u_;
  plan_detail::Shadow s;
  if (plan_detail::make_shadow(rings_, m_.pts, ring, p_, &s)) shadows_.push_back(s);
}

template <class Planner>
void EdgeFinder<Planner>::gather_shadows(std::uint32_t u) {
  shadows_.clear();
  own_ring_ = rings_.ring_of[m_.node_vertex[u]];
  const Planner& m = m_;
  const int gi = static_cast<int>(std::floor((p_.x - m.grid_x0) / m.cell_mm));
  const int gj = static_cast<int>(std::floor((p_.y - m.grid_y0) / m.cell_mm));
  const int j0 = std::max(0, gj - kShadowReachCells);
  const int j1 = std::min(m.grid_ny - 1, gj + kShadowReachCells);
  const int i0 = std::max(0, gi - kShadowReachCells);
  const int i1 = std::min(m.grid_nx - 1, gi + kShadowReachCells);
  for (int j = j0; j <= j1; ++j) {
    for (int i = i0; i <= i1; ++i) {
      const std::size_t c = static_cast<std::size_t>(j) * m.grid_nx + i;
      for (std::uint32_t k = m.cell_start[c]; k < m.cell_start[c + 1]; ++k)
        add_shadow(rings_.ring_of[m.cell_edges[k]]);
    }
  }
}

template <class Planner>
void EdgeFinder<Planner>::from_node(std::uint32_t u) {
  u_ = u, p_ = pos_[u], tp_ = to_prev_[u], tn_ = to_next_[u];
  gather_shadows(u);
  const Vec2 p = p_, tp = tp_, tn = tn_;
  const NodeCells& cells = cells_;
  const double tnorm = pd_norm(tp) + pd_norm(tn) + 1.0;  // scales the cell test's margin
  const TangentWedges wedges = TangentWedges::make(tp, tn);
  // Each pair is taken from the node it leaves forwards (+x first, then +y, then the higher
  // index for coincident nodes): v is exactly -v seen from the other end, so exactly one end
  // takes it, and the columns wholly behind the node (by a 1 mm margin) are never visited.
  const int ci_min = std::max(0, static_cast<int>(std::floor((p.x - 1.0 - cells.x0) / cells.size)));
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
      if (pos_side == 4 || neg_side == 4 || hidden(corner)) continue;
      visit_cell(u, static_cast<std::size_t>(cj) * cells.nx + ci, corner);
    }
  }
}

template <class Planner>
void EdgeFinder<Planner>::visit_cell(std::uint32_t u, std::size_t c, const Vec2 (&corner)[4]) {
  const auto [bin0, bins] = bins_to_visit(corner, cells_.widest[c]);
  for (int bi = 0; bi < bins; ++bi) {
    const std::size_t cb = c * kAngleBins + static_cast<std::size_t>((bin0 + bi) % kAngleBins);
    for (std::uint32_t k = cells_.start[cb]; k < cells_.start[cb + 1]; ++k) try_pair(u, k);
  }
}

template <class Planner>
void EdgeFinder<Planner>::try_pair(std::uint32_t u, std::uint32_t k) {
  const Vec2 p = p_, v = pd_sub(cpos_[k], p);
  if (v.x < 0.0 || (v.x == 0.0 && (v.y < 0.0 || (v.y == 0.0 && cells_.nodes[k] <= u)))) return;
  const double tol2 = kOnLineMm * kOnLineMm * pd_dot(v, v);
  const Tangency tu = tangency(v, tp_, tn_, tol2);
  if (tu == kNotTangent) return;
  const Tangency tw = tangency(v, cprev_[k], cnext_[k], tol2);
  if (tw == kNotTangent) return;
  const std::uint32_t w = cells_.nodes[k];
  if ((tu == kNearlyTangent && m_.enters_obstacle(m_.node_vertex[u], v)) ||
      (tw == kNearlyTangent && m_.enters_obstacle(m_.node_vertex[w], {-v.x, -v.y})))
    return;
  for (const plan_detail::Shadow& s : shadows_) {
    if (s.hides(v, kShadowMarginMm)) return;  // cheaper than the blocker cache
  }
  const double l = pd_norm(v);
  const auto cached = [&](std::uint32_t e) {
    return e != kNoEdge && m_.may_block(p, v, kOnLineMm * l, e) &&
           m_.edge_blocks(p, cpos_[k], l, e);
  };
  for (int r = 0; r < kRecent; ++r) {
    if (cached(recent_[u][r]) || cached(recent_[w][r])) return;
  }
  std::uint32_t e = kNoEdge;
  if (!m_.segment_clear(p, cpos_[k], &e)) {
    remember(u, e), remember(w, e);
    add_shadow(rings_.ring_of[e]);
    return;
  }
  edges.emplace_back(u, w);
  edges.emplace_back(w, u);
  weights.push_back({l});
  weights.push_back({l});
}

}  // namespace

void RoutePlanner::Impl::build_graph() {
  for (std::uint32_t i = 0; i < pts.size(); ++i) {
    const Vec2 e_in = pd_sub(pts[i], pts[prev[i]]), e_out = pd_sub(pts[next[i]], pts[i]);
    const double l = pd_norm(e_in) * pd_norm(e_out);
    if (l > 0.0 && pd_cross(e_in, e_out) < -1e-9 * l) node_vertex.push_back(i);
  }
  EdgeFinder<Impl> finder(*this);
  finder.run();
  edge_count = finder.edges.size() / 2;
  graph = plan_detail::Graph(boost::edges_are_unsorted_multi_pass, finder.edges.begin(),
                             finder.edges.end(), finder.weights.begin(),
                             static_cast<std::uint32_t>(node_vertex.size()));
}

}  // namespace agv::site
