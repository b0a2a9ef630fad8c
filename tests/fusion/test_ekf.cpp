#include <gtest/gtest.h>

#include <Eigen/Eigenvalues>
#include <cmath>
#include <cstdint>
#include <limits>
#include <stdexcept>

#include "agv/common/geometry.hpp"
#include "agv/fusion/ekf.hpp"
#include "ekf_test_util.hpp"

using namespace agv;
using namespace agv::fusion;
using namespace agv::fusion::test;

namespace {

// Ground truth for a straight drive along +x at 1 m/s from the origin.
Pose2 straight_truth(std::int64_t t_ns) {
  return {1000.0 * static_cast<double>(t_ns) * 1e-9, 0.0, 0.0};
}

void expect_same_estimate(const PoseEstimate& a, const PoseEstimate& b, double tol) {
  ASSERT_EQ(a.valid, b.valid);
  EXPECT_NEAR(a.pose.x_mm, b.pose.x_mm, tol);
  EXPECT_NEAR(a.pose.y_mm, b.pose.y_mm, tol);
  EXPECT_NEAR(a.pose.theta_rad, b.pose.theta_rad, tol);
  EXPECT_NEAR(a.v_mps, b.v_mps, tol);
  EXPECT_NEAR(a.omega_radps, b.omega_radps, tol);
  EXPECT_LE((a.cov - b.cov).cwiseAbs().maxCoeff(), tol);
}

bool spd(const StateCov& P) {
  if ((P - P.transpose()).cwiseAbs().maxCoeff() > 1e-12 * P.cwiseAbs().maxCoeff()) return false;
  const Eigen::SelfAdjointEigenSolver<StateCov> eig(P);
  return eig.eigenvalues()(0) > 0.0;
}

}  // namespace

TEST(FusionEkf, InvalidUntilFirstFixThenInitialisesFromIt) {
  Ekf ekf{EkfConfig{}};
  EXPECT_FALSE(ekf.estimate_at(0).valid);
  EXPECT_EQ(ekf.estimate_at(0).health, HealthState::kUninitialized);
  ASSERT_TRUE(ekf.add_odometry(0, 1.0, 0.0));
  ASSERT_TRUE(ekf.add_odometry(10 * kMs, 1.0, 0.0));
  EXPECT_FALSE(ekf.estimate_at(10 * kMs).valid);
  EXPECT_EQ(ekf.counters().odom_stored_uninitialised, 2u);

  const Pose2 z{500.0, -20.0, deg_to_rad(10.0)};
  EXPECT_EQ(ekf.add_fix(10 * kMs, z, fix_cov()), FixOutcome::kInitialised);
  const PoseEstimate e = ekf.estimate_at(10 * kMs);
  ASSERT_TRUE(e.valid);
  EXPECT_NEAR(e.pose.x_mm, 500.0, 1e-9);
  EXPECT_NEAR(e.pose.y_mm, -20.0, 1e-9);
  EXPECT_NEAR(e.pose.theta_rad, deg_to_rad(10.0), 1e-12);
  EXPECT_NEAR(e.v_mps, 1.0, 1e-12);  // taken from the odometry at the fix time
  EXPECT_EQ(e.health, HealthState::kLocalized);
  EXPECT_EQ(ekf.counters().fixes_initialised, 1u);
  EXPECT_TRUE(ekf.take_flags() & flags::kInitialised);
}

TEST(FusionEkf, DelayedInitialisationReplaysNewerOdometry) {
  Ekf ekf{EkfConfig{}};
  for (int i = 0; i <= 10; ++i) ASSERT_TRUE(ekf.add_odometry(i * 10 * kMs, 1.0, 0.0));
  // Fix exposed at 30 ms, arrives after odometry up to 100 ms.
  EXPECT_EQ(ekf.add_fix(30 * kMs, {30.0, 0.0, 0.0}, fix_cov()), FixOutcome::kInitialised);
  const PoseEstimate e = ekf.estimate_at(100 * kMs);
  ASSERT_TRUE(e.valid);
  EXPECT_NEAR(e.pose.x_mm, 100.0, 1e-6);
  // Before the initialisation time there is no estimate.
  EXPECT_FALSE(ekf.estimate_at(20 * kMs).valid);
}

TEST(FusionEkf, StraightLineDeadReckoning) {
  Ekf ekf{EkfConfig{}};
  ASSERT_TRUE(ekf.add_odometry(0, 1.0, 0.0));
  ASSERT_EQ(ekf.add_fix(0, {0.0, 0.0, 0.0}, fix_cov()), FixOutcome::kInitialised);
  for (int i = 1; i <= 100; ++i) ASSERT_TRUE(ekf.add_odometry(i * 10 * kMs, 1.0, 0.0));
  const PoseEstimate e = ekf.estimate_at(1 * kS);
  EXPECT_NEAR(e.pose.x_mm, 1000.0, 1e-6);
  EXPECT_NEAR(e.pose.y_mm, 0.0, 1e-9);
  EXPECT_NEAR(e.pose.theta_rad, 0.0, 1e-12);
  // Prediction beyond the newest odometry continues the motion.
  EXPECT_NEAR(ekf.estimate_at(1 * kS + 50 * kMs).pose.x_mm, 1050.0, 1e-6);
  // Along-track uncertainty grows more than cross-track (configured 5 vs 2 mm/sqrt(m)).
  EXPECT_GT(e.cov(0, 0), e.cov(1, 1));
}

TEST(FusionEkf, ConstantTurnFollowsTheCircle) {
  Ekf ekf{EkfConfig{}};
  const double v = 0.5, w = 0.5;  // radius 1000 mm, centre (0, 1000)
  ASSERT_TRUE(ekf.add_odometry(0, v, w));
  ASSERT_EQ(ekf.add_fix(0, {0.0, 0.0, 0.0}, fix_cov()), FixOutcome::kInitialised);
  const double quarter_s = (kPi / 2.0) / w;
  const int n = static_cast<int>(std::round(quarter_s / 0.01));
  std::int64_t t = 0;
  for (int i = 1; i <= n; ++i) {
    t = static_cast<std::int64_t>(std::llround(i * quarter_s / n * 1e9));
    ASSERT_TRUE(ekf.add_odometry(t, v, w));
  }
  const PoseEstimate e = ekf.estimate_at(t);
  EXPECT_NEAR(e.pose.x_mm, 1000.0, 1e-3);
  EXPECT_NEAR(e.pose.y_mm, 1000.0, 1e-3);
  EXPECT_NEAR(e.pose.theta_rad, kPi / 2.0, 1e-6);
}

TEST(FusionEkf, FixCorrectsDriftedPose) {
  Ekf ekf{EkfConfig{}};
  ASSERT_TRUE(ekf.add_odometry(0, 1.0, 0.0));
  ASSERT_EQ(ekf.add_fix(0, {0.0, 0.0, 0.0}, fix_cov()), FixOutcome::kInitialised);
  // Odometry reads 1 % high: after 1 s the dead-reckoned pose is 10 mm ahead.
  for (int i = 1; i <= 100; ++i) ASSERT_TRUE(ekf.add_odometry(i * 10 * kMs, 1.01, 0.0));
  // (Part of the 1 % is attributed to the uncertain odometry scale state already.)
  EXPECT_NEAR(ekf.estimate_at(kS).pose.x_mm, 1010.0, 1.0);
  EXPECT_EQ(ekf.add_fix(kS, {1000.0, 1.0, deg_to_rad(0.05)}, fix_cov()), FixOutcome::kFused);
  const PoseEstimate e = ekf.estimate_at(kS);
  EXPECT_NEAR(e.pose.x_mm, 1000.0, 0.1);
  EXPECT_NEAR(e.pose.y_mm, 1.0, 0.1);
  // The fix's 1 mm across the travel also says something of the heading over the metre driven
  // (their correlation), so the heading lands a little beyond the fix's own 0.05 deg.
  EXPECT_NEAR(e.pose.theta_rad, deg_to_rad(0.05), deg_to_rad(0.02));
  EXPECT_LT(e.position_sigma_mm, 0.5);
  EXPECT_EQ(ekf.counters().fixes_fused, 1u);
}

TEST(FusionEkf, GatedOutlierDoesNotMoveThePose) {
  Ekf ekf{EkfConfig{}};
  EXPECT_NEAR(ekf.gate_threshold(), 16.266, 1e-3);
  ASSERT_TRUE(ekf.add_odometry(0, 1.0, 0.0));
  ASSERT_EQ(ekf.add_fix(0, {0.0, 0.0, 0.0}, fix_cov()), FixOutcome::kInitialised);
  for (int i = 1; i <= 100; ++i) ASSERT_TRUE(ekf.add_odometry(i * 10 * kMs, 1.0, 0.0));
  ekf.take_flags();
  const PoseEstimate before = ekf.estimate_at(kS);
  // Wrong coordinates (neighbouring landmark), a 40 mm offset, a 90 deg heading misread.
  EXPECT_EQ(ekf.add_fix(kS, {2000.0, 0.0, 0.0}, fix_cov()), FixOutcome::kRejectedGate);
  EXPECT_GT(ekf.last_fix_mahalanobis_sq(), 1000.0);
  EXPECT_EQ(ekf.add_fix(kS, {1000.0, 40.0, 0.0}, fix_cov()), FixOutcome::kRejectedGate);
  EXPECT_EQ(ekf.add_fix(kS, {1000.0, 0.0, kPi / 2}, fix_cov()), FixOutcome::kRejectedGate);
  expect_same_estimate(ekf.estimate_at(kS), before, 0.0);
  EXPECT_EQ(ekf.counters().fixes_rejected_gate, 3u);
  EXPECT_EQ(ekf.counters().fixes_fused, 0u);
  const std::uint16_t f = ekf.take_flags();
  EXPECT_TRUE(f & flags::kRejectedGate);
  EXPECT_FALSE(f & flags::kFusedFix);
  // A good fix is still accepted afterwards.
  EXPECT_EQ(ekf.add_fix(kS, {1002.0, 0.5, 0.0}, fix_cov()), FixOutcome::kFused);
}

TEST(FusionEkf, GateProbabilityIsConfigurable) {
  EkfConfig c;
  c.fix.gate_probability = 0.95;
  EXPECT_NEAR(Ekf{c}.gate_threshold(), 7.815, 1e-3);
}

TEST(FusionEkf, HeadingInnovationIsWrapped) {
  Ekf ekf{EkfConfig{}};
  ASSERT_TRUE(ekf.add_odometry(0, 0.0, 0.0));
  ASSERT_EQ(ekf.add_fix(0, {0.0, 0.0, -kPi + 0.001}, fix_cov(0.2, 0.5)), FixOutcome::kInitialised);
  ASSERT_TRUE(ekf.add_odometry(10 * kMs, 0.0, 0.0));
  // pi - 0.001 is 0.002 rad from -pi + 0.001, not 2 pi - 0.002.
  EXPECT_EQ(ekf.add_fix(10 * kMs, {0.0, 0.0, kPi - 0.001}, fix_cov(0.2, 0.5)), FixOutcome::kFused);
  const PoseEstimate e = ekf.estimate_at(10 * kMs);
  EXPECT_GT(std::abs(e.pose.theta_rad), kPi - 0.002);
  EXPECT_LE(e.pose.theta_rad, kPi);
  EXPECT_GT(e.pose.theta_rad, -kPi);
}

namespace {

// Drives straight at 1 m/s with odometry every 10 ms (1 % scale error, small yaw drift) and a fix
// every 250 ms; each fix is handed to the filter `delay_samples` odometry samples late.
Ekf run_with_fix_delay(int delay_samples) {
  Ekf ekf{EkfConfig{}};
  struct Pending {
    std::int64_t t;
    Pose2 z;
    int due;
  };
  Pending pending[8];
  int n_pending = 0;
  ekf.add_odometry(0, 1.01, 0.002);
  ekf.add_fix(0, straight_truth(0), fix_cov());
  for (int i = 1; i <= 340; ++i) {  // the last fix (3 s) is delivered by 3.3 s at the latest
    const std::int64_t t = i * 10 * kMs;
    ekf.add_odometry(t, 1.01, 0.002);
    if (i % 25 == 0 && i <= 300) {
      const Pose2 truth = straight_truth(t);
      pending[n_pending++] = {t, {truth.x_mm + 0.1, truth.y_mm - 0.05, 1e-4}, i + delay_samples};
    }
    for (int k = 0; k < n_pending;) {
      if (pending[k].due <= i) {
        EXPECT_EQ(ekf.add_fix(pending[k].t, pending[k].z, fix_cov()), FixOutcome::kFused);
        pending[k] = pending[--n_pending];
      } else {
        ++k;
      }
    }
  }
  return ekf;
}

}  // namespace

TEST(FusionEkf, DelayedFixesGiveTheSameStateAsOnTimeFixes) {
  const Ekf on_time = run_with_fix_delay(0);
  const Ekf late = run_with_fix_delay(5);        // 50 ms late
  const Ekf very_late = run_with_fix_delay(30);  // 300 ms: later fixes overtake earlier ones
  EXPECT_EQ(on_time.counters().fixes_delayed, 0u);
  EXPECT_GT(late.counters().fixes_delayed, 0u);
  EXPECT_GT(late.counters().events_replayed, 0u);
  const std::int64_t t_end = 3400 * kMs;
  expect_same_estimate(late.estimate_at(t_end), on_time.estimate_at(t_end), 1e-9);
  expect_same_estimate(very_late.estimate_at(t_end), on_time.estimate_at(t_end), 1e-9);
  // And within the history, too.
  expect_same_estimate(late.estimate_at(t_end - 200 * kMs), on_time.estimate_at(t_end - 200 * kMs),
                       1e-9);
  EXPECT_EQ(late.counters().fixes_fused, on_time.counters().fixes_fused);
}

TEST(FusionEkf, FixOlderThanHistoryIsRejectedNotApplied) {
  EkfConfig c;
  c.fix.max_delay_ns = 200 * kMs;
  Ekf ekf{c};
  ekf.add_odometry(0, 1.0, 0.0);
  ekf.add_fix(0, {0.0, 0.0, 0.0}, fix_cov());
  for (int i = 1; i <= 100; ++i) ekf.add_odometry(i * 10 * kMs, 1.0, 0.0);
  const PoseEstimate before = ekf.estimate_at(kS);
  EXPECT_EQ(ekf.add_fix(700 * kMs, {700.0, 0.0, 0.0}, fix_cov()), FixOutcome::kRejectedTooOld);
  expect_same_estimate(ekf.estimate_at(kS), before, 0.0);
  EXPECT_EQ(ekf.counters().fixes_rejected_too_old, 1u);
  EXPECT_TRUE(ekf.take_flags() & flags::kRejectedTooOld);
  EXPECT_EQ(ekf.add_fix(900 * kMs, {900.0, 0.0, 0.0}, fix_cov()), FixOutcome::kFused);

  // Capacity, not time, limits the horizon: 16 events at 10 ms cover only 150 ms.
  EkfConfig small;
  small.core.history_capacity = 16;
  Ekf ekf2{small};
  ekf2.add_odometry(0, 1.0, 0.0);
  ekf2.add_fix(0, {0.0, 0.0, 0.0}, fix_cov());
  for (int i = 1; i <= 100; ++i) ekf2.add_odometry(i * 10 * kMs, 1.0, 0.0);
  EXPECT_GT(ekf2.counters().history_overwrites, 0u);
  EXPECT_EQ(ekf2.add_fix(800 * kMs, {800.0, 0.0, 0.0}, fix_cov()), FixOutcome::kRejectedTooOld);
  EXPECT_EQ(ekf2.add_fix(900 * kMs, {900.0, 0.0, 0.0}, fix_cov()), FixOutcome::kFused);
  // Queries older than the kept history give no estimate rather than a wrong one.
  EXPECT_FALSE(ekf2.estimate_at(500 * kMs).valid);
}

TEST(FusionEkf, KidnapReinitialisesAfterAgreeingFixes) {
  Ekf ekf{EkfConfig{}};
  ekf.add_odometry(0, 1.0, 0.0);
  ekf.add_fix(0, {0.0, 0.0, 0.0}, fix_cov());
  // The vehicle was carried to (5000, 3000) facing +y; odometry still says 1 m/s straight.
  // Its true pose at time t (s) is (5000, 3000 + 1000 t', 90 deg) with t' from 1 s.
  auto kidnapped = [](std::int64_t t) {
    return Pose2{5000.0, 3000.0 + 1000.0 * (static_cast<double>(t - kS) * 1e-9), kPi / 2};
  };
  FixOutcome last = FixOutcome::kFused;
  int n_fix = 0;
  std::int64_t t_re = 0;
  for (int i = 1; i <= 600; ++i) {
    const std::int64_t t = i * 10 * kMs;
    ekf.add_odometry(t, 1.0, 0.0);
    if (t >= kS && i % 50 == 0) {  // a fix every 0.5 s
      last = ekf.add_fix(t, kidnapped(t), fix_cov());
      ++n_fix;
      t_re = t;
      if (last == FixOutcome::kReinitialised) break;
      EXPECT_EQ(last, FixOutcome::kRejectedGate);
    }
  }
  EXPECT_EQ(last, FixOutcome::kReinitialised);
  // Three agreeing fixes (kidnap_fixes) were there after 1 s; the track had to last
  // kidnap_min_duration_ns (3 s) too (fixes at 1.0, 1.5, ..., 4.0 s) unless the filter's own
  // position became worthless first (sigma > 4x the lost limit: the uncalibrated 3 % speed scale
  // and 1.5 deg/s yaw bias priors do that after ~3.5 s without a fix), which allows it earlier.
  EXPECT_GE(n_fix, 3);
  EXPECT_LE(t_re, 4 * kS);
  EXPECT_EQ(ekf.counters().reinitialisations, 1u);
  EXPECT_TRUE(ekf.take_flags() & flags::kReinitialised);
  const PoseEstimate e = ekf.estimate_at(t_re);
  EXPECT_NEAR(e.pose.x_mm, kidnapped(t_re).x_mm, 1.0);
  EXPECT_NEAR(e.pose.y_mm, kidnapped(t_re).y_mm, 1.0);
  EXPECT_NEAR(e.pose.theta_rad, kPi / 2, 1e-3);
  // Subsequent fixes on the new track are fused normally.
  ekf.add_odometry(t_re + 10 * kMs, 1.0, 0.0);
  EXPECT_EQ(ekf.add_fix(t_re + 10 * kMs, kidnapped(t_re + 10 * kMs), fix_cov()),
            FixOutcome::kFused);
  // Fixes from before the re-initialisation are refused.
  EXPECT_EQ(ekf.add_fix(t_re - 100 * kMs, kidnapped(t_re - 100 * kMs), fix_cov()),
            FixOutcome::kRejectedTooOld);
}

TEST(FusionEkf, TransientConsistentDisagreementDoesNotKidnap) {
  // A camera clock glitch: 2 s of fixes stamped 300 ms late look like a vehicle 300 mm behind,
  // consistent with each other over three landmarks. Shorter than kidnap_min_duration_ns: the
  // pose stays, and fixes agree again after it.
  Ekf ekf{EkfConfig{}};
  ekf.add_odometry(0, 1.0, 0.0);
  ekf.add_fix(0, {0.0, 0.0, 0.0}, fix_cov());
  for (int i = 1; i <= 500; ++i) {
    const std::int64_t t = i * 10 * kMs;
    ekf.add_odometry(t, 1.0, 0.0);
    if (i % 50 == 0) {
      const bool glitch = t >= 2 * kS && t < 4 * kS;
      const double x = 1e-6 * static_cast<double>(t) - (glitch ? 300.0 : 0.0);
      const FixOutcome o = ekf.add_fix(t, {x, 0.0, 0.0}, fix_cov());
      EXPECT_EQ(o, glitch ? FixOutcome::kRejectedGate : FixOutcome::kFused) << t;
    }
  }
  EXPECT_EQ(ekf.counters().reinitialisations, 0u);
}

TEST(FusionEkf, RepeatedMisreadOfOneLandmarkDoesNotHijackThePose) {
  Ekf ekf{EkfConfig{}};
  ekf.add_odometry(0, 1.0, 0.0);
  ekf.add_fix(0, {0.0, 0.0, 0.0}, fix_cov());
  // A misprinted landmark (coordinates 1 m off) seen in five frames 33 ms apart: the fixes agree
  // with each other, but they are one landmark, so they count once towards kidnap_fixes.
  for (int i = 1; i <= 120; ++i) {
    const std::int64_t t = i * 10 * kMs;
    ekf.add_odometry(t, 1.0, 0.0);
  }
  for (int k = 0; k < 5; ++k) {
    const std::int64_t t = kS + k * 33 * kMs;
    EXPECT_EQ(
        ekf.add_fix(t, {1000.0 * 1e-9 * static_cast<double>(t) + 1000.0, 0.0, 0.0}, fix_cov()),
        FixOutcome::kRejectedGate);
  }
  EXPECT_EQ(ekf.counters().reinitialisations, 0u);
  // Fixes that disagree with each other never re-initialise either.
  EkfConfig c;
  c.recovery.kidnap_min_separation_mm = 0.0;
  Ekf ekf2{c};
  ekf2.add_odometry(0, 1.0, 0.0);
  ekf2.add_fix(0, {0.0, 0.0, 0.0}, fix_cov());
  for (int i = 1; i <= 300; ++i) {
    const std::int64_t t = i * 10 * kMs;
    ekf2.add_odometry(t, 1.0, 0.0);
    if (i % 20 == 0) {
      const double off = (i / 20) % 2 == 0 ? 1000.0 : -1000.0;
      EXPECT_EQ(ekf2.add_fix(t, {1e-6 * static_cast<double>(t) + off, 0.0, 0.0}, fix_cov()),
                FixOutcome::kRejectedGate);
    }
  }
  EXPECT_EQ(ekf2.counters().reinitialisations, 0u);
}

TEST(FusionEkf, LongDeadReckoningKeepsCovarianceSpdAndGrowing) {
  EkfConfig c;
  c.health.lost_position_sigma_mm = 1e9;
  c.health.lost_heading_sigma_rad = 1e9;
  Ekf ekf{c};
  ekf.add_odometry(0, 1.0, 0.0);
  ekf.add_fix(0, {0.0, 0.0, 0.0}, fix_cov());
  double prev_pos_var = 0.0, prev_th_var = 0.0;
  for (int i = 1; i <= 30000; ++i) {  // 300 s, with turns
    const std::int64_t t = i * 10 * kMs;
    // Straight stretches and S-bends (a full circle would legitimately shrink the position
    // covariance again: a heading error only rotates a closed circle about its start).
    const int phase = (i / 200) % 4;
    const double w = phase == 1 ? 0.3 : (phase == 3 ? -0.3 : 0.0);
    ASSERT_TRUE(ekf.add_odometry(t, 1.0, w));
    if (i % 500 == 0) {
      const PoseEstimate e = ekf.estimate_at(t);
      ASSERT_TRUE(spd(e.cov)) << "at step " << i;
      const double pos_var = e.cov(0, 0) + e.cov(1, 1);
      EXPECT_GT(pos_var, prev_pos_var);
      EXPECT_GT(e.cov(2, 2), prev_th_var);
      prev_pos_var = pos_var;
      prev_th_var = e.cov(2, 2);
    }
  }
  EXPECT_GT(std::sqrt(prev_pos_var), 100.0);
}

TEST(FusionEkf, HealthTransitions) {
  EkfConfig c;
  c.health.localized_timeout_ns = 2 * kS;
  c.health.odom_timeout_ns = 100 * kMs;
  c.health.lost_position_sigma_mm = 20.0;
  c.odometry.estimate_calibration = false;  // growth from Q alone, see the calibration test
  Ekf ekf{c};
  EXPECT_EQ(ekf.estimate_at(0).health, HealthState::kUninitialized);
  ekf.add_odometry(0, 1.0, 0.0);
  ekf.add_fix(0, {0.0, 0.0, 0.0}, fix_cov());
  PoseEstimate e = ekf.estimate_at(0);
  EXPECT_EQ(e.health, HealthState::kLocalized);
  EXPECT_EQ(e.time_since_fix_ns, 0);
  // Dead reckoning after 2 s without fixes; lost when the position sigma passes 20 mm.
  bool saw_dr = false, saw_lost = false;
  std::int64_t t_dr = 0, t_lost = 0;
  for (int i = 1; i <= 3000 && !saw_lost; ++i) {
    const std::int64_t t = i * 10 * kMs;
    ekf.add_odometry(t, 1.0, 0.0);
    e = ekf.estimate_at(t);
    EXPECT_EQ(e.time_since_fix_ns, t);
    if (!saw_dr && e.health == HealthState::kDeadReckoning) {
      saw_dr = true;
      t_dr = t;
    }
    if (e.health == HealthState::kLost) {
      saw_lost = true;
      t_lost = t;
      EXPECT_TRUE(e.flags & flags::kCovarianceLimit);
      EXPECT_FALSE(e.flags & flags::kOdomTimeout);
      EXPECT_GT(e.position_sigma_mm, 20.0);
    }
  }
  ASSERT_TRUE(saw_dr);
  ASSERT_TRUE(saw_lost);
  EXPECT_EQ(t_dr, 2 * kS + 10 * kMs);
  // Mostly heading random walk (0.3 deg/sqrt(s)) integrated over the distance.
  EXPECT_GT(t_lost, t_dr);
  EXPECT_LT(t_lost, 25 * kS);

  // A fix brings it back; odometry silence makes it lost again. (The yaw rate may have changed
  // right after the last sample, so 100 ms of silence also widens the heading sigma to ~4.6 deg;
  // a looser heading limit keeps this check on the timeout alone.)
  EkfConfig c2 = c;
  c2.health.lost_heading_sigma_rad = deg_to_rad(10.0);
  Ekf ekf2{c2};
  ekf2.add_odometry(0, 1.0, 0.0);
  ekf2.add_fix(0, {0.0, 0.0, 0.0}, fix_cov());
  ekf2.add_odometry(50 * kMs, 1.0, 0.0);
  EXPECT_EQ(ekf2.estimate_at(150 * kMs).health, HealthState::kLocalized);
  const PoseEstimate timed_out = ekf2.estimate_at(151 * kMs);
  EXPECT_EQ(timed_out.health, HealthState::kLost);
  EXPECT_TRUE(timed_out.flags & flags::kOdomTimeout);
  EXPECT_TRUE(timed_out.valid);  // still a prediction, flagged
  ekf2.add_odometry(160 * kMs, 1.0, 0.0);
  EXPECT_EQ(ekf2.estimate_at(160 * kMs).health, HealthState::kLocalized);
}

TEST(FusionEkf, BadInputsAreRejectedAndCounted) {
  Ekf ekf{EkfConfig{}};
  const double nan = std::numeric_limits<double>::quiet_NaN();
  const double inf = std::numeric_limits<double>::infinity();
  // A bad fix cannot initialise.
  EXPECT_EQ(ekf.add_fix(0, {nan, 0.0, 0.0}, fix_cov()), FixOutcome::kRejectedInvalid);
  EXPECT_FALSE(ekf.initialised());
  ASSERT_TRUE(ekf.add_odometry(0, 1.0, 0.0));
  ASSERT_EQ(ekf.add_fix(0, {0.0, 0.0, 0.0}, fix_cov()), FixOutcome::kInitialised);
  ASSERT_TRUE(ekf.add_odometry(10 * kMs, 1.0, 0.0));
  ekf.take_flags();
  const PoseEstimate before = ekf.estimate_at(20 * kMs);

  EXPECT_FALSE(ekf.add_odometry(20 * kMs, nan, 0.0));
  EXPECT_FALSE(ekf.add_odometry(20 * kMs, 1.0, inf));
  EXPECT_FALSE(ekf.add_odometry(20 * kMs, 50.0, 0.0));  // beyond max_abs_v_mps
  EXPECT_EQ(ekf.counters().odom_rejected_invalid, 3u);
  EXPECT_FALSE(ekf.add_odometry(10 * kMs, 1.0, 0.0));  // repeated time
  EXPECT_FALSE(ekf.add_odometry(5 * kMs, 1.0, 0.0));   // backwards
  EXPECT_EQ(ekf.counters().odom_rejected_time, 2u);

  Eigen::Matrix3d asym = fix_cov();
  asym(0, 1) = 0.01;
  Eigen::Matrix3d indefinite = fix_cov();
  indefinite(0, 0) = -0.04;
  Eigen::Matrix3d nan_cov = fix_cov();
  nan_cov(2, 2) = nan;
  const Pose2 good{10.0, 0.0, 0.0};
  EXPECT_EQ(ekf.add_fix(10 * kMs, {10.0, inf, 0.0}, fix_cov()), FixOutcome::kRejectedInvalid);
  EXPECT_EQ(ekf.add_fix(10 * kMs, {10.0, 0.0, nan}, fix_cov()), FixOutcome::kRejectedInvalid);
  EXPECT_EQ(ekf.add_fix(10 * kMs, good, asym), FixOutcome::kRejectedInvalid);
  EXPECT_EQ(ekf.add_fix(10 * kMs, good, indefinite), FixOutcome::kRejectedInvalid);
  EXPECT_EQ(ekf.add_fix(10 * kMs, good, Eigen::Matrix3d::Zero()), FixOutcome::kRejectedInvalid);
  EXPECT_EQ(ekf.add_fix(10 * kMs, good, nan_cov), FixOutcome::kRejectedInvalid);
  // Exposure far after the newest odometry: held (odometry may be late) without touching the
  // state...
  EXPECT_EQ(ekf.add_fix(10 * kS, good, fix_cov()), FixOutcome::kHeld);
  EXPECT_EQ(ekf.counters().fixes_held, 1u);
  EXPECT_EQ(ekf.counters().fixes_rejected_invalid, 7u);  // includes the NaN before init

  expect_same_estimate(ekf.estimate_at(20 * kMs), before, 0.0);
  const std::uint16_t f = ekf.take_flags();
  EXPECT_EQ(f, flags::kInvalidInput);
  EXPECT_EQ(ekf.take_flags(), 0u);  // cleared
  // Good data still works; the next odometry shows the held fix is 10 s ahead of flowing
  // odometry: a camera clock error, rejected as invalid.
  EXPECT_TRUE(ekf.add_odometry(20 * kMs, 1.0, 0.0));
  EXPECT_EQ(ekf.counters().fixes_rejected_invalid, 8u);
  EXPECT_TRUE(ekf.take_flags() & flags::kInvalidInput);
  EXPECT_EQ(ekf.add_fix(20 * kMs, {20.0, 0.0, 0.0}, fix_cov()), FixOutcome::kFused);
}

TEST(FusionEkf, FixNewerThanOdometryIsFusedAndOdometryContinuesFromIt) {
  Ekf ekf{EkfConfig{}};
  ekf.add_odometry(0, 1.0, 0.0);
  ekf.add_fix(0, {0.0, 0.0, 0.0}, fix_cov());
  ekf.add_odometry(10 * kMs, 1.0, 0.0);
  EXPECT_EQ(ekf.add_fix(15 * kMs, {15.3, 0.0, 0.0}, fix_cov()), FixOutcome::kFused);
  EXPECT_EQ(ekf.counters().fixes_delayed, 0u);
  ekf.add_odometry(20 * kMs, 1.0, 0.0);
  const PoseEstimate e = ekf.estimate_at(20 * kMs);
  EXPECT_NEAR(e.pose.x_mm, 20.3, 0.05);
}

TEST(FusionEkf, FlagsAccumulateUntilTaken) {
  Ekf ekf{EkfConfig{}};
  ekf.add_odometry(0, 1.0, 0.0);
  ekf.add_fix(0, {0.0, 0.0, 0.0}, fix_cov());
  ekf.add_odometry(10 * kMs, 1.0, 0.0);
  ekf.add_fix(10 * kMs, {5000.0, 0.0, 0.0}, fix_cov());
  const PoseEstimate e = ekf.estimate_at(10 * kMs);
  const std::uint16_t expected = flags::kInitialised | flags::kFusedOdom | flags::kRejectedGate;
  EXPECT_EQ(e.flags, expected);  // estimate_at reports without clearing
  EXPECT_EQ(ekf.take_flags(), expected);
  EXPECT_EQ(ekf.take_flags(), 0u);
}

TEST(FusionEkf, InvalidConfigurationThrows) {
  EkfConfig c;
  c.fix.gate_probability = 1.0;
  EXPECT_THROW(Ekf{c}, std::invalid_argument);
  EXPECT_FALSE(validate(c).empty());
  c = EkfConfig{};
  c.recovery.kidnap_fixes = 1;
  EXPECT_THROW(Ekf{c}, std::invalid_argument);
  c = EkfConfig{};
  c.odometry.v_sigma_mps = 0.0;
  EXPECT_THROW(Ekf{c}, std::invalid_argument);
  c = EkfConfig{};
  c.core.history_capacity = 2;
  EXPECT_THROW(Ekf{c}, std::invalid_argument);
  EXPECT_TRUE(validate(EkfConfig{}).empty());
}

namespace {

// Straight drive at 1 m/s with odometry that reads `scale` high and has a yaw-rate bias; a fix
// every metre (a landmark every 1 m). Returns the filter after `seconds`.
Ekf drive_with_biased_odometry(const EkfConfig& c, double scale, double bias_radps, int seconds,
                               double* max_err_before_fix_mm) {
  Ekf ekf{c};
  ekf.add_odometry(0, 1.0 * (1 + scale), bias_radps);
  ekf.add_fix(0, {0.0, 0.0, 0.0}, fix_cov());
  *max_err_before_fix_mm = 0.0;
  for (int i = 1; i <= seconds * 100; ++i) {
    const std::int64_t t = i * 10 * kMs;
    ekf.add_odometry(t, 1.0 * (1 + scale), bias_radps);
    if (i % 100 == 0) {
      const Pose2 truth = straight_truth(t);
      if (i > seconds * 50) {  // second half: after convergence
        const PoseEstimate e = ekf.estimate_at(t);
        *max_err_before_fix_mm = std::max(
            *max_err_before_fix_mm, std::hypot(e.pose.x_mm - truth.x_mm, e.pose.y_mm - truth.y_mm));
      }
      EXPECT_EQ(ekf.add_fix(t, truth, fix_cov()), FixOutcome::kFused) << "at " << i;
    }
  }
  return ekf;
}

}  // namespace

TEST(FusionEkf, LearnsOdometryScaleAndYawRateBias) {
  // Within what the plain 5-state filter's default gate tolerates (it has to fuse every fix for
  // the comparison); the calibrated filter handles far more (docs/design/fusion.md, eval_fusion).
  const double scale = 0.01, bias = deg_to_rad(0.5);
  double err_cal = 0.0, err_plain = 0.0;
  const Ekf cal = drive_with_biased_odometry(EkfConfig{}, scale, bias, 30, &err_cal);
  const PoseEstimate e = cal.estimate_at(30 * kS);
  // odometry v = (1 + s_v) v: the filter's s_v converges to the true scale error.
  EXPECT_NEAR(e.odom_v_scale_error, scale, 0.002);
  // At constant speed a yaw-rate bias and a yaw rate per speed are indistinguishable; their sum
  // at 1 m/s is what is observable.
  EXPECT_NEAR(e.odom_omega_bias_radps + e.odom_omega_per_v_radpm * 1.0, bias, deg_to_rad(0.05));
  EXPECT_NEAR(e.v_mps, 1.0, 0.002);
  EXPECT_NEAR(e.omega_radps, 0.0, deg_to_rad(0.05));

  EkfConfig plain;
  use_uncalibrated_noise(&plain);
  const Ekf five = drive_with_biased_odometry(plain, scale, bias, 30, &err_plain);
  const PoseEstimate f = five.estimate_at(30 * kS);
  EXPECT_EQ(f.odom_v_scale_error, 0.0);  // calibration states stay exactly zero
  EXPECT_EQ(f.odom_omega_scale_error, 0.0);
  EXPECT_EQ(f.odom_omega_bias_radps, 0.0);
  EXPECT_EQ(f.odom_omega_per_v_radpm, 0.0);
  // Dead reckoning over the last metre before each fix: ~10 mm uncalibrated, far less
  // calibrated.
  EXPECT_GT(err_plain, 8.0);
  EXPECT_LT(err_cal, 1.0);
}

TEST(FusionEkf, StandingOnAMisprintedLandmarkNeverReinitialises) {
  Ekf ekf{EkfConfig{}};
  ekf.add_odometry(0, 0.0, 0.0);
  ekf.add_fix(0, {0.0, 0.0, 0.0}, fix_cov());
  // Parked for 5 s on a landmark whose code says it is 1 m further on: 150 agreeing fixes, but
  // all at one place.
  int rejected = 0;
  for (int i = 1; i <= 500; ++i) {
    const std::int64_t t = i * 10 * kMs;
    ekf.add_odometry(t, 0.0, 0.0);
    if (i % 3 == 0)
      rejected += ekf.add_fix(t, {1000.0, 0.0, 0.0}, fix_cov()) == FixOutcome::kRejectedGate;
  }
  EXPECT_EQ(rejected, 166);
  EXPECT_EQ(ekf.counters().reinitialisations, 0u);
  EXPECT_NEAR(ekf.estimate_at(5 * kS).pose.x_mm, 0.0, 1e-6);
  // With the separation switched off the same data do re-initialise (the guard is what holds).
  EkfConfig c;
  c.recovery.kidnap_min_separation_mm = 0.0;
  Ekf ekf2{c};
  ekf2.add_odometry(0, 0.0, 0.0);
  ekf2.add_fix(0, {0.0, 0.0, 0.0}, fix_cov());
  for (int i = 1; i <= 500; ++i) {
    const std::int64_t t = i * 10 * kMs;
    ekf2.add_odometry(t, 0.0, 0.0);
    if (i % 3 == 0) ekf2.add_fix(t, {1000.0, 0.0, 0.0}, fix_cov());
  }
  EXPECT_GT(ekf2.counters().reinitialisations, 0u);
}
