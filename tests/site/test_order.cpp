// VDA 5050 order: a planned route encoded and decoded back, malformed orders refused with the
// field named, and routes planned through a decoded order's nodes. With AGV_ORDER_OUT set, the
// round-trip test also writes its order there (the schema check, test_order_schema.py).
#include <gtest/gtest.h>

#include <cmath>
#include <cstdlib>
#include <fstream>
#include <string>

#include "agv/site/planner.hpp"
#include "agv/vda5050/order.hpp"
#include "test_planner_util.hpp"

namespace agv {
namespace {

vda5050::Order header() {
  vda5050::Order h;
  h.header_id = 7, h.timestamp = "2026-01-02T03:04:05.000Z", h.manufacturer = "agvloc";
  h.serial_number = "agv-1", h.order_id = "ord-1";
  return h;
}

site::Site yard() {
  site::Site s;
  s.outline = site::test::rect(0, 0, 20000, 10000);
  s.obstacles.push_back(site::test::rack("r1", 9000, 2000, 11000, 8000));
  // With the walls, "pen" and "gate" close off the north-east corner.
  s.obstacles.push_back(site::test::rack("pen", 16000, 6000, 20000, 6500));
  s.obstacles.push_back(site::test::rack("gate", 16000, 6500, 16500, 10000));
  return s;
}

TEST(Order, RoundTrip) {
  const std::vector<Vec2> w{{1000, 2000}, {8500, 1500}, {11500, 1500}, {15000, 4000}};
  const vda5050::Order o = vda5050::order_from_waypoints(w, "hall-1", header());
  const std::string text = vda5050::encode_order(o);
  if (const char* path = std::getenv("AGV_ORDER_OUT")) std::ofstream(path) << text;
  vda5050::Order back;
  std::string error;
  ASSERT_TRUE(vda5050::parse_order(text, &back, &error)) << error;
  EXPECT_EQ(back.order_id, "ord-1");
  EXPECT_EQ(back.header_id, 7u);
  ASSERT_EQ(back.nodes.size(), 4u);
  ASSERT_EQ(back.edges.size(), 3u);
  EXPECT_EQ(back.nodes[1].sequence_id, 2u);
  EXPECT_EQ(back.edges[1].sequence_id, 3u);
  EXPECT_NEAR(back.nodes[1].x_m, 8.5, 1e-12);  // metres
  EXPECT_EQ(back.nodes[3].map_id, "hall-1");
  EXPECT_NEAR(back.nodes[0].theta_rad, std::atan2(-500, 7500), 1e-12);
  std::vector<Vec2> pts;
  ASSERT_TRUE(vda5050::order_waypoints_mm(back, &pts, &error));
  for (std::size_t i = 0; i < w.size(); ++i) EXPECT_NEAR(pts[i].x, w[i].x, 1e-9);
  EXPECT_EQ(vda5050::encode_order(back), text);
}

std::string mutate(const std::string& text, const std::string& from, const std::string& to) {
  std::string t = text;
  const auto at = t.find(from);
  EXPECT_NE(at, std::string::npos) << from;
  if (at != std::string::npos) t.replace(at, from.size(), to);
  return t;
}

TEST(Order, MalformedOrdersAreRefusedNamingTheField) {
  const std::string good = vda5050::encode_order(
      vda5050::order_from_waypoints({{0, 0}, {1000, 0}, {1000, 1000}}, "m", header()));
  const std::pair<std::string, std::string> cases[] = {
      {mutate(good, "\"x\": 1.0", "\"x\": \"1\""), "nodes[1].nodePosition.x"},
      {mutate(good, "\"x\": 1.0", "\"x\": 1e999"), "not JSON"},
      {mutate(good, "\"sequenceId\": 2", "\"sequenceId\": 4"), "nodes[1].sequenceId"},
      {mutate(good, "\"sequenceId\": 1", "\"sequenceId\": 2"), "edges[0].sequenceId"},
      {mutate(good, "\"endNodeId\": \"ord-1_n1\"", "\"endNodeId\": \"x\""), "edges[0].endNodeId"},
      {mutate(good, "\"headerId\": 7", "\"headerId\": -7"), "headerId"},
      {mutate(good, "\"orderId\": \"ord-1\"", "\"orderId\": 5"), "orderId"},
      {mutate(good, "\"released\": true", "\"released\": 1"), "edges[0].released"},
      {mutate(good, "\"actions\": []", "\"actions\": [{}]"), "edges[0].actions"},
      {"[1, 2]", "not an object"},
      {"{", "not JSON"},
      {std::string(30, '[') + std::string(30, ']'), "nested"},
      {std::string(vda5050::kOrderMaxBytes + 1, ' '), "larger"},
  };
  for (const auto& [text, field] : cases) {
    vda5050::Order o;
    std::string error;
    EXPECT_FALSE(vda5050::parse_order(text, &o, &error)) << field;
    EXPECT_NE(error.find(field), std::string::npos) << error;
  }
  const std::string no_edges =
      R"({"headerId":1,"timestamp":"t","version":"2.1.0","manufacturer":"m",
    "serialNumber":"s","orderId":"o","orderUpdateId":0,"nodes":[],"edges":[]})";
  vda5050::Order o;
  std::string error;
  EXPECT_FALSE(vda5050::parse_order(no_edges, &o, &error));
  EXPECT_NE(error.find("nodes"), std::string::npos) << error;
}

TEST(Order, RouteThroughTheNodes) {
  const site::Site s = yard();
  site::RoutePlanner p;
  std::string error;
  ASSERT_TRUE(site::RoutePlanner::build(s, {}, &p, &error)) << error;
  vda5050::Order o =
      vda5050::order_from_waypoints({{2000, 5000}, {15000, 5000}, {15000, 2000}}, "m", header());
  const site::Route r = site::route_from_order(p, o);
  ASSERT_EQ(r.status, site::PlanStatus::kOk) << r.error;
  EXPECT_GT(r.length_mm, 13000.0 + 3000.0);
  EXPECT_NEAR(site::test::polyline_length(r.waypoints_mm), r.length_mm, 1e-6 * r.length_mm);
  // The last node in the closed-off corner: unreachable.
  o = vda5050::order_from_waypoints({{2000, 5000}, {15000, 5000}, {18000, 8500}}, "m", header());
  site::Route bad = site::route_from_order(p, o);
  EXPECT_EQ(bad.status, site::PlanStatus::kNoRoute);
  EXPECT_NE(bad.error.find("ord-1_n2"), std::string::npos) << bad.error;
  o = vda5050::order_from_waypoints({{2000, 5000}, {10000, 5000}}, "m", header());
  bad = site::route_from_order(p, o);
  EXPECT_EQ(bad.status, site::PlanStatus::kGoalBlocked);
  EXPECT_NE(bad.error.find("ord-1_n1"), std::string::npos) << bad.error;
  EXPECT_NE(bad.error.find("r1"), std::string::npos) << bad.error;
}

}  // namespace
}  // namespace agv
