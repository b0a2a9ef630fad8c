// Route queries: the start and goal are joined to the graph nodes they see (tangent lines
// only), then Dijkstra's algorithm runs from all nodes the start sees at once, seeded with their
// distances, and stops once no unexplored node can improve the best arrival at the goal. The
// built graph is never modified, so queries are const and may run concurrently.
#include <algorithm>
#include <boost/range/iterator_range.hpp>
#include <cmath>
#include <cstdio>
#include <limits>
#include <vector>

#include "planner_internal.hpp"

namespace agv::site {

const char* to_string(PlanStatus s) {
  switch (s) {
    case PlanStatus::kOk:
      return "ok";
    case PlanStatus::kStartBlocked:
      return "start_blocked";
    case PlanStatus::kGoalBlocked:
      return "goal_blocked";
    case PlanStatus::kNoRoute:
      return "no_route";
    case PlanStatus::kInvalidInput:
      return "invalid_input";
  }
  return "unknown";
}

namespace {

constexpr double kInf = std::numeric_limits<double>::infinity();

// Distance from p to a polygon's area: 0 inside.
double distance_to_polygon_mm(const Polygon& poly, Vec2 p) {
  const std::vector<Vec2>& v = poly.vertices_mm;
  bool inside = false;
  double best = kInf;
  for (std::size_t i = 0; i < v.size(); ++i) {
    const Vec2 c = v[i], d = v[(i + 1) % v.size()], cd = pd_sub(d, c);
    const double l2 = pd_dot(cd, cd);
    const double t = l2 > 0.0 ? std::clamp(pd_dot(pd_sub(p, c), cd) / l2, 0.0, 1.0) : 0.0;
    best = std::min(best, pd_norm(pd_sub(p, {c.x + t * cd.x, c.y + t * cd.y})));
    if ((c.y > p.y) != (d.y > p.y) && p.x < c.x + (p.y - c.y) * cd.x / cd.y) inside = !inside;
  }
  return inside ? 0.0 : best;
}

double distance_to_boundary_mm(const Polygon& poly, Vec2 p, bool* inside) {
  const double d_area = distance_to_polygon_mm(poly, p);
  *inside = d_area == 0.0;
  if (!*inside) return d_area;
  double best = kInf;
  const std::vector<Vec2>& v = poly.vertices_mm;
  for (std::size_t i = 0; i < v.size(); ++i) {
    const Vec2 c = v[i], cd = pd_sub(v[(i + 1) % v.size()], c);
    const double l2 = pd_dot(cd, cd);
    const double t = l2 > 0.0 ? std::clamp(pd_dot(pd_sub(p, c), cd) / l2, 0.0, 1.0) : 0.0;
    best = std::min(best, pd_norm(pd_sub(p, {c.x + t * cd.x, c.y + t * cd.y})));
  }
  return best;
}

std::string format_point(Vec2 p) {
  char buf[64];
  std::snprintf(buf, sizeof buf, "(%.0f, %.0f) mm", p.x, p.y);
  return buf;
}

// A search entry: f = g + |node - goal|. A start entry's segment from the start is not yet
// tested: it is tested only when the entry comes first, and most never do.
struct Entry {
  double f, g;
  std::uint32_t node;
  bool from_start;
  bool operator<(const Entry& o) const { return f > o.f; }  // min-heap
};

}  // namespace

std::string RoutePlanner::Impl::blocked_reason(Vec2 p) const {
  const double r = params.vehicle_radius_mm + params.clearance_mm;
  // The inflation's corners reach r / cos(step / 2): name an obstacle found within that.
  const double reach = r / std::cos(0.5 * params.arc_step_rad) + kOnLineMm;
  double best = kInf;
  const Obstacle* hit = nullptr;
  for (const Obstacle& o : obstacles) {
    const double d = distance_to_polygon_mm(o.outline, p);
    if (d < best) best = d, hit = &o;
  }
  char buf[96];
  if (hit && best <= reach) {
    std::snprintf(buf, sizeof buf, " is %.0f mm from obstacle ", best);
    return format_point(p) + buf + (hit->id.empty() ? std::string("(no id)") : hit->id) +
           " (inside, or closer than radius + clearance " + std::to_string(static_cast<int>(r)) +
           " mm)";
  }
  bool inside = false;
  const double dw = distance_to_boundary_mm(outline, p, &inside);
  if (!inside) return format_point(p) + " is outside the site's outline";
  std::snprintf(buf, sizeof buf, " is %.0f mm from the outline (walls), closer than %.0f mm", dw,
                r);
  return format_point(p) + buf;
}

Route RoutePlanner::plan(Vec2 start_mm, Vec2 goal_mm) const {
  Route route;
  if (!std::isfinite(start_mm.x) || !std::isfinite(start_mm.y) || !std::isfinite(goal_mm.x) ||
      !std::isfinite(goal_mm.y) || !impl_) {
    route.status = PlanStatus::kInvalidInput;
    route.error = impl_ ? "start or goal is not finite" : "planner not built";
    return route;
  }
  const Impl& m = *impl_;
  if (!m.point_free(start_mm)) {
    route.status = PlanStatus::kStartBlocked;
    route.error = "start " + m.blocked_reason(start_mm);
    return route;
  }
  if (!m.point_free(goal_mm)) {
    route.status = PlanStatus::kGoalBlocked;
    route.error = "goal " + m.blocked_reason(goal_mm);
    return route;
  }
  route.status = PlanStatus::kOk;
  if (pd_norm(pd_sub(goal_mm, start_mm)) <= kOnLineMm) {
    route.waypoints_mm = {start_mm};
    return route;
  }
  if (m.segment_clear(start_mm, goal_mm)) {
    route.waypoints_mm = {start_mm, goal_mm};
    route.length_mm = pd_norm(pd_sub(goal_mm, start_mm));
    return route;
  }
  const std::size_t n = m.node_vertex.size();
  std::vector<double> dist(n, kInf);
  std::vector<std::uint32_t> pred(n);
  std::vector<Entry> heap;
  auto h = [&](std::uint32_t k) { return pd_norm(pd_sub(goal_mm, m.pts[m.node_vertex[k]])); };
  auto useful = [&](std::uint32_t i, Vec2 v) {
    return m.tangent_at(i, v) && !m.enters_obstacle(i, v);
  };
  for (std::uint32_t k = 0; k < n; ++k) {
    const std::uint32_t i = m.node_vertex[k];
    const Vec2 v = pd_sub(start_mm, m.pts[i]);
    if (!useful(i, v)) continue;
    const double g = pd_norm(v);
    heap.push_back({g + h(k), g, k, true});
  }
  std::make_heap(heap.begin(), heap.end());
  double best = kInf;
  std::uint32_t best_node = 0;
  while (!heap.empty() && heap.front().f < best) {
    std::pop_heap(heap.begin(), heap.end());
    const Entry top = heap.back();
    heap.pop_back();
    const std::uint32_t k = top.node, i = m.node_vertex[k];
    const Vec2 q = m.pts[i];
    if (top.from_start) {
      if (top.g >= dist[k] || !m.segment_clear(start_mm, q)) continue;
      dist[k] = top.g, pred[k] = k;
    } else if (top.g != dist[k]) {
      continue;  // superseded by a shorter arrival
    }
    // The arrival through k costs exactly top.f, the least key left: if k sees the goal, done.
    const Vec2 to_goal = pd_sub(goal_mm, q);
    if (useful(i, to_goal) && m.segment_clear(q, goal_mm)) {
      best = top.g + pd_norm(to_goal), best_node = k;
      break;
    }
    for (const auto e : boost::make_iterator_range(boost::out_edges(k, m.graph))) {
      const std::uint32_t j = static_cast<std::uint32_t>(boost::target(e, m.graph));
      const double g = top.g + m.graph[e].w;
      if (g < dist[j]) {
        dist[j] = g, pred[j] = k;
        heap.push_back({g + h(j), g, j, false});
        std::push_heap(heap.begin(), heap.end());
      }
    }
  }
  if (!std::isfinite(best)) {
    route.status = PlanStatus::kNoRoute;
    route.error = "no route from " + format_point(start_mm) + " to " + format_point(goal_mm) +
                  ": they lie in separate parts of the free space";
    return route;
  }
  std::vector<Vec2> back{goal_mm};
  for (std::uint32_t k = best_node;; k = pred[k]) {
    back.push_back(m.pts[m.node_vertex[k]]);
    if (pred[k] == k) break;
  }
  back.push_back(start_mm);
  route.waypoints_mm.assign(back.rbegin(), back.rend());
  route.length_mm = best;
  return route;
}

}  // namespace agv::site
