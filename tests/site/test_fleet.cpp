// Fleet simulator (agv/sim/fleet.hpp): clearance between every pair at every step, tasks
// finished, waits at reserved cells, deadlock and idle-vehicle blockages reported and resolved,
// sensors consistent with the truth, bad input refused.
#include <gtest/gtest.h>

#include <cmath>

#include "../support/gyro_errors.hpp"
#include "agv/sim/fleet.hpp"
#include "fleet_warehouse.hpp"

namespace agv::sim {
namespace {

site::Polygon rect(double x0, double y0, double x1, double y1) {
  return {{{x0, y0}, {x1, y0}, {x1, y1}, {x0, y1}}};
}

// 16 m x 10 m with two rack rows: aisles of 2.5 m and 3 m.
site::Site small_site() {
  site::Site s;
  s.name = "fleet-test";
  s.outline = rect(0, 0, 16000, 10000);
  site::Obstacle a, b;
  a.id = "rack-a";
  a.outline = rect(4000, 2500, 12000, 3500);
  b.id = "rack-b";
  b.outline = rect(4000, 6500, 12000, 7500);
  s.obstacles = {a, b};
  s.clearance_mm = 100.0;
  return s;
}

// Two 6 m x 6 m rooms joined by an 8 m corridor 1.6 m wide: two vehicles cannot pass in it.
site::Site corridor_site() {
  site::Site s;
  s.name = "corridor";
  s.outline.vertices_mm = {{0, 0},        {6000, 0},    {6000, 2200},  {14000, 2200},
                           {14000, 0},    {20000, 0},   {20000, 6000}, {14000, 6000},
                           {14000, 3800}, {6000, 3800}, {6000, 6000},  {0, 6000}};
  s.clearance_mm = 100.0;
  return s;
}

site::Site open_site() {
  site::Site s;
  s.name = "open";
  s.outline = rect(0, 0, 12000, 12000);
  s.clearance_mm = 100.0;
  return s;
}

site::RoutePlanner planner_for(const site::Site& s, double radius_mm = 400.0) {
  site::RoutePlanner p;
  std::string err;
  EXPECT_TRUE(route_planner_for_fleet(s, {radius_mm}, &p, &err)) << err;
  return p;
}

FleetVehicleSpec vehicle(double x, double y, double th, std::vector<FleetTask> tasks) {
  FleetVehicleSpec v;
  v.radius_mm = 400.0;
  v.start = {x, y, th};
  v.tasks = std::move(tasks);
  return v;
}

// Runs and checks the clearance of every pair at every step.
FleetResult run_checked(const site::Site& s, const site::RoutePlanner& planner,
                        const std::vector<FleetVehicleSpec>& specs, const FleetParams& p) {
  FleetResult r;
  std::string err;
  double worst_mm = 1e300;
  std::int64_t steps = 0;
  const double clearance = p.clearance_mm >= 0.0 ? p.clearance_mm : s.clearance_mm;
  auto check = [&](std::int64_t, const std::vector<Pose2>& poses) {
    ++steps;
    for (std::size_t i = 0; i < poses.size(); ++i) {
      for (std::size_t j = i + 1; j < poses.size(); ++j) {
        const double d = std::hypot(poses[i].x_mm - poses[j].x_mm, poses[i].y_mm - poses[j].y_mm);
        worst_mm = std::min(worst_mm, d - (specs[i].radius_mm + specs[j].radius_mm + clearance));
      }
    }
  };
  EXPECT_TRUE(simulate_fleet(s, planner, specs, p, &r, &err, check)) << err;
  EXPECT_EQ(steps, r.steps + 1);
  if (specs.size() > 1) {
    EXPECT_GE(worst_mm, -1e-6) << "two vehicles closer than r_i + r_j + clearance";
    EXPECT_NEAR(r.min_pair_margin_mm, worst_mm, 1e-9);
  }
  return r;
}

int count_events(const FleetResult& r, FleetEventKind k) {
  int n = 0;
  for (const FleetEvent& e : r.events) n += e.kind == k;
  return n;
}

TEST(Fleet, SixVehiclesKeepApartAndFinish) {
  const site::Site s = small_site();
  const std::vector<double> radii(6, 400.0);
  site::RoutePlanner planner;
  std::string err;
  ASSERT_TRUE(route_planner_for_fleet(s, radii, &planner, &err)) << err;
  std::vector<FleetVehicleSpec> specs;
  ASSERT_TRUE(make_random_fleet(planner, s, radii, 1, 11, &specs, &err)) << err;
  FleetParams p;
  p.duration_s = 90.0;
  const FleetResult r = run_checked(s, planner, specs, p);
  EXPECT_EQ(r.tasks_finished, 6);
  for (const FleetTaskRecord& t : r.tasks) {
    EXPECT_GE(t.finish_s, 0.0) << "vehicle " << t.vehicle << " task " << t.index;
    EXPECT_GT(t.picked_s, t.start_s);
    EXPECT_GT(t.finish_s, t.picked_s);
  }
  for (const FleetVehicleOutput& v : r.vehicles) {
    EXPECT_EQ(v.truth.size(), 9001u);
    EXPECT_EQ(v.odom.size(), 9001u);
    EXPECT_EQ(v.gyro.size(), 18001u);
    EXPECT_GT(v.distance_mm, 3000.0);
  }
  EXPECT_EQ(r.unresolved, 0);
}

TEST(Fleet, SameSeedSameRunOtherSeedOtherRun) {
  const site::Site s = small_site();
  const std::vector<double> radii(3, 400.0);
  site::RoutePlanner planner;
  std::string err;
  ASSERT_TRUE(route_planner_for_fleet(s, radii, &planner, &err)) << err;
  std::vector<FleetVehicleSpec> a, b, c;
  ASSERT_TRUE(make_random_fleet(planner, s, radii, 1, 5, &a, &err)) << err;
  ASSERT_TRUE(make_random_fleet(planner, s, radii, 1, 5, &b, &err)) << err;
  ASSERT_TRUE(make_random_fleet(planner, s, radii, 1, 6, &c, &err)) << err;
  ASSERT_EQ(a.size(), 3u);
  for (std::size_t i = 0; i < a.size(); ++i) {
    EXPECT_EQ(a[i].start.x_mm, b[i].start.x_mm);
    EXPECT_EQ(a[i].tasks[0].drop_mm.y, b[i].tasks[0].drop_mm.y);
    EXPECT_TRUE(planner.point_free(a[i].tasks[0].pick_mm));
  }
  EXPECT_NE(a[0].start.x_mm, c[0].start.x_mm);
  FleetParams p;
  p.duration_s = 10.0;
  FleetResult ra, rb;
  ASSERT_TRUE(simulate_fleet(s, planner, a, p, &ra, &err)) << err;
  ASSERT_TRUE(simulate_fleet(s, planner, a, p, &rb, &err)) << err;
  for (std::size_t i = 0; i < a.size(); ++i) {
    ASSERT_EQ(ra.vehicles[i].truth.size(), rb.vehicles[i].truth.size());
    EXPECT_EQ(ra.vehicles[i].truth.back().pose.x_mm, rb.vehicles[i].truth.back().pose.x_mm);
    EXPECT_EQ(ra.vehicles[i].odom[500].v_mps, rb.vehicles[i].odom[500].v_mps);
    EXPECT_EQ(ra.vehicles[i].gyro[999].gyro_z_radps, rb.vehicles[i].gyro[999].gyro_z_radps);
  }
  // Each vehicle's sensors have their own seed.
  EXPECT_NE(ra.vehicles[0].gyro[10].gyro_z_radps, ra.vehicles[1].gyro[10].gyro_z_radps);
}

TEST(Fleet, CrossingVehiclesOneWaits) {
  // Without the reservation they would meet at (6, 6) m at the same time.
  const site::Site s = open_site();
  const site::RoutePlanner planner = planner_for(s);
  const std::vector<FleetVehicleSpec> specs = {
      vehicle(1000, 6000, 0.0, {{{11000, 6000}, {11000, 9000}}}),
      vehicle(6000, 1000, kPi / 2, {{{6000, 11000}, {9000, 11000}}})};
  FleetParams p;
  p.duration_s = 40.0;
  const FleetResult r = run_checked(s, planner, specs, p);
  EXPECT_EQ(r.tasks_finished, 2);
  EXPECT_GE(r.vehicles[0].waits + r.vehicles[1].waits, 1);
  EXPECT_GT(r.vehicles[0].wait_s + r.vehicles[1].wait_s, 0.5);
  EXPECT_EQ(r.deadlocks, 0);
  // Waiting means standing: every truth sample while waiting has v = 0 somewhere.
  bool stood = false;
  for (const FleetVehicleOutput& v : r.vehicles) {
    for (std::size_t k = 100; k < 1500 && k < v.truth.size(); ++k) stood |= v.truth[k].v_mps == 0.0;
  }
  EXPECT_TRUE(stood);
}

TEST(Fleet, HeadOnInCorridorIsReportedAndResolved) {
  const site::Site s = corridor_site();
  const site::RoutePlanner planner = planner_for(s);
  const std::vector<FleetVehicleSpec> specs = {
      vehicle(2000, 3000, 0.0, {{{17000, 3000}, {17000, 1000}}}),
      vehicle(18000, 3000, kPi, {{{3000, 3000}, {3000, 1000}}})};
  FleetParams p;
  p.duration_s = 100.0;
  const FleetResult r = run_checked(s, planner, specs, p);
  EXPECT_GE(r.deadlocks, 1);
  EXPECT_GE(count_events(r, FleetEventKind::kDeadlock), 1);
  EXPECT_GE(count_events(r, FleetEventKind::kEvade), 1);
  // The lower priority (higher index) drives aside.
  EXPECT_GE(r.vehicles[1].evasions, 1);
  EXPECT_EQ(r.vehicles[0].evasions, 0);
  EXPECT_EQ(r.tasks_finished, 2);
  EXPECT_EQ(r.unresolved, 0);
}

TEST(Fleet, IdleVehicleInTheWayDrivesAside) {
  const site::Site s = corridor_site();
  const site::RoutePlanner planner = planner_for(s);
  const std::vector<FleetVehicleSpec> specs = {
      vehicle(2000, 3000, 0.0, {{{18000, 3000}, {18000, 1000}}}), vehicle(10000, 3000, 0.0, {})};
  FleetParams p;
  p.duration_s = 80.0;
  const FleetResult r = run_checked(s, planner, specs, p);
  EXPECT_EQ(r.blocked_by_idle, 1);
  EXPECT_EQ(count_events(r, FleetEventKind::kBlockedByIdle), 1);
  EXPECT_EQ(r.vehicles[1].evasions, 1);
  EXPECT_EQ(r.tasks_finished, 1);
}

// An idle vehicle parked mid-corridor with vehicles coming from both ends: it has no refuge
// (the corridor is the let-through vehicle's route, each room lies behind a waiting vehicle), so
// the blockage stayed unresolved until the run ended. The waiting vehicle now backs away first.
TEST(Fleet, IdleVehicleBoxedInFromBothEndsIsFreed) {
  const site::Site s = corridor_site();
  const site::RoutePlanner planner = planner_for(s);
  const std::vector<FleetVehicleSpec> specs = {
      vehicle(5000, 3000, 0.0, {{{17000, 3000}, {17000, 1000}}}),
      vehicle(15000, 3000, kPi, {{{3000, 3000}, {3000, 1000}}}), vehicle(10000, 3000, 0.0, {})};
  FleetParams p;
  p.duration_s = 120.0;
  const FleetResult r = run_checked(s, planner, specs, p);
  EXPECT_GE(r.blocked_by_idle, 1);
  EXPECT_EQ(r.tasks_finished, 2);
}

// Six vehicles on the benchmark warehouse over several seeds: every task finished and no
// blockage left unresolved (seeds 10-12 each had an idle vehicle that could not move aside).
TEST(Fleet, SmallFleetOverSeedsFinishesWithNoUnresolvedBlockage) {
  const site::Site s = fleet_bench::warehouse();
  const std::vector<double> radii{400, 400, 400, 550, 400, 400};
  site::RoutePlanner planner;
  std::string err;
  ASSERT_TRUE(route_planner_for_fleet(s, radii, &planner, &err)) << err;
  for (std::uint64_t seed = 9; seed <= 12; ++seed) {
    std::vector<FleetVehicleSpec> specs;
    ASSERT_TRUE(make_random_fleet(planner, s, radii, 1, seed, &specs, &err)) << err;
    FleetParams p;
    p.duration_s = 180.0;
    p.seed = seed;
    p.keep_samples = false;
    const FleetResult r = run_checked(s, planner, specs, p);
    EXPECT_EQ(r.tasks_finished, 6) << "seed " << seed;
    EXPECT_EQ(r.unresolved, 0) << "seed " << seed;
  }
}

TEST(Fleet, SensorsFollowTheTruth) {
  const site::Site s = small_site();
  const site::RoutePlanner planner = planner_for(s);
  const std::vector<FleetVehicleSpec> specs = {
      vehicle(1500, 1500, 1.0, {{{14000, 5000}, {2000, 8500}}})};
  FleetParams p;
  p.duration_s = 50.0;
  p.odometry.scale_error = p.odometry.scale_asymmetry = p.odometry.noise_mps = 0.0;
  p.odometry.slip_rate_per_s = 0.0;
  testsupport::switch_off_gyro_errors(&p.gyro);
  FleetResult r;
  std::string err;
  ASSERT_TRUE(simulate_fleet(s, planner, specs, p, &r, &err)) << err;
  const FleetVehicleOutput& v = r.vehicles[0];
  EXPECT_GT(v.distance_mm, 20000.0);
  // Dead reckoning on error-free period-mean odometry retraces the truth.
  Pose2 dr = v.truth.front().pose;
  double worst_mm = 0.0;
  for (std::size_t k = 1; k < v.odom.size(); ++k) {
    const double dt = 1e-9 * static_cast<double>(v.odom[k].t_ns - v.odom[k - 1].t_ns);
    const double th_mid = dr.theta_rad + 0.5 * v.odom[k].omega_radps * dt;
    dr.x_mm += 1000.0 * v.odom[k].v_mps * dt * std::cos(th_mid);
    dr.y_mm += 1000.0 * v.odom[k].v_mps * dt * std::sin(th_mid);
    dr.theta_rad += v.odom[k].omega_radps * dt;
    worst_mm = std::max(worst_mm,
                        std::hypot(dr.x_mm - v.truth[k].pose.x_mm, dr.y_mm - v.truth[k].pose.y_mm));
  }
  EXPECT_LT(worst_mm, 30.0);
  // The error-free gyro integrates to the heading turned.
  double turned = 0.0;
  for (std::size_t k = 1; k < v.gyro.size(); ++k) turned += v.gyro[k].gyro_z_radps * 0.005;
  EXPECT_NEAR(wrap_angle_rad(specs[0].start.theta_rad + turned - v.truth.back().pose.theta_rad),
              0.0, 1e-6);
  // Default errors make the odometry differ from the truth.
  FleetParams q;
  q.duration_s = 50.0;
  FleetResult r2;
  ASSERT_TRUE(simulate_fleet(s, planner, specs, q, &r2, &err)) << err;
  double diff = 0.0;
  for (std::size_t k = 0; k < v.odom.size(); ++k) {
    diff = std::max(diff, std::abs(r2.vehicles[0].odom[k].v_mps - v.odom[k].v_mps));
  }
  EXPECT_GT(diff, 0.001);
}

TEST(Fleet, BadInputIsRefused) {
  const site::Site s = small_site();
  const site::RoutePlanner planner = planner_for(s);
  FleetParams p;
  p.duration_s = 1.0;
  FleetResult r;
  std::string err;
  EXPECT_FALSE(simulate_fleet(s, planner, {}, p, &r, &err));
  EXPECT_NE(err.find("no vehicles"), std::string::npos) << err;
  EXPECT_FALSE(simulate_fleet(s, planner, {vehicle(8000, 3000, 0, {})}, p, &r, &err));
  EXPECT_NE(err.find("start"), std::string::npos) << err;
  EXPECT_FALSE(simulate_fleet(s, planner, {vehicle(1500, 1500, 0, {}), vehicle(2000, 1500, 0, {})},
                              p, &r, &err));
  EXPECT_NE(err.find("too close"), std::string::npos) << err;
  EXPECT_FALSE(simulate_fleet(s, planner, {vehicle(1500, 1500, 0, {{{8000, 3000}, {1500, 8000}}})},
                              p, &r, &err));
  EXPECT_NE(err.find("task 0"), std::string::npos) << err;
  FleetParams bad = p;
  bad.step_ns = 0;
  EXPECT_FALSE(simulate_fleet(s, planner, {vehicle(1500, 1500, 0, {})}, bad, &r, &err));
  bad = p;
  bad.duration_s = std::nan("");
  EXPECT_FALSE(simulate_fleet(s, planner, {vehicle(1500, 1500, 0, {})}, bad, &r, &err));
  std::vector<FleetVehicleSpec> specs;
  EXPECT_FALSE(make_random_fleet(planner, s, std::vector<double>(200, 400.0), 1, 1, &specs, &err));
  EXPECT_NE(err.find("no free room"), std::string::npos) << err;
  site::RoutePlanner unused;
  EXPECT_FALSE(route_planner_for_fleet(s, {0.0}, &unused, &err));
}

// A head-on cycle in a packed rack aisle: every refuge off the other vehicles' route plans lay in
// the next aisle, out of reach, and the cycle was retried every 2 s until the run ended (28 of 40
// tasks). A refuge may now lie on a plan (never on the let-through vehicle's own route), and when
// no member of the cycle can move aside the vehicles queued behind it make room.
TEST(Fleet, PackedAisleHeadOnIsBrokenAndEveryTaskFinishes) {
  const site::Site s = fleet_bench::warehouse();
  std::vector<double> radii;
  for (int i = 0; i < 20; ++i) radii.push_back(i % 4 == 3 ? 550.0 : 400.0);
  site::RoutePlanner planner;
  std::string err;
  ASSERT_TRUE(route_planner_for_fleet(s, radii, &planner, &err)) << err;
  std::vector<FleetVehicleSpec> specs;
  ASSERT_TRUE(make_random_fleet(planner, s, radii, 2, 3, &specs, &err)) << err;
  FleetParams p;
  p.duration_s = 600.0;
  p.seed = 3;
  FleetResult r;
  ASSERT_TRUE(simulate_fleet(s, planner, specs, p, &r, &err)) << err;
  EXPECT_EQ(r.tasks_finished, 40);
  EXPECT_GE(r.min_pair_margin_mm, 0.0);
  EXPECT_GE(r.deadlocks, 1);  // the case still contains the head-on it was written for
}

}  // namespace
}  // namespace agv::sim
