// Fault class "duplicated and reordered odometry" of the fault-replay suite
// (tests/faults/README.md). A recording cannot hold it (odom.csv must be strictly increasing), so
// this drives the localizer core directly: the simulator's lawnmower odometry (1 m/s, default
// errors, period means) goes over the fake CAN bus as E2E-protected frames, some duplicated and
// some pairs swapped inside a fault window that contains a turn, with landmark fixes synthesized
// from the truth (vision-like noise, handed over 30 ms after exposure as `replay --fast` does). The
// same assertions as run_faults.py: no localized pose > 50 mm off the truth, recovery <= 0.5 s
// after the window when a landmark is in view by then, >= 99 % of ticks within 3 sigma and
// normalised-error RMS >= 0.2.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <random>
#include <string>
#include <vector>

#include "agv/can/fake_can.hpp"
#include "agv/localizer/localizer.hpp"
#include "agv/protocol/codec.hpp"
#include "agv/sim/render.hpp"
#include "agv/sim/trajectory.hpp"
#include "config.hpp"
#include "output_loop.hpp"

using namespace agv;

namespace {

// Assertions of the fault suite, as in run_faults.py.
constexpr double kMaxLocalizedErrMm = 50.0;
constexpr double kRecoveryOkMm = 20.0;
constexpr double kRecoveryMaxS = 0.5;
constexpr double kCoverageMin = 0.99;
constexpr double kNeesRmsMin = 0.2;

constexpr std::int64_t kT0Ns = 10'000'000'000LL;     // recording clock at the trajectory start
constexpr std::int64_t kPeriodNs = 10'000'000;       // odometry and output ticks
constexpr std::int64_t kFramePeriodNs = 50'000'000;  // 20 fps
constexpr std::int64_t kFixDelayNs = 30'000'000;     // replay.fix_delay_ms
constexpr std::int64_t kDurationNs = 24'000'000'000LL;
// Fault window (trajectory time): contains the second 180 degree turn (12.3..13.9 s).
constexpr std::int64_t kFaultStartNs = 11'000'000'000LL;
constexpr std::int64_t kFaultEndNs = 16'000'000'000LL;

enum class OdomFault { kNone, kDuplicated, kSwapped };

struct Result {
  double max_localized_err_mm = 0.0;
  double recovery_s = -1.0;  // -1: never
  bool landmark_in_view = false;
  double coverage = 0.0;
  double nees_rms = 0.0;
  int ticks = 0;
  protocol::OdometryCounters counters;
};

struct Fix {
  std::int64_t t_ns;
  vision::LandmarkFix fix;
};

// Fixes at 20 fps whenever a landmark centre is within +-50 mm along and +-30 mm across the
// vehicle's reference point (about what the camera decodes at 640x480), vision-like noise.
std::vector<Fix> make_fixes(const sim::Trajectory& traj) {
  const LandmarkMap map = sim::default_landmark_grid();
  std::mt19937_64 rng(5);
  std::normal_distribution<double> n01;
  const double s_xy = 0.05, s_th = 0.015 * kPi / 180.0;
  std::vector<Fix> out;
  for (std::int64_t t = 0; t <= kDurationNs; t += kFramePeriodNs) {
    const Pose2 p = sim::trajectory_state(traj, t).pose;
    for (const auto& [id, e] : map.entries) {
      const double dx = e.pose.x_mm - p.x_mm, dy = e.pose.y_mm - p.y_mm;
      const double along = dx * std::cos(p.theta_rad) + dy * std::sin(p.theta_rad);
      const double across = -dx * std::sin(p.theta_rad) + dy * std::cos(p.theta_rad);
      if (std::abs(along) > 50.0 || std::abs(across) > 30.0) continue;
      Fix f{kT0Ns + t, {}};
      f.fix.status = vision::FixStatus::kOk;
      f.fix.landmark_id = id;
      f.fix.vehicle_in_world = {p.x_mm + s_xy * n01(rng), p.y_mm + s_xy * n01(rng),
                                wrap_angle_rad(p.theta_rad + s_th * n01(rng))};
      f.fix.cov_world = Eigen::Matrix3d::Zero();
      f.fix.cov_world(0, 0) = f.fix.cov_world(1, 1) = s_xy * s_xy;
      f.fix.cov_world(2, 2) = s_th * s_th;
      out.push_back(f);
    }
  }
  return out;
}

Result run(OdomFault fault) {
  sim::TrajectoryParams tp;
  tp.kind = sim::TrajectoryKind::kLawnmower;
  tp.speed_mps = 1.0;
  tp.lawnmower_rows = 4;
  sim::Trajectory traj;
  EXPECT_TRUE(sim::make_trajectory(tp, &traj, nullptr));
  sim::OdometryParams op;
  op.seed = 11;
  const std::vector<sim::SlipEvent> slips = sim::make_slip_events(op, kDurationNs);
  const std::vector<Fix> fixes = make_fixes(traj);

  config::Config cfg;
  cfg.can.odometry_mode = agv::protocol::OdometryMode::kTwist;
  const protocol::ProtocolConfig pc = config::protocol_config(cfg);
  can::FakeCanNetwork net;
  auto controller = net.create_endpoint(16);  // pose frames sent back to it are dropped: fine
  auto localizer = net.create_endpoint(256);
  localizer::Localizer out(app::localizer_config(cfg));

  auto frame_for = [&](std::int64_t k) {
    const std::int64_t t = k * kPeriodNs;
    const sim::OdometrySample o = sim::odometry_sample(op, slips, traj, t);
    agv::hal::CanFrame f;
    protocol::encode_odometry(pc, o.v_mps, o.omega_radps, static_cast<std::uint8_t>(k % 15), &f);
    return f;
  };
  auto send_at = [&](std::int64_t t_ns, const hal::CanFrame& f) {
    net.set_time_ns(t_ns);
    controller->send(f);
  };

  Result r;
  double sum_sq = 0.0;
  int n_sq = 0, n_cov = 0;
  std::size_t next_fix = 0;
  std::int64_t good_ns = -1, view_ns = -1;
  const std::int64_t n_ticks = kDurationNs / kPeriodNs;
  for (std::int64_t k = 0; k <= n_ticks; ++k) {
    const std::int64_t t = k * kPeriodNs;
    const std::int64_t rx_ns = kT0Ns + t - 1'000'000;  // the frame arrives 1 ms before the tick
    const bool in_window = t >= kFaultStartNs && t < kFaultEndNs;
    if (in_window && fault == OdomFault::kDuplicated && k % 3 == 0) {
      send_at(rx_ns, frame_for(k));
      send_at(rx_ns + 500'000, frame_for(k));  // the same frame again 0.5 ms later
    } else if (in_window && fault == OdomFault::kSwapped && k % 10 == 0) {
      send_at(rx_ns, frame_for(k + 1));  // k + 1 overtakes k ...
    } else if (in_window && fault == OdomFault::kSwapped && k % 10 == 1) {
      send_at(rx_ns, frame_for(k - 1));  // ... which arrives one period late
    } else {
      send_at(rx_ns, frame_for(k));
    }
    hal::CanFrame rx;
    while (localizer->receive(&rx, 0) == hal::CanStatus::kOk) out.on_can_frame(rx);
    while (next_fix < fixes.size() && fixes[next_fix].t_ns + kFixDelayNs <= kT0Ns + t) {
      out.on_fix(fixes[next_fix].fix, fixes[next_fix].t_ns);
      ++next_fix;
    }
    const app::TickRecord rec = out.tick(kT0Ns + t);
    const fusion::PoseEstimate& e = rec.estimate;
    if (!e.valid) continue;
    const Pose2 truth = sim::trajectory_state(traj, t).pose;
    const double ex = e.pose.x_mm - truth.x_mm, ey = e.pose.y_mm - truth.y_mm;
    const double eth = wrap_angle_rad(e.pose.theta_rad - truth.theta_rad);
    const double err = std::hypot(ex, ey);
    const bool localized = e.health == fusion::HealthState::kLocalized;
    if (localized) r.max_localized_err_mm = std::max(r.max_localized_err_mm, err);
    if (t >= kFaultEndNs && good_ns < 0 && localized && err <= kRecoveryOkMm) good_ns = t;
    if (t < kFaultStartNs) continue;
    const double sx = std::sqrt(e.cov(0, 0)), sy = std::sqrt(e.cov(1, 1));
    const double sth = std::sqrt(e.cov(2, 2));
    if (std::abs(ex) <= 3 * sx && std::abs(ey) <= 3 * sy && std::abs(eth) <= 3 * sth) ++n_cov;
    for (const double q : {ex / sx, ey / sy, eth / sth}) sum_sq += q * q;
    n_sq += 3;
    ++r.ticks;
  }
  for (const Fix& f : fixes) {
    if (f.t_ns >= kT0Ns + kFaultEndNs) {
      view_ns = f.t_ns - kT0Ns;
      break;
    }
  }
  r.landmark_in_view = view_ns >= 0 && view_ns - kFaultEndNs <= kRecoveryMaxS * 1e9;
  r.recovery_s = good_ns < 0 ? -1.0 : static_cast<double>(good_ns - kFaultEndNs) * 1e-9;
  r.coverage = r.ticks > 0 ? static_cast<double>(n_cov) / r.ticks : 0.0;
  r.nees_rms = n_sq > 0 ? std::sqrt(sum_sq / n_sq) : 0.0;
  r.counters = out.odometry_decoder().counters();
  std::printf(
      "| %s | %.1f | %s%.2f%s | %.1f | %.4f | odometry frames accepted %llu, repeated "
      "%llu, counter jumps %llu, bad counter %llu, lost %llu |\n",
      fault == OdomFault::kNone         ? "odom_can_clean"
      : fault == OdomFault::kDuplicated ? "odom_duplicated"
                                        : "odom_swapped",
      r.max_localized_err_mm, good_ns < 0 ? "never " : "", r.recovery_s,
      r.landmark_in_view ? "" : " (no landmark in 0.5 s)", 100.0 * r.coverage, r.nees_rms,
      static_cast<unsigned long long>(r.counters.accepted),
      static_cast<unsigned long long>(r.counters.repeated),
      static_cast<unsigned long long>(r.counters.counter_jump),
      static_cast<unsigned long long>(r.counters.bad_counter),
      static_cast<unsigned long long>(r.counters.lost_frames));
  return r;
}

void expect_issue13_properties(const Result& r) {
  EXPECT_GT(r.ticks, 500);
  EXPECT_LE(r.max_localized_err_mm, kMaxLocalizedErrMm);
  if (r.landmark_in_view) {
    EXPECT_GE(r.recovery_s, 0.0) << "never recovered";
    EXPECT_LE(r.recovery_s, kRecoveryMaxS);
  }
  EXPECT_GE(r.coverage, kCoverageMin);
  EXPECT_GE(r.nees_rms, kNeesRmsMin);
}

}  // namespace

TEST(OdometryFaults, WindowContainsATurn) {
  sim::TrajectoryParams tp;
  tp.kind = sim::TrajectoryKind::kLawnmower;
  tp.speed_mps = 1.0;
  sim::Trajectory traj;
  ASSERT_TRUE(sim::make_trajectory(tp, &traj, nullptr));
  double max_omega = 0.0;
  for (std::int64_t t = kFaultStartNs; t < kFaultEndNs; t += kPeriodNs) {
    max_omega = std::max(max_omega, std::abs(sim::trajectory_state(traj, t).omega_radps));
  }
  EXPECT_GT(max_omega, 1.0);
}

// The control: the same run without the fault (if this fails, the fault rows say nothing about
// duplicates or reordering).
TEST(OdometryFaults, CleanCanOdometry) {
  const Result r = run(OdomFault::kNone);
  EXPECT_EQ(r.counters.rejected(), 0u);
  expect_issue13_properties(r);
}

TEST(OdometryFaults, DuplicatedFrames) {
  const Result r = run(OdomFault::kDuplicated);
  EXPECT_GT(r.counters.repeated, 100u);  // the duplicates did reach the decoder
  expect_issue13_properties(r);
}

TEST(OdometryFaults, SwappedPairs) {
  const Result r = run(OdomFault::kSwapped);
  EXPECT_GT(r.counters.rejected() + r.counters.lost_frames, 40u);  // the swaps reached it
  expect_issue13_properties(r);
}
