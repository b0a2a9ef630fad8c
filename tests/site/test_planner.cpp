// The route planner on hand-made sites: the straight case, detours, and each degenerate case
// (collinear vertices, touching racks, a corridor exactly the vehicle's width, a start on an
// inflated edge, start == goal, blocked ends, an enclosed goal).
#include <gtest/gtest.h>

#include <cmath>
#include <string>

#include "agv/site/planner.hpp"
#include "test_planner_util.hpp"

namespace agv::site {
namespace {

using test::min_clearance_mm;
using test::polyline_length;
using test::rack;

constexpr double kR = 500.0;  // radius 400 + clearance 100

Site room(double w = 20000, double h = 10000) {
  Site s;
  s.outline = test::rect(0, 0, w, h);
  return s;
}

RoutePlanner build(const Site& s, PlannerParams p = {}) {
  RoutePlanner planner;
  std::string error;
  EXPECT_TRUE(RoutePlanner::build(s, p, &planner, &error)) << error;
  return planner;
}

void expect_clear(const Site& s, const Route& r) {
  ASSERT_EQ(r.status, PlanStatus::kOk) << r.error;
  EXPECT_GE(min_clearance_mm(s, r.waypoints_mm, 5.0), kR - 1e-6);
  EXPECT_NEAR(polyline_length(r.waypoints_mm), r.length_mm, 1e-6 * (1.0 + r.length_mm));
}

TEST(Planner, StraightWhenVisible) {
  const Site s = room();
  const RoutePlanner p = build(s);
  const Route r = p.plan({1000, 1000}, {19000, 9000});
  expect_clear(s, r);
  EXPECT_EQ(r.waypoints_mm.size(), 2u);
  EXPECT_NEAR(r.length_mm, std::hypot(18000, 8000), 1e-9);
}

TEST(Planner, DetourAroundRackWrapsItsInflatedCorners) {
  Site s = room();
  s.obstacles.push_back(rack("r1", 9000, 2000, 11000, 8000));
  const RoutePlanner p = build(s);
  const Route r = p.plan({5000, 5000}, {15000, 5000});
  expect_clear(s, r);
  EXPECT_GT(r.waypoints_mm.size(), 2u);
  // Over the inflated top corners (8500, 8500) and (11500, 8500): about 2 x 4950 + 3000 mm.
  EXPECT_GT(r.length_mm, 12500.0);
  EXPECT_LT(r.length_mm, 13200.0);
  // The inflation lies outside the exact offset: every inflated vertex at least kR from the rack.
  for (const Polygon& poly : p.inflated()) {
    for (const Vec2& v : poly.vertices_mm) {
      EXPECT_GE(test::boundary_dist(s.obstacles[0].outline.vertices_mm, v), kR - 1e-9);
    }
  }
}

TEST(Planner, CollinearVerticesAndAlignedRacks) {
  Site s = room();
  Obstacle o = rack("c", 6000, 3000, 14000, 7000);
  o.outline.vertices_mm = {{6000, 3000},  {8000, 3000},  {10000, 3000}, {14000, 3000},
                           {14000, 7000}, {10000, 7000}, {6000, 7000}};
  s.obstacles.push_back(o);
  // Two more racks in line: the route slides along their common inflated edge.
  s.obstacles.push_back(rack("d", 15000, 1500, 16000, 3000));
  s.obstacles.push_back(rack("e", 4000, 1500, 5000, 3000));
  const RoutePlanner p = build(s);
  const Route r = p.plan({2000, 2000 + kR + 1000}, {18000, 3000 + kR});
  expect_clear(s, r);
  for (const Vec2& w : r.waypoints_mm) EXPECT_TRUE(p.point_free(w));
}

TEST(Planner, TouchingRacksMergeWithNoPassageBetween) {
  Site s = room(20000, 14000);
  s.obstacles.push_back(rack("a", 8000, 2000, 10000, 5000));
  s.obstacles.push_back(rack("b", 10000, 5000, 12000, 9000));  // touches a at a corner
  const RoutePlanner p = build(s);
  EXPECT_EQ(p.inflated().size(), 1u);
  const Route r = p.plan({9000, 7000}, {11000, 3000});
  expect_clear(s, r);
  EXPECT_GT(r.length_mm, 5000.0);
}

TEST(Planner, CorridorExactlyTheVehicleWidthIsNotUsed) {
  // Racks 2 * kR apart: the inflated racks touch along the corridor's axis, leaving no width.
  Site s = room();
  s.obstacles.push_back(rack("lo", 9000, 0, 11000, 5000 - kR));
  s.obstacles.push_back(rack("hi", 9000, 5000 + kR, 11000, 10000));
  const RoutePlanner p = build(s);
  const Route r = p.plan({5000, 5000}, {15000, 5000});
  EXPECT_NE(r.status, PlanStatus::kOk) << "length " << r.length_mm;
  // One millimetre more on each side: the corridor is driven straight through.
  Site wider = room();
  wider.obstacles.push_back(rack("lo", 9000, 0, 11000, 5000 - kR - 1));
  wider.obstacles.push_back(rack("hi", 9000, 5000 + kR + 1, 11000, 10000));
  const RoutePlanner pw = build(wider);
  const Route rw = pw.plan({5000, 5000}, {15000, 5000});
  expect_clear(wider, rw);
  EXPECT_NEAR(rw.length_mm, 10000.0, 1e-6);
}

TEST(Planner, StartOnAnInflatedEdge) {
  Site s = room();
  s.obstacles.push_back(rack("r1", 9000, 2000, 11000, 8000));
  const RoutePlanner p = build(s);
  const Vec2 start{9000 - kR, 5000};  // on the inflated rack's left edge
  EXPECT_TRUE(p.point_free(start));
  const Route r = p.plan(start, {15000, 5000});
  expect_clear(s, r);
  // Sliding along the edge is allowed, entering the rack is not.
  EXPECT_TRUE(p.segment_free(start, {9000 - kR, 8000}));
  EXPECT_FALSE(p.segment_free(start, {15000, 5000}));
  EXPECT_TRUE(p.segment_free(start, {2000, 5000}));
}

TEST(Planner, StartEqualsGoal) {
  const Site s = room();
  const RoutePlanner p = build(s);
  const Route r = p.plan({3000, 3000}, {3000, 3000});
  ASSERT_EQ(r.status, PlanStatus::kOk);
  EXPECT_EQ(r.waypoints_mm.size(), 1u);
  EXPECT_EQ(r.length_mm, 0.0);
}

TEST(Planner, BlockedEndsNameTheObstacle) {
  Site s = room();
  s.obstacles.push_back(rack("rack-17", 9000, 2000, 11000, 8000));
  const RoutePlanner p = build(s);
  Route r = p.plan({10000, 5000}, {15000, 5000});
  EXPECT_EQ(r.status, PlanStatus::kStartBlocked);
  EXPECT_NE(r.error.find("rack-17"), std::string::npos) << r.error;
  r = p.plan({15000, 5000}, {9000 - kR + 10, 5000});  // inside the inflation, outside the rack
  EXPECT_EQ(r.status, PlanStatus::kGoalBlocked);
  EXPECT_NE(r.error.find("rack-17"), std::string::npos) << r.error;
  r = p.plan({15000, 5000}, {100, 5000});  // too close to the wall
  EXPECT_EQ(r.status, PlanStatus::kGoalBlocked);
  EXPECT_NE(r.error.find("outline"), std::string::npos) << r.error;
  r = p.plan({15000, 5000}, {-3000, 5000});
  EXPECT_EQ(r.status, PlanStatus::kGoalBlocked);
  r = p.plan({NAN, 5000}, {1000, 5000});
  EXPECT_EQ(r.status, PlanStatus::kInvalidInput);
  EXPECT_STREQ(to_string(PlanStatus::kNoRoute), "no_route");
}

TEST(Planner, EnclosedGoalHasNoRoute) {
  Site s = room();
  // Four racks touching at their ends enclose a 4 m x 4 m yard.
  s.obstacles.push_back(rack("s", 8000, 2000, 13000, 3000));
  s.obstacles.push_back(rack("e", 12000, 3000, 13000, 8000));
  s.obstacles.push_back(rack("n", 7000, 7000, 12000, 8000));
  s.obstacles.push_back(rack("w", 7000, 2000, 8000, 7000));
  const RoutePlanner p = build(s);
  const Route r = p.plan({3000, 5000}, {10000, 5000});
  EXPECT_EQ(r.status, PlanStatus::kNoRoute);
  EXPECT_FALSE(r.error.empty());
  const Route inside = p.plan({9500, 4500}, {10500, 5500});
  expect_clear(s, inside);
}

TEST(Planner, LShapedSiteAndConcaveRack) {
  Site s;
  s.outline.vertices_mm = {{0, 0},       {20000, 0},    {20000, 8000},
                           {8000, 8000}, {8000, 20000}, {0, 20000}};
  Obstacle u;  // a U open to the east
  u.id = "u";
  u.outline.vertices_mm = {{2000, 2000}, {6000, 2000}, {6000, 3000}, {3000, 3000},
                           {3000, 5000}, {6000, 5000}, {6000, 6000}, {2000, 6000}};
  s.obstacles.push_back(u);
  const RoutePlanner p = build(s);
  const Route r = p.plan({18000, 2000}, {2000, 18000});  // around the outline's reflex corner
  expect_clear(s, r);
  const Route into_u = p.plan({4500, 4000}, {1000, 4000});  // from inside the U to its back
  expect_clear(s, into_u);
}

TEST(Planner, BadGeometryIsRefused) {
  Site s = room();
  s.obstacles.push_back(rack("ok", 1000, 1000, 2000, 2000));
  s.obstacles.push_back({"flat", ObstacleKind::kRack, {{{0, 0}, {1, 1}}}, 2000.0});
  RoutePlanner p;
  std::string error;
  EXPECT_FALSE(RoutePlanner::build(s, {}, &p, &error));
  EXPECT_NE(error.find("flat"), std::string::npos) << error;
  Site tiny = room(800, 800);
  EXPECT_FALSE(RoutePlanner::build(tiny, {}, &p, &error));
  EXPECT_NE(error.find("no free space"), std::string::npos) << error;
  const Route r = RoutePlanner().plan({0, 0}, {1, 1});
  EXPECT_EQ(r.status, PlanStatus::kInvalidInput);
}

}  // namespace
}  // namespace agv::site
