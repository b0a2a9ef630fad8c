// Trajectories are closed, consistent with their own speeds, pass over the landmark grid; the
// odometry model has the documented errors and is a pure function of time.
#include <gtest/gtest.h>

#include <cmath>
#include <fstream>
#include <sstream>

#include "agv/sim/render.hpp"
#include "agv/sim/trajectory.hpp"

using namespace agv;
using namespace agv::sim;

namespace {

constexpr TrajectoryKind kAll[] = {TrajectoryKind::kLine, TrajectoryKind::kSquare,
                                   TrajectoryKind::kCircle, TrajectoryKind::kFigure8,
                                   TrajectoryKind::kLawnmower};

Trajectory make(TrajectoryKind k) {
  TrajectoryParams p;
  p.kind = k;
  Trajectory t;
  std::string err;
  EXPECT_TRUE(make_trajectory(p, &t, &err)) << err;
  return t;
}

}  // namespace

TEST(Trajectory, ClosedLoopsAndNames) {
  for (TrajectoryKind k : kAll) {
    const Trajectory t = make(k);
    EXPECT_LT(t.closure_error_mm, 1e-6) << to_string(k);
    EXPECT_GT(t.length_mm, 3000.0);
    TrajectoryKind back;
    ASSERT_TRUE(parse_trajectory_kind(to_string(k), &back));
    EXPECT_EQ(back, k);
  }
  TrajectoryKind k;
  EXPECT_FALSE(parse_trajectory_kind("spiral", &k));
}

TEST(Trajectory, IntegratingOwnSpeedsReproducesPose) {
  for (TrajectoryKind kind : kAll) {
    const Trajectory t = make(kind);
    Pose2 p = t.start;
    const std::int64_t dt = 200'000;  // 0.2 ms midpoint integration
    const double dt_s = 2e-4;
    double max_err = 0.0;
    for (std::int64_t tn = 0; tn < 30'000'000'000LL; tn += dt) {
      const MotionState m = trajectory_state(t, tn + dt / 2);
      const double th = p.theta_rad + 0.5 * m.omega_radps * dt_s;
      p.x_mm += 1000.0 * m.v_mps * dt_s * std::cos(th);
      p.y_mm += 1000.0 * m.v_mps * dt_s * std::sin(th);
      p.theta_rad = wrap_angle_rad(p.theta_rad + m.omega_radps * dt_s);
      const MotionState truth = trajectory_state(t, tn + dt);
      max_err = std::max(max_err, std::hypot(p.x_mm - truth.pose.x_mm, p.y_mm - truth.pose.y_mm));
    }
    EXPECT_LT(max_err, 2.0) << to_string(kind);
  }
}

TEST(Trajectory, StartsAtRestAndRampsUp) {
  const Trajectory t = make(TrajectoryKind::kLine);
  EXPECT_EQ(trajectory_state(t, 0).v_mps, 0.0);
  EXPECT_EQ(trajectory_state(t, -5).pose.x_mm, t.start.x_mm);
  EXPECT_NEAR(trajectory_state(t, 500'000'000).v_mps, 0.25, 1e-12);
  EXPECT_NEAR(trajectory_state(t, 5'000'000'000).v_mps, 0.5, 1e-12);
}

TEST(Trajectory, PassesOverLandmarks) {
  const LandmarkMap grid = default_landmark_grid();
  for (TrajectoryKind kind : kAll) {
    const Trajectory t = make(kind);
    int passed = 0;
    for (const auto& [id, e] : grid.entries) {
      double best = 1e300;
      for (std::int64_t tn = 0; tn < 200'000'000'000LL && tn * 0.5e-6 < t.length_mm + 1000;
           tn += 20'000'000) {
        const Pose2 p = trajectory_state(t, tn).pose;
        best = std::min(best, std::hypot(p.x_mm - e.pose.x_mm, p.y_mm - e.pose.y_mm));
      }
      if (best < 40.0) ++passed;
    }
    EXPECT_GE(passed, 4) << to_string(kind);
  }
}

TEST(Trajectory, RejectsBadParams) {
  TrajectoryParams p;
  Trajectory t;
  std::string err;
  p.speed_mps = 0.0;
  EXPECT_FALSE(make_trajectory(p, &t, &err));
  EXPECT_FALSE(err.empty());
  p = {};
  p.kind = TrajectoryKind::kLawnmower;
  p.lawnmower_rows = 3;
  EXPECT_FALSE(make_trajectory(p, &t, &err));
  p = {};
  p.grid_spacing_mm = std::nan("");
  EXPECT_FALSE(make_trajectory(p, &t, &err));
}

TEST(Odometry, ErrorFreeModelMatchesTruth) {
  const Trajectory t = make(TrajectoryKind::kFigure8);
  OdometryParams op;
  op.scale_error = op.scale_asymmetry = op.noise_mps = 0.0;
  op.slip_rate_per_s = 0.0;
  for (std::int64_t tn = 0; tn < 30'000'000'000LL; tn += 123'456'789) {
    const MotionState m = trajectory_state(t, tn);
    const OdometrySample o = odometry_sample(op, {}, OdometrySample{m.v_mps, m.omega_radps}, tn);
    EXPECT_NEAR(o.v_mps, m.v_mps, 1e-12);
    EXPECT_NEAR(o.omega_radps, m.omega_radps, 1e-12);
  }
}

TEST(Odometry, ScaleNoiseSlipAndDeterminism) {
  const Trajectory t = make(TrajectoryKind::kLine);
  OdometryParams op;
  op.slip_rate_per_s = 0.0;
  double sum_ratio = 0.0, sum_sq = 0.0;
  int n = 0;
  for (std::int64_t tn = 2'000'000'000; tn < 6'000'000'000LL; tn += 10'000'000) {
    const MotionState m = trajectory_state(t, tn);  // straight at 0.5 m/s
    ASSERT_EQ(m.omega_radps, 0.0);
    const OdometrySample o = odometry_sample(op, {}, OdometrySample{m.v_mps, m.omega_radps}, tn);
    EXPECT_EQ(o.v_mps, odometry_sample(op, {}, OdometrySample{m.v_mps, m.omega_radps}, tn)
                           .v_mps);  // pure function of t
    sum_ratio += o.v_mps / m.v_mps;
    sum_sq += (o.v_mps - 1.01 * m.v_mps) * (o.v_mps - 1.01 * m.v_mps);
    ++n;
  }
  EXPECT_NEAR(sum_ratio / n, 1.01, 0.001);  // documented 1 % scale error
  // v noise is the mean of two wheels: sigma / sqrt(2).
  EXPECT_NEAR(std::sqrt(sum_sq / n), 0.003 / std::sqrt(2.0), 0.0006);

  // Slip: deterministic events; during one the reported speed exceeds the truth a lot.
  op.slip_rate_per_s = 0.5;
  op.slip_excess = 0.25;  // harsh slip, well above the noise
  const auto ev = make_slip_events(op, 60'000'000'000LL);
  const auto ev2 = make_slip_events(op, 60'000'000'000LL);
  ASSERT_FALSE(ev.empty());
  ASSERT_EQ(ev.size(), ev2.size());
  EXPECT_EQ(ev[0].t_start_ns, ev2[0].t_start_ns);
  EXPECT_GT(ev.size(), 15u);
  EXPECT_LT(ev.size(), 50u);
  const std::int64_t mid = (ev[0].t_start_ns + ev[0].t_end_ns) / 2 + 3'000'000'000LL;
  auto shifted = ev;
  for (auto& e : shifted) {
    e.t_start_ns += 3'000'000'000LL;
    e.t_end_ns += 3'000'000'000LL;
  }
  op.noise_mps = 0.0;
  const MotionState m = trajectory_state(t, mid);
  const OdometrySample slipping =
      odometry_sample(op, shifted, OdometrySample{m.v_mps, m.omega_radps}, mid);
  const OdometrySample normal =
      odometry_sample(op, {}, OdometrySample{m.v_mps, m.omega_radps}, mid);
  EXPECT_NEAR(slipping.v_mps - normal.v_mps, 0.5 * 0.25 * m.v_mps, 0.01);
  EXPECT_GT(std::abs(slipping.omega_radps), 0.2);
}

namespace {

OdometryParams error_free(OdomSampleTiming timing) {
  OdometryParams op;
  op.scale_error = op.scale_asymmetry = op.noise_mps = 0.0;
  op.slip_rate_per_s = 0.0;
  op.timing = timing;
  return op;
}

// The lawnmower at 1 m/s; false where the trajectory cannot be made.
bool lawnmower_1mps(Trajectory* t) {
  TrajectoryParams tp;
  tp.kind = TrajectoryKind::kLawnmower;
  tp.speed_mps = 1.0;
  return make_trajectory(tp, t, nullptr);
}

// Time at which the vehicle reaches path length s_mm (after the start ramp).
std::int64_t time_at_s(const Trajectory& t, double s_mm) {
  const double v = t.params.speed_mps, a = t.params.accel_mps2;
  const double ramp_s = v / a, ramp_mm = 500.0 * v * v / a;
  return static_cast<std::int64_t>(std::llround((ramp_s + (s_mm - ramp_mm) / (1000.0 * v)) * 1e9));
}

}  // namespace

TEST(Odometry, SampleTimingNames) {
  for (OdomSampleTiming k : {OdomSampleTiming::kPeriodMean, OdomSampleTiming::kInstant}) {
    OdomSampleTiming back;
    ASSERT_TRUE(parse_odom_sample_timing(to_string(k), &back));
    EXPECT_EQ(back, k);
  }
  OdomSampleTiming k;
  EXPECT_FALSE(parse_odom_sample_timing("mean", &k));
  EXPECT_EQ(OdometryParams{}.timing, OdomSampleTiming::kPeriodMean);  // what controllers send
}

// Arc entry of the lawnmower (omega steps from 0 to v * curvature inside one 10 ms period): the
// period-mean sample integrates to exactly the heading the vehicle turned over the period; the
// instantaneous sample claims the whole period was turning.
TEST(Odometry, PeriodMeanIntegratesArcEntryExactly) {
  Trajectory t;
  ASSERT_TRUE(lawnmower_1mps(&t));
  ASSERT_EQ(t.segments[0].curvature_per_mm, 0.0);
  ASSERT_NE(t.segments[1].curvature_per_mm, 0.0);
  const std::int64_t entry = time_at_s(t, t.seg_start_s_mm[1]);
  const OdometryParams mean = error_free(OdomSampleTiming::kPeriodMean);
  const OdometryParams inst = error_free(OdomSampleTiming::kInstant);
  const double period_s = static_cast<double>(mean.period_ns) * 1e-9;
  for (const std::int64_t into : {1'000'000LL, 3'000'000LL, 7'000'000LL}) {
    const std::int64_t tn = entry + into;  // sample period [tn - 10 ms, tn] straddles the step
    const double turned = wrap_angle_rad(trajectory_state(t, tn).pose.theta_rad -
                                         trajectory_state(t, tn - mean.period_ns).pose.theta_rad);
    ASSERT_GT(std::abs(turned), 1e-4);
    EXPECT_NEAR(odometry_sample(mean, {}, t, tn).omega_radps * period_s, turned, 1e-9) << into;
    const double inst_turn = odometry_sample(inst, {}, t, tn).omega_radps * period_s;
    EXPECT_GT(std::abs(inst_turn - turned), 0.2 * std::abs(turned)) << into;
    // Distance too: the mean speed times the period is the distance driven.
    EXPECT_NEAR(odometry_sample(mean, {}, t, tn).v_mps * period_s * 1000.0,
                trajectory_state(t, tn).s_mm - trajectory_state(t, tn - mean.period_ns).s_mm, 1e-9);
  }
}

// Dead reckoning from error-free period-mean samples over a whole lawnmower lap (start ramp,
// twelve omega steps) ends where the vehicle is: heading exactly (the samples telescope), position
// to the arc-vs-chord error of constant-curvature integration. Instantaneous samples do not.
TEST(Odometry, PeriodMeanSamplesReproduceRoute) {
  Trajectory t;
  ASSERT_TRUE(lawnmower_1mps(&t));
  auto dead_reckon = [&](OdomSampleTiming timing, double* max_pos_mm, double* max_head_rad) {
    const OdometryParams op = error_free(timing);
    const double dt_s = static_cast<double>(op.period_ns) * 1e-9;
    Pose2 p = t.start;
    *max_pos_mm = *max_head_rad = 0.0;
    const std::int64_t end = time_at_s(t, t.length_mm) + 1'000'000'000;
    for (std::int64_t tn = op.period_ns; tn <= end; tn += op.period_ns) {
      const OdometrySample o = odometry_sample(op, {}, t, tn);
      const double ds = 1000.0 * o.v_mps * dt_s, dth = o.omega_radps * dt_s;
      // Exact for a constant-curvature period: chord length along the mid heading.
      const double chord = std::abs(dth) < 1e-12 ? ds : ds * std::sin(0.5 * dth) / (0.5 * dth);
      p.x_mm += chord * std::cos(p.theta_rad + 0.5 * dth);
      p.y_mm += chord * std::sin(p.theta_rad + 0.5 * dth);
      p.theta_rad = wrap_angle_rad(p.theta_rad + dth);
      const Pose2 truth = trajectory_state(t, tn).pose;
      *max_pos_mm = std::max(*max_pos_mm, std::hypot(p.x_mm - truth.x_mm, p.y_mm - truth.y_mm));
      *max_head_rad =
          std::max(*max_head_rad, std::abs(wrap_angle_rad(p.theta_rad - truth.theta_rad)));
    }
  };
  double pos_mm, head_rad;
  dead_reckon(OdomSampleTiming::kPeriodMean, &pos_mm, &head_rad);
  EXPECT_LT(head_rad, 1e-9);
  EXPECT_LT(pos_mm, 0.1);  // periods that straddle an arc entry/exit are not one arc
  dead_reckon(OdomSampleTiming::kInstant, &pos_mm, &head_rad);
  EXPECT_GT(head_rad, 1e-3);  // about v * k * period per step until the next step cancels it
  EXPECT_GT(pos_mm, 1.0);
}

TEST(DefaultMap, FileMatchesBuiltInGrid) {
  std::ifstream f(std::string(AGV_SOURCE_DIR) + "/tools/maps/default_grid.csv");
  ASSERT_TRUE(f) << "tools/maps/default_grid.csv missing";
  std::stringstream ss;
  ss << f.rdbuf();
  LandmarkMap m;
  std::string err;
  ASSERT_TRUE(parse_landmark_map(ss.str(), &m, &err)) << err;
  const LandmarkMap g = default_landmark_grid();
  ASSERT_EQ(m.entries.size(), 25u);
  ASSERT_EQ(m.entries.size(), g.entries.size());
  for (const auto& [id, e] : g.entries) {
    const LandmarkMapEntry* o = m.find(id);
    ASSERT_NE(o, nullptr);
    EXPECT_NEAR(o->pose.x_mm, e.pose.x_mm, 1e-9);
    EXPECT_NEAR(o->pose.y_mm, e.pose.y_mm, 1e-9);
    EXPECT_NEAR(wrap_angle_rad(o->pose.theta_rad - e.pose.theta_rad), 0.0, 1e-9);
  }
}

// The vehicle-calibration drive (docs/design/simulator.md): stops over landmarks 0..3 of row 0,
// turns on the spot there, and period-mean odometry dead-reckons it (turns included) exactly.
TEST(Trajectory, CalibrationDriveStopsAndTurnsOverLandmarks) {
  TrajectoryParams tp;
  tp.kind = TrajectoryKind::kCalibration;
  Trajectory t;
  ASSERT_TRUE(make_trajectory(tp, &t, nullptr));
  ASSERT_GT(t.moves.size(), 5u);
  EXPECT_LT(t.closure_error_mm, 1e-9);
  double max_off_landmark_mm = 0.0, turned = 0.0;
  int turns = 0;
  for (size_t i = 1; i < t.moves.size(); ++i) {
    // Every move starts standing over a landmark (20 mm lateral offset of the path).
    const Pose2 p = t.move_start_pose[i];
    const double lx = std::round(p.x_mm / 1000.0) * 1000.0;
    max_off_landmark_mm = std::max(max_off_landmark_mm, std::hypot(p.x_mm - lx, p.y_mm - 20.0));
    if (t.moves[i].rotate) {
      ++turns;
      turned += std::abs(t.moves[i].amount);
      // On the spot: position constant through the turn, v = 0.
      const auto t_mid =
          static_cast<std::int64_t>((t.move_start_t_s[i] + 0.5 * t.moves[i].duration_s()) * 1e9);
      const MotionState m = trajectory_state(t, t_mid);
      EXPECT_NEAR(m.pose.x_mm, p.x_mm, 1e-9);
      EXPECT_EQ(m.v_mps, 0.0);
      EXPECT_GT(std::abs(m.omega_radps), 0.1);
    }
  }
  EXPECT_LT(max_off_landmark_mm, 1e-6);
  EXPECT_GE(turns, 6);
  EXPECT_GT(turned, 4 * kPi);
  // Period-mean odometry integrates to the route over two blocks.
  const OdometryParams op = error_free(OdomSampleTiming::kPeriodMean);
  const double dt_s = static_cast<double>(op.period_ns) * 1e-9;
  Pose2 p = t.start;
  double max_pos = 0.0, max_head = 0.0;
  const auto end =
      static_cast<std::int64_t>((t.moves[0].duration_s() + 2 * t.block_duration_s) * 1e9);
  for (std::int64_t tn = op.period_ns; tn <= end; tn += op.period_ns) {
    const OdometrySample o = odometry_sample(op, {}, t, tn);
    const double ds = 1000.0 * o.v_mps * dt_s, dth = o.omega_radps * dt_s;
    p.x_mm += ds * std::cos(p.theta_rad + 0.5 * dth);
    p.y_mm += ds * std::sin(p.theta_rad + 0.5 * dth);
    p.theta_rad = wrap_angle_rad(p.theta_rad + dth);
    const Pose2 truth = trajectory_state(t, tn).pose;
    max_pos = std::max(max_pos, std::hypot(p.x_mm - truth.x_mm, p.y_mm - truth.y_mm));
    max_head = std::max(max_head, std::abs(wrap_angle_rad(p.theta_rad - truth.theta_rad)));
  }
  EXPECT_LT(max_head, 1e-9);
  EXPECT_LT(max_pos, 1e-6);
}
