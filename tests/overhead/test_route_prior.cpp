// The route prior of the overhead tracker (route_prior.hpp, FleetTracker::set_route): a vehicle on
// an L-shaped route whose fixes stop 1 m before the corner is extrapolated round the corner along
// the route, where the constant turn-rate model carries it straight on; a route the track does not
// lie on, or one set after its newest fix, is ignored; bad routes are refused. Synthetic fixes.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdint>
#include <limits>
#include <random>
#include <string>
#include <vector>

#include "agv/overhead/route_prior.hpp"
#include "agv/overhead/tracker.hpp"
#include "agv/vda5050/order.hpp"

using namespace agv;
using namespace agv::overhead;

namespace {

constexpr std::int64_t kMs = 1'000'000;
constexpr double kSpeedMps = 1.0;

// (0, 0) -> (4000, 0) -> (4000, 4000); the vehicle starts at (500, 0).
const std::vector<Vec2> kRoute = {{0.0, 0.0}, {4000.0, 0.0}, {4000.0, 4000.0}};

// The truth on the route at t_s: 1 m/s from x = 500 mm, turning on the spot at the corner.
Pose2 truth_at(double t_s) {
  const double s = 500.0 + 1000.0 * kSpeedMps * t_s;
  if (s <= 4000.0) return {s, 0.0, 0.0};
  return {4000.0, std::min(4000.0, s - 4000.0), kPi / 2.0};
}

TagFix fix_at(const Pose2& p, std::mt19937_64* rng) {
  std::normal_distribution<double> n(0.0, 1.0);
  const double ex = 3.0 * n(*rng);
  const double ey = 3.0 * n(*rng);
  const double et = 0.005 * n(*rng);
  TagFix f;
  f.pose = {p.x_mm + ex, p.y_mm + ey, wrap_angle_rad(p.theta_rad + et)};
  f.cov = {9.0, 0, 0, 0, 9.0, 0, 0, 0, 0.005 * 0.005};
  return f;
}

TrackerParams params(bool route) {
  TrackerParams p;
  p.route_prior = route;
  p.lost_sigma_mm = 5000.0;  // keep the coasting track reported, to compare poses
  return p;
}

// Fixes at 10 Hz for 2.5 s (the last at x = 3000 mm, 1 m before the corner).
constexpr std::int64_t kLastFixNs = 2500 * kMs;
void feed(FleetTracker* tr) {
  std::mt19937_64 rng(5);
  for (std::int64_t t = 0; t <= kLastFixNs; t += 100 * kMs) {
    const FixResult r = tr->add_fix(0, t, fix_at(truth_at(1e-9 * static_cast<double>(t)), &rng));
    ASSERT_TRUE(r == FixResult::kApplied || r == FixResult::kStarted);
  }
}

double error_mm(const TrackOutput& o, const Pose2& truth) {
  return std::hypot(o.pose.x_mm - truth.x_mm, o.pose.y_mm - truth.y_mm);
}

bool same_output(const TrackOutput& a, const TrackOutput& b) {
  return a.state == b.state && a.pose.x_mm == b.pose.x_mm && a.pose.y_mm == b.pose.y_mm &&
         a.pose.theta_rad == b.pose.theta_rad && a.cov == b.cov && a.v_mps == b.v_mps &&
         a.omega_radps == b.omega_radps;
}

TEST(RoutePrior, CoastingTrackFollowsTheRouteRoundTheCorner) {
  FleetTracker with(2, params(true)), without(2, params(false));
  std::string err;
  ASSERT_TRUE(with.set_route(0, kRoute, 0, &err)) << err;
  feed(&with);
  feed(&without);
  const std::int64_t t = kLastFixNs + 2000 * kMs;
  const Pose2 truth = truth_at(1e-9 * static_cast<double>(t));  // (4000, 1000), heading north
  with.update_states(t);
  without.update_states(t);
  const TrackOutput a = with.output(0, t), b = without.output(0, t);
  EXPECT_EQ(a.state, TrackState::kCoasting);
  EXPECT_LT(error_mm(a, truth), 300.0);  // the filter's speed after 2.5 s of fixes
  EXPECT_NEAR(wrap_angle_rad(a.pose.theta_rad - truth.theta_rad), 0.0, 0.05);
  EXPECT_GT(error_mm(b, truth), 1000.0);  // straight on past the corner
  // Across the route the sigma is the route's tolerance at least.
  EXPECT_GE(std::sqrt(a.cov[0]), with.params().route.cross_track_sigma_mm - 1e-9);
  EXPECT_GE(a.sigma_theta_rad, with.params().route.heading_sigma_rad - 1e-12);
  // The truth within 3 sigma of the prediction.
  EXPECT_LT(error_mm(a, truth), 3.0 * a.sigma_xy_mm);
  // The fix after the coast is gated against the extrapolation along the route: applied.
  std::mt19937_64 rng(9);
  EXPECT_EQ(with.add_fix(0, t, fix_at(truth, &rng)), FixResult::kApplied);
}

TEST(RoutePrior, BeforeCoastingAndWithoutRouteTheOutputIsUnchanged) {
  FleetTracker with(2, params(true)), without(2, params(false)), no_route(2, params(true));
  ASSERT_TRUE(with.set_route(0, kRoute, 0));
  feed(&with);
  feed(&without);
  feed(&no_route);
  for (std::int64_t dt_ms : {0, 100, 250, 500, 2000}) {
    const std::int64_t t = kLastFixNs + dt_ms * kMs;
    EXPECT_TRUE(same_output(no_route.output(0, t), without.output(0, t))) << dt_ms;
    const bool coasting = static_cast<double>(dt_ms) > with.params().coast_after_ms;
    EXPECT_EQ(same_output(with.output(0, t), without.output(0, t)), !coasting) << dt_ms;
  }
}

TEST(RoutePrior, RouteTheTrackIsNotOnIsIgnored) {
  FleetTracker ref(1, params(false));
  feed(&ref);
  const std::int64_t t = kLastFixNs + 2000 * kMs;
  const std::vector<std::vector<Vec2>> wrong = {
      {{0.0, 1000.0}, {4000.0, 1000.0}, {4000.0, 5000.0}},  // 1 m aside
      {{4000.0, 0.0}, {0.0, 0.0}},                          // the opposite way
  };
  for (const auto& route : wrong) {
    FleetTracker tr(1, params(true));
    ASSERT_TRUE(tr.set_route(0, route, 0));
    feed(&tr);
    EXPECT_TRUE(same_output(tr.output(0, t), ref.output(0, t)));
  }
  // A route set after the newest fix (a new order the vehicle was not seen on) is not used.
  FleetTracker late(1, params(true));
  feed(&late);
  ASSERT_TRUE(late.set_route(0, kRoute, kLastFixNs + 1));
  EXPECT_TRUE(same_output(late.output(0, t), ref.output(0, t)));
  // Cleared: the motion model again.
  FleetTracker cleared(1, params(true));
  ASSERT_TRUE(cleared.set_route(0, kRoute, 0));
  feed(&cleared);
  EXPECT_FALSE(same_output(cleared.output(0, t), ref.output(0, t)));
  cleared.clear_route(0);
  EXPECT_TRUE(same_output(cleared.output(0, t), ref.output(0, t)));
}

TEST(RoutePrior, BadRoutesAreRefusedAndTheOldOneKept) {
  FleetTracker tr(2, params(true));
  ASSERT_TRUE(tr.set_route(0, kRoute, 0));
  const double nan = std::numeric_limits<double>::quiet_NaN();
  const double inf = std::numeric_limits<double>::infinity();
  const std::vector<std::vector<Vec2>> bad = {{},
                                              {{1.0, 2.0}},
                                              {{1.0, 2.0}, {1.0, 2.0}},
                                              {{0.0, 0.0}, {nan, 0.0}},
                                              {{0.0, 0.0}, {inf, 1.0}}};
  for (const auto& route : bad) {
    std::string err;
    EXPECT_FALSE(tr.set_route(0, route, 0, &err));
    EXPECT_FALSE(err.empty());
  }
  std::vector<Vec2> huge(kRouteMaxPoints + 1);
  for (std::size_t i = 0; i < huge.size(); ++i) huge[i] = {static_cast<double>(i), 0.0};
  EXPECT_FALSE(tr.set_route(0, huge, 0));
  std::string err;
  EXPECT_FALSE(tr.set_route(2, kRoute, 0, &err));
  EXPECT_NE(err.find("outside"), std::string::npos);
  tr.clear_route(7);  // nothing to do, no crash
  FleetTracker off(1, params(false));
  EXPECT_FALSE(off.set_route(0, kRoute, 0, &err));
  EXPECT_NE(err.find("off"), std::string::npos);
  // The first route is still in force.
  feed(&tr);
  const std::int64_t t = kLastFixNs + 2000 * kMs;
  EXPECT_LT(error_mm(tr.output(0, t), truth_at(4.5)), 300.0);
  // Parameters of the prior are checked when it is on.
  TrackerParams p = params(true);
  p.route.cross_track_sigma_mm = 0.0;
  EXPECT_THROW(FleetTracker(1, p), std::invalid_argument);
  p.route_prior = false;
  EXPECT_NO_THROW(FleetTracker(1, p));
}

TEST(RoutePrior, PredictionOnThePolyline) {
  RoutePath path;
  std::string err;
  ASSERT_TRUE(path.assign(kRoute, &err)) << err;
  EXPECT_DOUBLE_EQ(path.length_mm(), 8000.0);
  RouteFixState fs;
  fs.pose = {3000.0, 50.0, 0.05};
  fs.v_mmps = 1000.0;
  fs.cov_xyv = {100.0, 0, 0, 0, 100.0, 0, 0, 0, 100.0};
  const RoutePriorParams rp;
  RoutePrediction r;
  ASSERT_EQ(predict_on_route(path, fs, 2.0, 0.0, rp, &r), RouteFit::kOnRoute);
  EXPECT_NEAR(r.pose.x_mm, 4000.0, 1e-9);
  EXPECT_NEAR(r.pose.y_mm, 1000.0, 1e-9);
  EXPECT_NEAR(r.pose.theta_rad, kPi / 2.0, 1e-12);
  EXPECT_NEAR(r.cross_track_mm, 50.0, 1e-9);
  // Along the second segment (y): the fix's along variance 100 + dt^2 100 = 500.
  EXPECT_NEAR(r.cov[4], 500.0, 1e-9);
  EXPECT_NEAR(r.cov[0], rp.cross_track_sigma_mm * rp.cross_track_sigma_mm, 1e-9);
  // Stops at the end.
  ASSERT_EQ(predict_on_route(path, fs, 60.0, 0.0, rp, &r), RouteFit::kOnRoute);
  EXPECT_TRUE(r.at_end);
  EXPECT_NEAR(r.pose.y_mm, 4000.0, 1e-9);
  // At the corner the heading chooses the segment.
  fs.pose = {4000.0, 0.0, kPi / 2.0};
  ASSERT_EQ(predict_on_route(path, fs, 1.0, 0.0, rp, &r), RouteFit::kOnRoute);
  EXPECT_NEAR(r.pose.y_mm, 1000.0, 1e-9);
  // Off the route, heading against it, bad input.
  fs.pose = {2000.0, 400.0, 0.0};
  EXPECT_EQ(predict_on_route(path, fs, 1.0, 0.0, rp, &r), RouteFit::kOffRoute);
  fs.pose = {2000.0, 0.0, kPi};
  EXPECT_EQ(predict_on_route(path, fs, 1.0, 0.0, rp, &r), RouteFit::kOffRoute);
  fs.pose = {2000.0, 0.0, 0.0};
  EXPECT_EQ(predict_on_route(path, fs, -1.0, 0.0, rp, &r), RouteFit::kInvalid);
  fs.v_mmps = std::numeric_limits<double>::quiet_NaN();
  EXPECT_EQ(predict_on_route(path, fs, 1.0, 0.0, rp, &r), RouteFit::kInvalid);
  EXPECT_EQ(predict_on_route(RoutePath{}, RouteFixState{}, 1.0, 0.0, rp, &r), RouteFit::kInvalid);
}

// The route as a fleet manager sends it: a VDA 5050 order, read back into waypoints.
TEST(RoutePrior, RouteFromAnOrder) {
  vda5050::Order header;
  header.order_id = "o1";
  header.manufacturer = "agvloc";
  header.serial_number = "agv-1";
  const std::string text =
      vda5050::encode_order(vda5050::order_from_waypoints(kRoute, "m", header));
  vda5050::Order order;
  std::string err;
  ASSERT_TRUE(vda5050::parse_order(text, &order, &err)) << err;
  std::vector<Vec2> pts;
  ASSERT_TRUE(vda5050::order_waypoints_mm(order, &pts, &err)) << err;
  FleetTracker tr(1, params(true));
  ASSERT_TRUE(tr.set_route(0, pts, 0, &err)) << err;
  feed(&tr);
  const std::int64_t t = kLastFixNs + 2000 * kMs;
  EXPECT_LT(error_mm(tr.output(0, t), truth_at(4.5)), 300.0);
}

}  // namespace
