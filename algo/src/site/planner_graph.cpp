// The planner's predicates (point and segment in the free space, exact up to kOnLineMm, robust
// to segments that slide along edges or pass through vertices) over a uniform grid of the free
// space's edges, and the planner's construction (the graph's edges: planner_graph_edges.cpp).
#include <algorithm>
#include <cmath>
#include <limits>
#include <utility>
#include <vector>

#include "planner_internal.hpp"

namespace agv::site {

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
