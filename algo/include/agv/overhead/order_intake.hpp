// The fleet manager's VDA 5050 orders as the tracker's routes (route_prior.hpp): one message on
// <interface>/<vN>/<manufacturer>/<serialNumber>/order read strictly (vda5050::parse_order), its
// serial number one of the fleet's vehicles, its base (released nodes, each with a position) the
// vehicle's route. An update of the current order (same orderId, higher orderUpdateId) must
// begin at the last base node of the route it extends, as VDA 5050 2.x stitches updates; the
// route is then the old one up to that node and the update's base after it. Anyone with access to
// the broker can write there: every refusal is named and changes nothing. Pure: text in.
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>
#include <string_view>
#include <vector>

#include "agv/common/geometry.hpp"

namespace agv::overhead {

enum class OrderReason : std::uint8_t {
  kNone,                  // accepted: a route
  kDuplicate,             // the current order's update id again: nothing to do, not an error
  kBadTopic,              // not <interface>/vN/<manufacturer>/<serial>/order
  kUnknownVehicle,        // the topic's serial number is no fleet vehicle's id
  kMalformed,             // refused by the strict reading (vda5050::parse_order)
  kTopicMismatch,         // the payload's serialNumber, manufacturer or major version differ
  kNoPosition,            // a released node without nodePosition
  kReleasedAfterHorizon,  // a released node after an unreleased one
  kStaleUpdate,           // the current order with a lower orderUpdateId
  kNotStitched,           // an update that does not begin at the route's last base node
};

// "bad_topic", "unknown_vehicle", ... (a metrics label); "none" for kNone.
const char* order_reason_name(OrderReason r);
inline constexpr int kOrderReasonCount = static_cast<int>(OrderReason::kNotStitched) + 1;

struct OrderRoute {
  std::size_t agv = 0;  // index in the fleet
  std::string order_id;
  std::uint32_t order_update_id = 0;
  // The base in site mm. One point: the vehicle is to stay at its node (no route to follow).
  std::vector<Vec2> waypoints_mm;
};

class OrderIntake {
 public:
  // fleet_ids: the site's vehicles in fleet order (their VDA 5050 serial numbers).
  OrderIntake(std::vector<std::string> fleet_ids, std::string interface_name);
  // One message. kNone: *out is the vehicle's route now. Otherwise *out is unchanged and
  // *detail (may be null) says what was refused.
  OrderReason take(std::string_view topic, std::string_view payload, OrderRoute* out,
                   std::string* detail);
  // Forget vehicle agv's order (its route was cleared): the next order of any id starts afresh.
  void forget(std::size_t agv);

 private:
  struct Current {
    std::string order_id;
    std::uint32_t update_id = 0;
    std::vector<std::string> node_ids;
    std::vector<std::uint32_t> sequence_ids;
    std::vector<Vec2> pts_mm;
  };
  std::vector<std::string> ids_;
  std::string interface_;
  std::vector<Current> cur_;
};

}  // namespace agv::overhead
