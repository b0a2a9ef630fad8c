// The fleet manager's orders as routes (algo/src/overhead/order_intake.cpp): the base of an order
// for a fleet vehicle becomes its route, stitched updates extend it, and every refusal (topic,
// vehicle, payload, stale or unstitched update) is named and leaves the route as it was.
#include <gtest/gtest.h>

#include <string>
#include <vector>

#include "agv/overhead/order_intake.hpp"
#include "agv/overhead/route_prior.hpp"
#include "agv/vda5050/order.hpp"

namespace agv::overhead {
namespace {

const std::vector<std::string> kFleet = {"agv-1", "agv-2", "agv-3"};
const char* const kTopic2 = "uagv/v2/acme/agv-2/order";

// Order `id` update `update` for `serial` through waypoints (mm) whose node and sequence ids
// begin at `first` (node ids id_n<first + i>, sequence ids 2 (first + i)).
vda5050::Order order(const std::string& serial, const std::string& id, std::uint32_t update,
                     const std::vector<Vec2>& w_mm, std::uint32_t first = 0) {
  vda5050::Order h;
  h.timestamp = "2026-12-03T10:00:00.000Z", h.manufacturer = "acme", h.serial_number = serial;
  h.order_id = id, h.order_update_id = update;
  vda5050::Order o = vda5050::order_from_waypoints(w_mm, "hall", h);
  for (std::size_t i = 0; i < o.nodes.size(); ++i) {
    o.nodes[i].node_id = id + "_n" + std::to_string(first + i);
    o.nodes[i].sequence_id = static_cast<std::uint32_t>(2 * (first + i));
    if (i + 1 < o.nodes.size()) {
      o.edges[i].sequence_id = static_cast<std::uint32_t>(2 * (first + i) + 1);
      o.edges[i].start_node_id = id + "_n" + std::to_string(first + i);
      o.edges[i].end_node_id = id + "_n" + std::to_string(first + i + 1);
    }
  }
  return o;
}

OrderReason take(OrderIntake* in, const vda5050::Order& o, OrderRoute* r,
                 const std::string& topic = kTopic2) {
  std::string why;
  return in->take(topic, vda5050::encode_order(o), r, &why);
}

TEST(OrderIntake, TheBaseOfAFleetVehiclesOrderIsItsRoute) {
  OrderIntake in(kFleet, "uagv");
  OrderRoute r;
  ASSERT_EQ(take(&in, order("agv-2", "o1", 0, {{1000, 0}, {5000, 0}, {5000, 3000}}), &r),
            OrderReason::kNone);
  EXPECT_EQ(r.agv, 1u);
  EXPECT_EQ(r.order_id, "o1");
  ASSERT_EQ(r.waypoints_mm.size(), 3u);
  EXPECT_NEAR(r.waypoints_mm[2].x, 5000.0, 1e-9);
  EXPECT_NEAR(r.waypoints_mm[2].y, 3000.0, 1e-9);
}

TEST(OrderIntake, TheHorizonIsNotPartOfTheRoute) {
  OrderIntake in(kFleet, "uagv");
  vda5050::Order o = order("agv-2", "o1", 0, {{0, 0}, {1000, 0}, {2000, 0}, {3000, 0}});
  o.nodes[2].released = o.nodes[3].released = false;
  o.edges[1].released = o.edges[2].released = false;
  OrderRoute r;
  ASSERT_EQ(take(&in, o, &r), OrderReason::kNone);
  ASSERT_EQ(r.waypoints_mm.size(), 2u);
  EXPECT_NEAR(r.waypoints_mm[1].x, 1000.0, 1e-9);
  o.nodes[3].released = true;
  o.order_id = "o2";
  EXPECT_EQ(take(&in, o, &r), OrderReason::kReleasedAfterHorizon);
}

TEST(OrderIntake, AStitchedUpdateExtendsTheRoute) {
  OrderIntake in(kFleet, "uagv");
  OrderRoute r;
  ASSERT_EQ(take(&in, order("agv-2", "o1", 0, {{0, 0}, {1000, 0}, {2000, 0}}), &r),
            OrderReason::kNone);
  // Begins at the base's last node (o1_n2, sequence 4).
  ASSERT_EQ(take(&in, order("agv-2", "o1", 1, {{2000, 0}, {2000, 1000}}, 2), &r),
            OrderReason::kNone);
  ASSERT_EQ(r.waypoints_mm.size(), 4u);
  EXPECT_NEAR(r.waypoints_mm[3].y, 1000.0, 1e-9);
  EXPECT_EQ(r.order_update_id, 1u);
  EXPECT_EQ(take(&in, order("agv-2", "o1", 1, {{2000, 0}, {2000, 1000}}, 2), &r),
            OrderReason::kDuplicate);
  EXPECT_EQ(take(&in, order("agv-2", "o1", 0, {{0, 0}, {9000, 0}}), &r), OrderReason::kStaleUpdate);
  // Not at the base's last node (o1_n3): refused, and the route stays as it was.
  EXPECT_EQ(take(&in, order("agv-2", "o1", 2, {{2000, 0}, {2000, 5000}}, 2), &r),
            OrderReason::kNotStitched);
  ASSERT_EQ(take(&in, order("agv-2", "o1", 2, {{2000, 1000}, {0, 1000}}, 3), &r),
            OrderReason::kNone);
  ASSERT_EQ(r.waypoints_mm.size(), 5u);
  EXPECT_NEAR(r.waypoints_mm[4].x, 0.0, 1e-9);
  // Another order replaces the route.
  ASSERT_EQ(take(&in, order("agv-2", "o2", 0, {{7000, 7000}, {8000, 7000}}), &r),
            OrderReason::kNone);
  EXPECT_EQ(r.waypoints_mm.size(), 2u);
}

TEST(OrderIntake, RefusalsAreNamed) {
  OrderIntake in(kFleet, "uagv");
  OrderRoute r;
  r.agv = 99;
  const vda5050::Order o = order("agv-2", "o1", 0, {{0, 0}, {1000, 0}});
  std::string why;
  EXPECT_EQ(take(&in, o, &r, "uagv/v2/acme/agv-2/state"), OrderReason::kBadTopic);
  EXPECT_EQ(take(&in, o, &r, "uagv/v2/acme/agv-2/order/x"), OrderReason::kBadTopic);
  EXPECT_EQ(take(&in, o, &r, "other/v2/acme/agv-2/order"), OrderReason::kBadTopic);
  EXPECT_EQ(take(&in, o, &r, "uagv/v2/acme/agv-9/order"), OrderReason::kUnknownVehicle);
  EXPECT_EQ(take(&in, o, &r, "uagv/v2/acme/agv-1/order"), OrderReason::kTopicMismatch);
  EXPECT_EQ(take(&in, o, &r, "uagv/v2/other/agv-2/order"), OrderReason::kTopicMismatch);
  EXPECT_EQ(take(&in, o, &r, "uagv/v3/acme/agv-2/order"), OrderReason::kTopicMismatch);
  EXPECT_EQ(in.take(kTopic2, "{\"orderId\":", &r, &why), OrderReason::kMalformed);
  EXPECT_FALSE(why.empty());
  vda5050::Order blind = o;
  blind.nodes[1].has_position = false;
  EXPECT_EQ(take(&in, blind, &r), OrderReason::kNoPosition);
  EXPECT_EQ(r.agv, 99u) << "a refusal changed the output";
  EXPECT_STREQ(order_reason_name(OrderReason::kNotStitched), "not_stitched");
  for (int i = 0; i < kOrderReasonCount; ++i)
    EXPECT_STRNE(order_reason_name(static_cast<OrderReason>(i)), "unknown");
}

TEST(OrderIntake, EndlessUpdatesKeepTheNewestPartOfTheRoute) {
  OrderIntake in(kFleet, "uagv");
  OrderRoute r;
  ASSERT_EQ(take(&in, order("agv-2", "o1", 0, {{0, 0}, {100, 0}}), &r), OrderReason::kNone);
  for (std::uint32_t u = 1; u < 1200; ++u) {
    const double x = 100.0 * u;
    ASSERT_EQ(take(&in, order("agv-2", "o1", u, {{x, 0}, {x + 100, 0}}, u), &r), OrderReason::kNone)
        << u;
  }
  ASSERT_EQ(r.waypoints_mm.size(), kRouteMaxPoints);
  EXPECT_NEAR(r.waypoints_mm.back().x, 120000.0, 1e-9);
  RoutePath path;
  std::string why;
  EXPECT_TRUE(path.assign(r.waypoints_mm, &why)) << why;
  in.forget(1);
  EXPECT_EQ(take(&in, order("agv-2", "o1", 0, {{0, 0}, {100, 0}}), &r), OrderReason::kNone);
}

}  // namespace
}  // namespace agv::overhead
