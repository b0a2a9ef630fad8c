// VDA 5050 orders as the tracker's routes (order_intake.hpp).
#include "agv/overhead/order_intake.hpp"

#include <algorithm>
#include <cstddef>
#include <utility>

#include "agv/overhead/route_prior.hpp"
#include "agv/vda5050/order.hpp"

namespace agv::overhead {

namespace {

// The topic's levels; false unless exactly five.
bool split_topic(std::string_view topic, std::string_view (&level)[5]) {
  std::size_t n = 0, from = 0;
  for (std::size_t i = 0; i <= topic.size(); ++i) {
    if (i < topic.size() && topic[i] != '/') continue;
    if (n == 5) return false;
    level[n++] = topic.substr(from, i - from);
    from = i + 1;
  }
  return n == 5;
}

// "v2" for "2.1.0".
std::string major_level(const std::string& version) {
  std::string v = "v";
  v.append(version, 0, version.find('.'));
  return v;
}

OrderReason fail(OrderReason r, std::string* detail, std::string what) {
  if (detail != nullptr) *detail = std::move(what);
  return r;
}

// The order's base: its released nodes, which must come before any unreleased one.
OrderReason base_of(const vda5050::Order& o, std::size_t* n, std::string* detail) {
  *n = 0;
  while (*n < o.nodes.size() && o.nodes[*n].released) ++*n;
  for (std::size_t i = *n; i < o.nodes.size(); ++i) {
    if (o.nodes[i].released)
      return fail(OrderReason::kReleasedAfterHorizon, detail,
                  "nodes[" + std::to_string(i) + "]: released after an unreleased node");
  }
  if (*n == 0) return fail(OrderReason::kNoPosition, detail, "no released node");
  for (std::size_t i = 0; i < *n; ++i) {
    if (!o.nodes[i].has_position)
      return fail(OrderReason::kNoPosition, detail,
                  "nodes[" + std::to_string(i) + "] (" + o.nodes[i].node_id + "): no nodePosition");
  }
  return OrderReason::kNone;
}

}  // namespace

const char* order_reason_name(OrderReason r) {
  switch (r) {
    case OrderReason::kNone:
      return "none";
    case OrderReason::kDuplicate:
      return "duplicate";
    case OrderReason::kBadTopic:
      return "bad_topic";
    case OrderReason::kUnknownVehicle:
      return "unknown_vehicle";
    case OrderReason::kMalformed:
      return "malformed";
    case OrderReason::kTopicMismatch:
      return "topic_mismatch";
    case OrderReason::kNoPosition:
      return "no_position";
    case OrderReason::kReleasedAfterHorizon:
      return "released_after_horizon";
    case OrderReason::kStaleUpdate:
      return "stale_update";
    case OrderReason::kNotStitched:
      return "not_stitched";
  }
  return "unknown";
}

OrderIntake::OrderIntake(std::vector<std::string> fleet_ids, std::string interface_name)
    : ids_(std::move(fleet_ids)), interface_(std::move(interface_name)), cur_(ids_.size()) {}

void OrderIntake::forget(std::size_t agv) {
  if (agv < cur_.size()) cur_[agv] = Current{};
}

OrderReason OrderIntake::take(std::string_view topic, std::string_view payload, OrderRoute* out,
                              std::string* detail) {
  std::string_view level[5];
  if (!split_topic(topic, level) || level[0] != interface_ || level[4] != "order")
    return fail(OrderReason::kBadTopic, detail, "not " + interface_ + "/vN/MANUFACTURER/ID/order");
  const auto it = std::find(ids_.begin(), ids_.end(), level[3]);
  if (it == ids_.end())
    return fail(OrderReason::kUnknownVehicle, detail, "no fleet vehicle " + std::string(level[3]));
  const std::size_t agv = static_cast<std::size_t>(it - ids_.begin());
  vda5050::Order o;
  std::string why;
  if (!vda5050::parse_order(payload, &o, &why)) return fail(OrderReason::kMalformed, detail, why);
  if (o.serial_number != level[3] || o.manufacturer != level[2] ||
      major_level(o.version) != level[1])
    return fail(OrderReason::kTopicMismatch, detail,
                "serialNumber, manufacturer or version differ from the topic's");
  std::size_t base = 0;
  if (const OrderReason r = base_of(o, &base, detail); r != OrderReason::kNone) return r;
  Current& cur = cur_[agv];
  Current next;
  if (!cur.order_id.empty() && o.order_id == cur.order_id) {
    if (o.order_update_id == cur.update_id)
      return fail(OrderReason::kDuplicate, detail, "update " + std::to_string(cur.update_id));
    if (o.order_update_id < cur.update_id)
      return fail(OrderReason::kStaleUpdate, detail,
                  "orderUpdateId " + std::to_string(o.order_update_id) + " after " +
                      std::to_string(cur.update_id));
    if (cur.node_ids.back() != o.nodes[0].node_id ||
        cur.sequence_ids.back() != o.nodes[0].sequence_id)
      return fail(OrderReason::kNotStitched, detail,
                  "the update begins at " + o.nodes[0].node_id + ", not at the base's last node " +
                      cur.node_ids.back());
    next = cur;
    next.node_ids.pop_back(), next.sequence_ids.pop_back(), next.pts_mm.pop_back();
  }
  next.order_id = o.order_id;
  next.update_id = o.order_update_id;
  for (std::size_t i = 0; i < base; ++i) {
    next.node_ids.push_back(o.nodes[i].node_id);
    next.sequence_ids.push_back(o.nodes[i].sequence_id);
    next.pts_mm.push_back({o.nodes[i].x_m * 1e3, o.nodes[i].y_m * 1e3});
  }
  // Stitched updates add to the route without end; the passed part is of no use to the prior.
  if (next.pts_mm.size() > kRouteMaxPoints) {
    const auto drop = static_cast<std::ptrdiff_t>(next.pts_mm.size() - kRouteMaxPoints);
    next.node_ids.erase(next.node_ids.begin(), next.node_ids.begin() + drop);
    next.sequence_ids.erase(next.sequence_ids.begin(), next.sequence_ids.begin() + drop);
    next.pts_mm.erase(next.pts_mm.begin(), next.pts_mm.begin() + drop);
  }
  cur = std::move(next);
  out->agv = agv;
  out->order_id = cur.order_id;
  out->order_update_id = cur.update_id;
  out->waypoints_mm = cur.pts_mm;
  return OrderReason::kNone;
}

}  // namespace agv::overhead
