// VDA 5050 2.1.0 `order` messages for routes of the site planner: a route's waypoints encoded as
// released nodes (positions in metres and radians) joined by edges, and an order decoded back,
// strictly: bounded sizes, types, even node / odd edge sequence ids that alternate, edges that
// join their neighbouring nodes, finite positions. Pure: text in, text out.
#pragma once

#include <cstdint>
#include <string>
#include <string_view>
#include <vector>

#include "agv/common/geometry.hpp"

namespace agv::vda5050 {

struct OrderNode {
  std::string node_id;
  std::uint32_t sequence_id = 0;  // even
  bool released = true;
  bool has_position = false;
  double x_m = 0.0, y_m = 0.0;
  bool has_theta = false;
  double theta_rad = 0.0;
  std::string map_id;
};

struct OrderEdge {
  std::string edge_id;
  std::uint32_t sequence_id = 0;  // odd, between its nodes'
  bool released = true;
  std::string start_node_id, end_node_id;
};

struct Order {
  std::uint32_t header_id = 0;
  std::string timestamp;  // ISO 8601
  std::string version = "2.1.0";
  std::string manufacturer, serial_number;
  std::string order_id;
  std::uint32_t order_update_id = 0;
  std::vector<OrderNode> nodes;
  std::vector<OrderEdge> edges;
};

// Limits of the decoder (and of what the encoder is given).
inline constexpr std::size_t kOrderMaxBytes = 1 << 20;
inline constexpr std::size_t kOrderMaxNodes = 1000;
inline constexpr std::size_t kOrderMaxString = 256;

// An order through the waypoints (mm): node i at waypoint i, theta the heading of the segment
// leaving it (the last node: of the segment arriving). Node ids "<order_id>_n<i>", edge ids
// "<order_id>_e<i>". The identity and timestamp fields come from `header` (its nodes and edges
// are ignored).
Order order_from_waypoints(const std::vector<Vec2>& waypoints_mm, const std::string& map_id,
                           const Order& header);
std::string encode_order(const Order& order);
// False with *error naming the field ("nodes[3].nodePosition.x: not finite") on anything the
// strict reading refuses.
bool parse_order(std::string_view text, Order* out, std::string* error);
// The nodes' positions in mm (every node must have one).
bool order_waypoints_mm(const Order& order, std::vector<Vec2>* out, std::string* error);

}  // namespace agv::vda5050
