// Routes through the nodes of a VDA 5050 order, leg by leg.
#include <cmath>
#include <string>

#include "agv/site/planner.hpp"
#include "agv/vda5050/order.hpp"

namespace agv::site {

Route route_from_order(const RoutePlanner& planner, const vda5050::Order& order) {
  Route out;
  auto node_name = [&](std::size_t i) {
    return "node " + order.nodes[i].node_id + " (nodes[" + std::to_string(i) + "])";
  };
  if (order.nodes.empty()) {
    out.status = PlanStatus::kInvalidInput;
    out.error = "the order has no nodes";
    return out;
  }
  std::vector<Vec2> pts;
  for (std::size_t i = 0; i < order.nodes.size(); ++i) {
    const vda5050::OrderNode& n = order.nodes[i];
    if (!n.has_position || !std::isfinite(n.x_m) || !std::isfinite(n.y_m)) {
      out.status = PlanStatus::kInvalidInput;
      out.error = node_name(i) + ": no finite nodePosition";
      return out;
    }
    pts.push_back({n.x_m * 1e3, n.y_m * 1e3});
  }
  out.status = PlanStatus::kOk;
  out.waypoints_mm = {pts[0]};
  for (std::size_t i = 0; i + 1 < pts.size() || (pts.size() == 1 && i == 0); ++i) {
    const std::size_t j = std::min(i + 1, pts.size() - 1);
    const Route leg = planner.plan(pts[i], pts[j]);
    if (leg.status != PlanStatus::kOk) {
      out.status = leg.status;
      out.waypoints_mm.clear();
      out.length_mm = 0.0;
      if (leg.status == PlanStatus::kStartBlocked) {
        out.error = node_name(i) + " is blocked: " + leg.error;
      } else if (leg.status == PlanStatus::kGoalBlocked) {
        out.error = node_name(j) + " is blocked: " + leg.error;
      } else {
        out.error = node_name(j) + " cannot be reached from " + node_name(i) + ": " + leg.error;
      }
      return out;
    }
    out.waypoints_mm.insert(out.waypoints_mm.end(), leg.waypoints_mm.begin() + 1,
                            leg.waypoints_mm.end());
    out.length_mm += leg.length_mm;
    if (pts.size() == 1) break;
  }
  return out;
}

}  // namespace agv::site
