// The drivable trajectory: continuity of pose, curvature, lateral and longitudinal limits, a
// duration consistent with the speed profile, blends that shrink to fit short segments or are
// refused, and blends checked against the collision-free space.
#include <gtest/gtest.h>

#include <cmath>
#include <string>

#include "agv/site/planner.hpp"
#include "test_planner_util.hpp"

namespace agv::site {
namespace {

Route polyline_route(std::vector<Vec2> w) {
  Route r;
  r.status = PlanStatus::kOk;
  r.waypoints_mm = std::move(w);
  r.length_mm = test::polyline_length(r.waypoints_mm);
  return r;
}

void check_limits(const RouteTrajectory& tr, const DriveLimits& lim) {
  const double dt = 0.005;
  TrajectorySample prev = tr.at(0.0);
  EXPECT_EQ(prev.v_mps, 0.0);
  double travelled_mm = 0.0;
  for (double t = dt; t <= tr.duration_s() + dt; t += dt) {
    const TrajectorySample s = tr.at(t);
    const double step = std::hypot(s.pose.x_mm - prev.pose.x_mm, s.pose.y_mm - prev.pose.y_mm);
    travelled_mm += step;
    EXPECT_LE(step, lim.speed_mps * 1e3 * dt * 1.001 + 1e-6) << "t " << t;
    EXPECT_LE(std::abs(wrap_angle_rad(s.pose.theta_rad - prev.pose.theta_rad)),
              lim.max_curvature_per_mm * step * 1.01 + 1e-9)
        << "t " << t;
    EXPECT_LE(std::abs(s.curvature_per_mm), lim.max_curvature_per_mm * (1 + 1e-9));
    EXPECT_LE(s.v_mps * s.v_mps * std::abs(s.curvature_per_mm) * 1e3,
              lim.lateral_accel_mps2 * (1 + 1e-9));
    EXPECT_LE(s.v_mps, lim.speed_mps + 1e-12);
    EXPECT_LE(std::abs(s.v_mps - prev.v_mps), lim.accel_mps2 * (s.t_s - prev.t_s) + 1e-9)
        << "t " << t;
    EXPECT_NEAR(s.omega_radps, s.v_mps * s.curvature_per_mm * 1e3, 1e-12);
    prev = s;
  }
  EXPECT_EQ(prev.v_mps, 0.0);
  EXPECT_NEAR(travelled_mm, tr.length_mm(), 1e-3 * tr.length_mm() + 1.0);
  // Never faster than the top speed with the acceleration ramps at both ends.
  const double v = lim.speed_mps, a = lim.accel_mps2, l_m = tr.length_mm() * 1e-3;
  EXPECT_GE(tr.duration_s(), l_m / v + (l_m > v * v / a ? v / a : 0.0) - 1e-9);
}

TEST(Trajectory, RightAngleCorner) {
  const DriveLimits lim;
  RouteTrajectory tr;
  std::string error;
  ASSERT_TRUE(
      RouteTrajectory::make(polyline_route({{0, 0}, {5000, 0}, {5000, 5000}}), lim, &tr, &error))
      << error;
  ASSERT_EQ(tr.pieces.size(), 5u);  // line, clothoid, arc, clothoid, line
  for (std::size_t i = 0; i + 1 < tr.pieces.size(); ++i) {
    EXPECT_NEAR(tr.pieces[i].k1_per_mm, tr.pieces[i + 1].k0_per_mm, 1e-12);  // curvature continuous
    EXPECT_NEAR(tr.pieces[i].s0_mm + tr.pieces[i].length_mm, tr.pieces[i + 1].s0_mm, 1e-9);
  }
  EXPECT_LT(tr.length_mm(), 10000.0);
  EXPECT_GT(tr.max_corner_deviation_mm(), 0.0);
  check_limits(tr, lim);
  const TrajectorySample end = tr.at(1e9);
  EXPECT_NEAR(end.pose.x_mm, 5000.0, 1e-3);
  EXPECT_NEAR(end.pose.y_mm, 5000.0, 1e-3);
  EXPECT_NEAR(end.pose.theta_rad, kPi / 2, 1e-6);
  // Positions along the polyline are continuous where pieces meet.
  const std::vector<Vec2> pts = tr.polyline(5.0);
  for (std::size_t i = 0; i + 1 < pts.size(); ++i) {
    EXPECT_LE(std::hypot(pts[i + 1].x - pts[i].x, pts[i + 1].y - pts[i].y), 5.0 + 1e-6);
  }
}

TEST(Trajectory, ShortSegmentsShrinkTheClothoidsOrAreRefused) {
  const DriveLimits lim;
  RouteTrajectory tr;
  std::string error;
  // Corners 200 mm apart turning 22.5 deg each (an inflated corner's chain): shorter clothoids.
  std::vector<Vec2> w{{-3000, 0}};
  double th = 0.0;
  Vec2 p{0, 0};
  w.push_back(p);
  for (int i = 0; i < 4; ++i) {
    th += kPi / 8;
    p = {p.x + 200 * std::cos(th), p.y + 200 * std::sin(th)};
    w.push_back(p);
  }
  w.push_back({p.x + 3000 * std::cos(th), p.y + 3000 * std::sin(th)});
  ASSERT_TRUE(RouteTrajectory::make(polyline_route(w), lim, &tr, &error)) << error;
  check_limits(tr, lim);
  // A right angle with 50 mm legs cannot be turned at a 300 mm radius.
  EXPECT_FALSE(RouteTrajectory::make(polyline_route({{0, 0}, {50, 0}, {50, 50}, {3000, 50}}), lim,
                                     &tr, &error));
  EXPECT_NE(error.find("corner"), std::string::npos) << error;
  Route bad;
  bad.status = PlanStatus::kNoRoute;
  EXPECT_FALSE(RouteTrajectory::make(bad, lim, &tr, &error));
  DriveLimits zero = lim;
  zero.speed_mps = 0.0;
  EXPECT_FALSE(RouteTrajectory::make(polyline_route({{0, 0}, {1000, 0}}), zero, &tr, &error));
}

TEST(Trajectory, StraightAndSinglePoint) {
  const DriveLimits lim;
  RouteTrajectory tr;
  std::string error;
  ASSERT_TRUE(RouteTrajectory::make(polyline_route({{0, 0}, {100, 0}}), lim, &tr, &error)) << error;
  check_limits(tr, lim);  // too short to reach the top speed: a triangle profile, its peak
  // between knots 20 mm apart, so a little slower than the ideal one
  const double ideal_s = 2.0 * std::sqrt(0.1 / lim.accel_mps2);
  EXPECT_GE(tr.duration_s(), ideal_s - 1e-9);
  EXPECT_LE(tr.duration_s(), 1.01 * ideal_s);
  ASSERT_TRUE(RouteTrajectory::make(polyline_route({{7, 8}}), lim, &tr, &error)) << error;
  EXPECT_EQ(tr.duration_s(), 0.0);
  EXPECT_EQ(tr.at(3.0).pose.x_mm, 7.0);
}

TEST(Trajectory, PlannedRouteStaysCollisionFree) {
  Site s;
  s.outline = test::rect(0, 0, 20000, 10000);
  s.obstacles.push_back(test::rack("r1", 9000, 2000, 11000, 8000));
  s.obstacles.push_back(test::rack("r2", 4000, 0, 5000, 4000));
  RoutePlanner p, collision;
  std::string error;
  PlannerParams params;
  ASSERT_TRUE(RoutePlanner::build(s, params, &p, &error)) << error;
  params.clearance_mm = 0.0;
  ASSERT_TRUE(RoutePlanner::build(s, params, &collision, &error)) << error;
  const Route r = p.plan({2000, 2000}, {15000, 5000});
  ASSERT_EQ(r.status, PlanStatus::kOk) << r.error;
  RouteTrajectory tr;
  const DriveLimits lim;
  ASSERT_TRUE(RouteTrajectory::make_checked(r, lim, collision, &tr, &error)) << error;
  check_limits(tr, lim);
  // The blends cut into the clearance margin, never past it.
  EXPECT_GE(test::min_clearance_mm(s, tr.polyline(10.0), 5.0), params.vehicle_radius_mm - 1e-6);
  EXPECT_LE(tr.max_corner_deviation_mm(), PlannerParams{}.clearance_mm);
}

}  // namespace
}  // namespace agv::site
