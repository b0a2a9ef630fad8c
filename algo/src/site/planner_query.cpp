// Route queries: the start and goal are joined to the graph nodes they see (tangent lines
// only), then Dijkstra's algorithm runs from all nodes the start sees at once, seeded with their
// distances, and stops once no unexplored node can improve the best arrival at the goal. The
// built graph is never modified, so queries are const and may run concurrently.
#include <algorithm>
#include <boost/graph/dijkstra_shortest_paths.hpp>
#include <cmath>
#include <cstdio>
#include <limits>
#include <vector>

#include "planner_internal.hpp"

namespace agv::site {

using plan_detail::kOnLineMm;
using plan_detail::pd_cross;
using plan_detail::pd_dot;
using plan_detail::pd_norm;
using plan_detail::pd_sub;

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

struct StopSearch {};

// Stops Dijkstra's algorithm once the node it settles is no closer than the best arrival.
struct ArrivalVisitor : boost::default_dijkstra_visitor {
  const std::vector<double>* dist;
  const std::vector<double>* to_goal;
  double* best;
  std::uint32_t* best_node;
  template <class G>
  void examine_vertex(std::uint32_t u, const G&) {
    const double d = (*dist)[u];
    if (d >= *best) throw StopSearch{};
    if (d + (*to_goal)[u] < *best) *best = d + (*to_goal)[u], *best_node = u;
  }
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
  std::vector<double> dist(n, kInf), to_goal(n, kInf);
  std::vector<std::uint32_t> pred(n), sources;
  for (std::uint32_t k = 0; k < n; ++k) {
    pred[k] = k;
    const std::uint32_t i = m.node_vertex[k];
    const Vec2 q = m.pts[i];
    for (int end = 0; end < 2; ++end) {
      const Vec2 p = end == 0 ? start_mm : goal_mm;
      const Vec2 v = pd_sub(p, q);
      if (!m.tangent_at(i, v) || m.enters_obstacle(i, v) || !m.segment_clear(p, q)) continue;
      (end == 0 ? dist : to_goal)[k] = pd_norm(v);
      if (end == 0) sources.push_back(k);
    }
  }
  double best = kInf;
  std::uint32_t best_node = 0;
  std::vector<boost::default_color_type> color(n, boost::white_color);
  ArrivalVisitor vis;
  vis.dist = &dist, vis.to_goal = &to_goal, vis.best = &best, vis.best_node = &best_node;
  try {
    const auto index = boost::get(boost::vertex_index, m.graph);
    boost::dijkstra_shortest_paths_no_init(m.graph, sources.begin(), sources.end(),
                                           boost::make_iterator_property_map(pred.data(), index),
                                           boost::make_iterator_property_map(dist.data(), index),
                                           boost::get(&plan_detail::EdgeWeight::w, m.graph), index,
                                           std::less<double>(), boost::closed_plus<double>(kInf),
                                           0.0, vis,
                                           boost::make_iterator_property_map(color.data(), index));
  } catch (const StopSearch&) {
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
