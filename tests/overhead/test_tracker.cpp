// The per-vehicle EKF of the overhead tracker (algo/src/overhead/tracker*.cpp): convergence on a
// circle, honest covariance (NEES), delayed fixes equal to in-order ones, the gate, the track
// states, refused input, and no heap use per fix (tests/support/alloc_counter.cpp counts).
// Fixes are synthetic (no rendering).
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <limits>
#include <new>
#include <random>
#include <vector>

#include "../support/alloc_counter.hpp"
#include "agv/overhead/tracker.hpp"
#include "pose_nees.hpp"

using namespace agv;
using namespace agv::overhead;

namespace {

constexpr std::int64_t kMs = 1'000'000;

TagFix make_fix(double x_mm, double y_mm, double theta_rad, double sigma_mm = 5.0,
                double sigma_rad = 0.01) {
  TagFix f;
  f.pose = {x_mm, y_mm, theta_rad};
  f.cov = {sigma_mm * sigma_mm, 0, 0, 0, sigma_mm * sigma_mm, 0, 0, 0, sigma_rad * sigma_rad};
  return f;
}

TagFix noisy_fix(const Pose2& truth, double sigma_mm, double sigma_rad, std::mt19937_64* rng) {
  std::normal_distribution<double> n(0.0, 1.0);
  // Drawn in sequence (an argument list's order is the compiler's).
  const double ex = sigma_mm * n(*rng);
  const double ey = sigma_mm * n(*rng);
  const double et = sigma_rad * n(*rng);
  return make_fix(truth.x_mm + ex, truth.y_mm + ey, wrap_angle_rad(truth.theta_rad + et), sigma_mm,
                  sigma_rad);
}

// A vehicle on a circle of radius_mm about the origin, counter-clockwise at speed_mps.
Pose2 on_circle(double t_s, double radius_mm, double speed_mps) {
  const double a = speed_mps * 1000.0 * t_s / radius_mm;
  return {radius_mm * std::cos(a), radius_mm * std::sin(a), wrap_angle_rad(a + kPi / 2.0)};
}

double nees3(const TrackOutput& o, const Pose2& truth) {
  return overhead::test::pose_nees(o.pose, o.cov, truth);
}

TEST(OverheadTracker, CircleWithNoisyFixesConverges) {
  TrackerParams p;  // a steady vehicle: smaller accelerations than the defaults allow
  p.accel_noise_mps2 = 0.2;
  p.alpha_noise_radps2 = 0.2;
  FleetTracker tr(1, p);
  std::mt19937_64 rng(7);
  const double sigma_mm = 5.0, sigma_rad = deg_to_rad(0.5);
  double pos_se = 0.0, head_se = 0.0, raw_se = 0.0, raw_head_se = 0.0, v_sum = 0.0, w_sum = 0.0;
  int n = 0;
  for (int k = 0; k <= 300; ++k) {  // 30 s at 10 Hz: radius 2 m at 0.5 m/s
    const double t_s = 0.1 * k;
    const Pose2 truth = on_circle(t_s, 2000.0, 0.5);
    const TagFix f = noisy_fix(truth, sigma_mm, sigma_rad, &rng);
    const FixResult r = tr.add_fix(0, k * 100 * kMs, f);
    ASSERT_EQ(r, k == 0 ? FixResult::kStarted : FixResult::kApplied) << k;
    if (t_s < 3.0) continue;
    const TrackOutput o = tr.output(0, k * 100 * kMs);
    ASSERT_EQ(o.state, TrackState::kConfirmed);
    pos_se += std::pow(o.pose.x_mm - truth.x_mm, 2) + std::pow(o.pose.y_mm - truth.y_mm, 2);
    head_se += std::pow(wrap_angle_rad(o.pose.theta_rad - truth.theta_rad), 2);
    raw_se += std::pow(f.pose.x_mm - truth.x_mm, 2) + std::pow(f.pose.y_mm - truth.y_mm, 2);
    raw_head_se += std::pow(wrap_angle_rad(f.pose.theta_rad - truth.theta_rad), 2);
    v_sum += o.v_mps;
    w_sum += o.omega_radps;
    ++n;
  }
  const double pos_rms = std::sqrt(pos_se / n), head_rms = std::sqrt(head_se / n);
  const double raw_rms = std::sqrt(raw_se / n), raw_head_rms = std::sqrt(raw_head_se / n);
  std::printf(
      "circle r=2 m, 0.5 m/s, fixes 10 Hz sigma 5 mm / 0.5 deg: position RMS %.2f mm "
      "(fixes %.2f mm), heading RMS %.3f deg (fixes %.3f deg)\n",
      pos_rms, raw_rms, rad_to_deg(head_rms), rad_to_deg(raw_head_rms));
  EXPECT_LT(pos_rms, 0.8 * raw_rms);  // the filter beats the raw fixes
  EXPECT_LT(head_rms, 0.9 * raw_head_rms);
  // Speed and turn rate: each estimate carries the fixes' noise (about 0.03 m/s, 0.03 rad/s
  // here); their mean over the run is the circle's.
  EXPECT_NEAR(v_sum / n, 0.5, 0.005);
  EXPECT_NEAR(w_sum / n, 0.25, 0.005);
  // Extrapolated a quarter second ahead, the arc is followed within the output's sigma.
  const TrackOutput end = tr.output(0, 300 * 100 * kMs);
  const TrackOutput ahead = tr.output(0, 30250 * kMs);
  const Pose2 truth_ahead = on_circle(30.25, 2000.0, 0.5);
  EXPECT_LT(std::hypot(ahead.pose.x_mm - truth_ahead.x_mm, ahead.pose.y_mm - truth_ahead.y_mm),
            3.0 * ahead.sigma_xy_mm);
  EXPECT_GT(ahead.sigma_xy_mm, end.sigma_xy_mm);
}

// Truth drawn from the filter's own model (white accelerations of the configured densities, fine
// steps): the normalised estimation error squared must average 3 (x, y, theta).
TEST(OverheadTracker, CovarianceIsHonest) {
  TrackerParams p;
  p.accel_noise_mps2 = 0.3;
  p.alpha_noise_radps2 = 0.5;
  p.initial_speed_sigma_mps = 1.0;
  p.initial_turn_sigma_radps = 0.5;
  std::mt19937_64 rng(11);
  std::normal_distribution<double> n01(0.0, 1.0);
  const double dt = 0.001, sigma_mm = 5.0, sigma_rad = 0.01;
  double sum = 0.0;
  int samples = 0, above95 = 0, gated = 0;
  for (int run = 0; run < 20; ++run) {
    FleetTracker tr(1, p);
    Pose2 x{0.0, 0.0, 0.3 * run};
    double v = 0.5, w = 0.2;          // m/s, rad/s
    for (int k = 0; k <= 100; ++k) {  // 10 s, fixes at 10 Hz
      if (k > 0) {
        for (int s = 0; s < 100; ++s) {
          x.x_mm += 1000.0 * v * dt * std::cos(x.theta_rad);
          x.y_mm += 1000.0 * v * dt * std::sin(x.theta_rad);
          x.theta_rad = wrap_angle_rad(x.theta_rad + w * dt);
          v += p.accel_noise_mps2 * std::sqrt(dt) * n01(rng);
          w += p.alpha_noise_radps2 * std::sqrt(dt) * n01(rng);
        }
      }
      const std::int64_t t = k * 100 * kMs;
      // The gate refuses 0.1 % of right fixes (chi2 0.999).
      gated += tr.add_fix(0, t, noisy_fix(x, sigma_mm, sigma_rad, &rng)) == FixResult::kGated;
      if (k < 10) continue;
      const double d2 = nees3(tr.output(0, t), x);
      sum += d2;
      above95 += d2 > 7.815 ? 1 : 0;
      ++samples;
    }
  }
  const double mean = sum / samples;
  const double frac95 = static_cast<double>(above95) / samples;
  std::printf(
      "NEES over %d samples: mean %.3f (3 expected), %.1f %% above the 95 %% bound, "
      "%d of 2020 fixes gated\n",
      samples, mean, 100.0 * frac95, gated);
  EXPECT_GT(mean, 2.5);
  EXPECT_LT(mean, 3.5);
  EXPECT_LT(frac95, 0.09);
  EXPECT_LE(gated, 6);
}

// A camera's calibration error is one bias for all its fixes: the same runs as above, each
// fix moved by the run's bias drawn from cov_camera as well as by its own noise. The filter
// averages the noise away, not the bias, and reports the bias on top (NEES about 3). Taken as
// noise, the bias makes the reported sigma shrink far below the error (NEES well above 3).
TEST(OverheadTracker, CameraBiasIsReportedNotAveraged) {
  TrackerParams p;
  p.accel_noise_mps2 = 0.3;
  p.alpha_noise_radps2 = 0.5;
  std::mt19937_64 rng(13);
  std::normal_distribution<double> n01(0.0, 1.0);
  const double sigma_mm = 1.0, sigma_rad = 0.002, bias_mm = 4.0, bias_rad = 0.003;
  auto mean_nees = [&](bool as_bias) {
    double sum = 0.0;
    int samples = 0;
    for (int run = 0; run < 40; ++run) {
      FleetTracker tr(1, p);
      const Pose2 x{1000.0, -500.0, 0.3 * run};
      const double bx = bias_mm * n01(rng), by = bias_mm * n01(rng), bt = bias_rad * n01(rng);
      for (int k = 0; k <= 50; ++k) {  // a parked vehicle, fixes at 10 Hz
        TagFix f =
            noisy_fix({x.x_mm + bx, x.y_mm + by, x.theta_rad + bt}, sigma_mm, sigma_rad, &rng);
        const std::array<double, 9> c{bias_mm * bias_mm,  0, 0, 0, bias_mm * bias_mm, 0, 0, 0,
                                      bias_rad * bias_rad};
        for (std::size_t i = 0; i < 9; ++i) f.cov[i] += c[i];
        if (as_bias) f.cov_camera = c;
        const std::int64_t t = k * 100 * kMs;
        EXPECT_NE(tr.add_fix(0, t, f), FixResult::kGated);
        if (k < 10) continue;
        const TrackOutput o = tr.output(0, t);
        EXPECT_GE(o.cov[0], as_bias ? bias_mm * bias_mm : 0.0);
        sum += nees3(o, x);
        ++samples;
      }
    }
    return sum / samples;
  };
  const double with_bias = mean_nees(true), as_noise = mean_nees(false);
  std::printf("NEES mean with the camera part as a bias %.2f, as noise %.2f (3 expected)\n",
              with_bias, as_noise);
  EXPECT_GT(with_bias, 2.0);
  EXPECT_LT(with_bias, 4.0);
  EXPECT_GT(as_noise, 10.0);
}

// A vehicle turning on the spot in the overlap of two cameras whose calibrations differ by 3 mm
// (each within its stated 2 mm bias sigma), read alternately by the two at 20 Hz: the jump
// between them is no motion. The filter must neither give the vehicle a speed from it nor
// extrapolate that speed into an error beyond its reported sigma.
TEST(OverheadTracker, TwoCamerasBiasesAreNoMotion) {
  const double bias_mm = 2.0;
  const std::array<double, 9> c{bias_mm * bias_mm, 0, 0, 0, bias_mm * bias_mm, 0, 0, 0, 1e-8};
  std::mt19937_64 rng(5);
  const auto run = [&](bool sources_known) {
    FleetTracker tr(1);
    double worst_speed_mps = 0.0, worst_z = 0.0;
    for (int k = 0; k <= 80; ++k) {
      const int cam = k % 2;
      const double t_s = 0.05 * k;
      const Pose2 truth{2000.0, 1000.0, wrap_angle_rad(0.3 - 0.8 * t_s)};
      TagFix f = noisy_fix({truth.x_mm + (cam == 0 ? 1.5 : -1.5), truth.y_mm, truth.theta_rad}, 0.3,
                           0.0005, &rng);
      for (std::size_t i = 0; i < 9; ++i) f.cov[i] += c[i];
      f.cov_camera = c;
      f.source = sources_known ? cam : -1;
      const std::int64_t t = static_cast<std::int64_t>(k) * 50 * kMs;
      EXPECT_EQ(tr.add_fix(0, t, f), k == 0 ? FixResult::kStarted : FixResult::kApplied) << k;
      if (k < 20) continue;
      // Halfway to the next fix, as an output tick between them sees it.
      const TrackOutput o = tr.output(0, t + 40 * kMs);
      const Pose2 later{truth.x_mm, truth.y_mm, wrap_angle_rad(truth.theta_rad - 0.8 * 0.04)};
      worst_speed_mps = std::max(worst_speed_mps, std::abs(o.v_mps));
      const double e = std::hypot(o.pose.x_mm - later.x_mm, o.pose.y_mm - later.y_mm);
      worst_z = std::max(worst_z, e / o.sigma_xy_mm);
    }
    std::printf("sources %s: largest speed %.3f m/s, largest error / sigma %.2f\n",
                sources_known ? "known" : "unknown", worst_speed_mps, worst_z);
    return std::make_pair(worst_speed_mps, worst_z);
  };
  const auto [speed, z] = run(true);
  EXPECT_LT(speed, 0.08);
  EXPECT_LT(z, 3.0);
  run(false);  // for the record: what the filter does without knowing the cameras
}

struct TimedFix {
  std::int64_t exposure_ns, arrival_ns;
  TagFix fix;
};

// Two cameras with different rates and latencies: fed in arrival order, the filter rewinds and
// replays; the result equals feeding in exposure order.
TEST(OverheadTracker, DelayedFixesEqualInOrder) {
  std::mt19937_64 rng(3);
  std::vector<TimedFix> fixes;
  for (int k = 0; k < 80; ++k) {  // camera A: 10 Hz, 30 ms latency
    const std::int64_t t = k * 100 * kMs;
    fixes.push_back(
        {t, t + 30 * kMs, noisy_fix(on_circle(t * 1e-9, 1500.0, 0.8), 4.0, 0.01, &rng)});
  }
  for (int k = 0; k < 120; ++k) {  // camera B: 15 Hz, 120 ms latency
    const std::int64_t t = 20 * kMs + std::int64_t{k} * 66'666'667;
    fixes.push_back(
        {t, t + 120 * kMs, noisy_fix(on_circle(t * 1e-9, 1500.0, 0.8), 6.0, 0.015, &rng)});
  }
  FleetTracker in_order(1), delayed(1);
  std::sort(fixes.begin(), fixes.end(),
            [](const TimedFix& a, const TimedFix& b) { return a.exposure_ns < b.exposure_ns; });
  for (const TimedFix& f : fixes) in_order.add_fix(0, f.exposure_ns, f.fix);
  std::stable_sort(fixes.begin(), fixes.end(), [](const TimedFix& a, const TimedFix& b) {
    return a.arrival_ns < b.arrival_ns;
  });
  for (const TimedFix& f : fixes) delayed.add_fix(0, f.exposure_ns, f.fix);
  EXPECT_GT(delayed.counters().replays, 50u);
  EXPECT_EQ(in_order.counters().replays, 0u);
  EXPECT_EQ(delayed.counters().applied, in_order.counters().applied);
  EXPECT_EQ(delayed.counters().gated + delayed.counters().too_old, 0u);
  const std::int64_t end = 8 * 1000 * kMs;
  const TrackOutput a = in_order.output(0, end), b = delayed.output(0, end);
  EXPECT_NEAR(a.pose.x_mm, b.pose.x_mm, 1e-6);
  EXPECT_NEAR(a.pose.y_mm, b.pose.y_mm, 1e-6);
  EXPECT_NEAR(a.pose.theta_rad, b.pose.theta_rad, 1e-6);
  EXPECT_NEAR(a.v_mps, b.v_mps, 1e-6);
  EXPECT_NEAR(a.omega_radps, b.omega_radps, 1e-6);
  for (std::size_t i = 0; i < 9; ++i)
    EXPECT_NEAR(a.cov[i], b.cov[i], 1e-6 * (1.0 + std::abs(a.cov[i])));
  EXPECT_EQ(a.last_fix_t_ns, b.last_fix_t_ns);
}

// Drives a vehicle straight along +x at 0.5 m/s with fixes at 10 Hz from start_ms to end_ms.
void drive(FleetTracker* tr, std::int64_t end_ms, std::size_t agv = 0, double y_mm = 0.0,
           std::int64_t start_ms = 0) {
  for (std::int64_t t = start_ms; t <= end_ms; t += 100) {
    tr->add_fix(agv, t * kMs, make_fix(0.5 * static_cast<double>(t), y_mm, 0.0));
  }
}

TEST(OverheadTracker, FixOfAnotherVehicleIsGated) {
  FleetTracker tr(2);
  drive(&tr, 2000, 0, 0.0);
  const TrackOutput before = tr.output(0, 2100 * kMs);
  ASSERT_EQ(before.state, TrackState::kConfirmed);
  // Vehicle 1 drives beside it, 1 m to the left; its tag read as vehicle 0's.
  EXPECT_EQ(tr.add_fix(0, 2100 * kMs, make_fix(1050.0, 1000.0, 0.0)), FixResult::kGated);
  EXPECT_EQ(tr.counters().gated, 1u);
  const TrackOutput after = tr.output(0, 2100 * kMs);
  EXPECT_EQ(after.pose.x_mm, before.pose.x_mm);
  EXPECT_EQ(after.pose.y_mm, before.pose.y_mm);
  EXPECT_EQ(after.last_fix_t_ns, before.last_fix_t_ns);
  // A wrong heading at the right place is gated too; the right fix is applied.
  EXPECT_EQ(tr.add_fix(0, 2100 * kMs, make_fix(1050.0, 0.0, 0.5)), FixResult::kGated);
  EXPECT_EQ(tr.add_fix(0, 2100 * kMs, make_fix(1050.0, 0.0, 0.0)), FixResult::kApplied);
  EXPECT_EQ(tr.output(1, 0).state, TrackState::kNone);
}

TEST(OverheadTracker, StatesTentativeConfirmedCoastingLost) {
  TrackerParams p;
  p.lost_sigma_mm = 5000.0;  // lost by time here (the sigma rule is the next test's)
  FleetTracker tr(1, p);
  EXPECT_EQ(tr.output(0, 0).state, TrackState::kNone);
  EXPECT_EQ(tr.add_fix(0, 0, make_fix(0, 0, 0)), FixResult::kStarted);
  EXPECT_EQ(tr.output(0, 0).state, TrackState::kTentative);
  EXPECT_FALSE(tr.output(0, 0).valid());
  EXPECT_EQ(tr.add_fix(0, 100 * kMs, make_fix(50, 0, 0)), FixResult::kApplied);
  EXPECT_EQ(tr.output(0, 100 * kMs).state, TrackState::kTentative);
  EXPECT_EQ(tr.add_fix(0, 200 * kMs, make_fix(100, 0, 0)), FixResult::kApplied);
  EXPECT_EQ(tr.output(0, 200 * kMs).state, TrackState::kConfirmed);
  drive(&tr, 2000, 0, 0.0, 300);
  tr.update_states(2200 * kMs);
  const TrackOutput confirmed = tr.output(0, 2200 * kMs);
  EXPECT_EQ(confirmed.state, TrackState::kConfirmed);
  EXPECT_TRUE(confirmed.valid());
  tr.update_states(2400 * kMs);
  const TrackOutput coasting = tr.output(0, 2400 * kMs);
  EXPECT_EQ(coasting.state, TrackState::kCoasting);
  EXPECT_TRUE(coasting.valid());
  EXPECT_GT(coasting.sigma_xy_mm, confirmed.sigma_xy_mm);
  double last_sigma = coasting.sigma_xy_mm;
  for (std::int64_t t = 2500; t <= 4900; t += 200) {
    tr.update_states(t * kMs);
    const TrackOutput o = tr.output(0, t * kMs);
    EXPECT_EQ(o.state, TrackState::kCoasting) << t;
    EXPECT_GT(o.sigma_xy_mm, last_sigma) << t;
    last_sigma = o.sigma_xy_mm;
  }
  tr.update_states(5100 * kMs);  // 3.1 s without a fix
  EXPECT_EQ(tr.output(0, 5100 * kMs).state, TrackState::kLost);
  EXPECT_EQ(tr.counters().lost, 1u);
  for (std::int64_t t = 5100; t < 120000; t += 700) {
    tr.update_states(t * kMs);
    EXPECT_FALSE(tr.output(0, t * kMs).valid()) << t;
    EXPECT_FALSE(tr.output(0, 2400 * kMs).valid()) << t;  // not even at an earlier time
  }
  EXPECT_EQ(tr.counters().lost, 1u);
  // The next fix restarts the track, wherever it is (nothing to gate it by).
  EXPECT_EQ(tr.add_fix(0, 121000 * kMs, make_fix(-5000, 3000, 1.0)), FixResult::kStarted);
  EXPECT_EQ(tr.output(0, 121000 * kMs).state, TrackState::kTentative);
  EXPECT_NEAR(tr.output(0, 121000 * kMs).pose.x_mm, -5000.0, 1e-9);
  EXPECT_EQ(tr.counters().started, 2u);
}

TEST(OverheadTracker, CoastingTrackIsLostWhenSigmaGrows) {
  TrackerParams p;
  p.accel_noise_mps2 = 0.2;
  p.alpha_noise_radps2 = 0.2;
  p.lost_sigma_mm = 60.0;
  FleetTracker tr(1, p);
  drive(&tr, 2000);
  std::int64_t lost_at = 0;
  for (std::int64_t t = 2000; t < 5000 && lost_at == 0; t += 50) {
    tr.update_states(t * kMs);
    const TrackOutput o = tr.output(0, t * kMs);
    if (o.state == TrackState::kLost)
      lost_at = t;
    else
      EXPECT_LE(o.sigma_xy_mm, p.lost_sigma_mm);
  }
  EXPECT_GT(lost_at, 2000 + 300);
  EXPECT_LT(lost_at, 2000 + 3000);  // before lost_after_ms: by sigma
  // output() applies the rule without update_states: a second tracker never told the time.
  FleetTracker quiet(1, p);
  drive(&quiet, 2000);
  EXPECT_EQ(quiet.output(0, lost_at * kMs).state, TrackState::kLost);
  EXPECT_EQ(quiet.output(0, 2100 * kMs).state, TrackState::kConfirmed);
}

TEST(OverheadTracker, TentativeTrackThatMissesIsDropped) {
  FleetTracker tr(1);
  EXPECT_EQ(tr.add_fix(0, 0, make_fix(0, 0, 0)), FixResult::kStarted);
  tr.update_states(200 * kMs);
  EXPECT_EQ(tr.output(0, 200 * kMs).state, TrackState::kTentative);
  tr.update_states(400 * kMs);
  EXPECT_EQ(tr.output(0, 400 * kMs).state, TrackState::kNone);
  EXPECT_EQ(tr.counters().lost, 0u);  // never reported, so never lost
  EXPECT_EQ(tr.add_fix(0, 500 * kMs, make_fix(900, 0, 0)), FixResult::kStarted);
  // A tentative track gates, too: a fix 1 m away does not move it.
  EXPECT_EQ(tr.add_fix(0, 600 * kMs, make_fix(1900, 0, 0)), FixResult::kGated);
  EXPECT_EQ(tr.counters().started, 2u);
}

TEST(OverheadTracker, TooOldFixesAreRefused) {
  TrackerParams p;
  p.history = 8;
  FleetTracker tr(1, p);
  drive(&tr, 2000);
  EXPECT_EQ(tr.add_fix(0, 1400 * kMs, make_fix(700, 0, 0)), FixResult::kTooOld);  // 600 ms old
  EXPECT_EQ(tr.counters().too_old, 1u);
  // Within max_fix_age_ms but older than the 8 states kept (800 ms of fixes at 10 Hz).
  p.max_fix_age_ms = 2000.0;
  FleetTracker small(1, p);
  drive(&small, 2000);
  EXPECT_EQ(small.add_fix(0, 1050 * kMs, make_fix(525, 0, 0)), FixResult::kTooOld);
  EXPECT_EQ(small.add_fix(0, 1750 * kMs, make_fix(875, 0, 0)), FixResult::kApplied);
  EXPECT_EQ(small.counters().replays, 1u);
  // Older than a new track's first fix: nothing to rewind to.
  FleetTracker fresh(1);
  fresh.add_fix(0, 1000 * kMs, make_fix(0, 0, 0));
  EXPECT_EQ(fresh.add_fix(0, 990 * kMs, make_fix(0, 0, 0)), FixResult::kTooOld);
}

TEST(OverheadTracker, InvalidFixesAreRefused) {
  FleetTracker tr(1);
  const double nan = std::numeric_limits<double>::quiet_NaN();
  EXPECT_EQ(tr.add_fix(0, 0, make_fix(nan, 0, 0)), FixResult::kInvalid);
  EXPECT_EQ(tr.add_fix(0, 0, make_fix(0, 0, std::numeric_limits<double>::infinity())),
            FixResult::kInvalid);
  TagFix f = make_fix(0, 0, 0);
  f.cov[4] = nan;
  EXPECT_EQ(tr.add_fix(0, 0, f), FixResult::kInvalid);
  f = make_fix(0, 0, 0);
  f.cov[8] = -1e-4;  // negative variance
  EXPECT_EQ(tr.add_fix(0, 0, f), FixResult::kInvalid);
  f = make_fix(0, 0, 0);
  f.cov[1] = f.cov[3] = 25.0;  // x and y perfectly correlated: singular
  EXPECT_EQ(tr.add_fix(0, 0, f), FixResult::kInvalid);
  f = make_fix(0, 0, 0);
  f.cov[1] = 10.0;  // not symmetric
  EXPECT_EQ(tr.add_fix(0, 0, f), FixResult::kInvalid);
  EXPECT_EQ(tr.add_fix(1, 0, make_fix(0, 0, 0)), FixResult::kInvalid);  // outside the fleet
  EXPECT_EQ(tr.counters().invalid, 7u);
  EXPECT_EQ(tr.output(0, 0).state, TrackState::kNone);
  EXPECT_EQ(tr.output(5, 0).state, TrackState::kNone);
  EXPECT_EQ(tr.add_fix(0, 0, make_fix(0, 0, 0)), FixResult::kStarted);
}

TEST(OverheadTracker, HeadingInnovationIsWrapped) {
  FleetTracker tr(1);
  std::mt19937_64 rng(5);
  // Driving along -x: the heading's fixes fall on both sides of +-pi.
  for (int k = 0; k <= 50; ++k) {
    const Pose2 truth{-50.0 * k, 0.0, kPi};
    ASSERT_NE(tr.add_fix(0, k * 100 * kMs, noisy_fix(truth, 3.0, 0.02, &rng)), FixResult::kGated);
  }
  const TrackOutput o = tr.output(0, 5000 * kMs);
  EXPECT_LT(std::abs(wrap_angle_rad(o.pose.theta_rad - kPi)), 0.05);
  EXPECT_NEAR(o.pose.x_mm, -2500.0, 10.0);
  EXPECT_NEAR(o.v_mps, 0.5, 0.05);
  EXPECT_EQ(tr.counters().gated, 0u);
}

TEST(OverheadTracker, ParamsAreChecked) {
  EXPECT_EQ(validate(TrackerParams{}), "");
  TrackerParams p;
  p.history = 1;
  EXPECT_NE(validate(p).find("history"), std::string::npos);
  EXPECT_THROW(FleetTracker(3, p), std::invalid_argument);
  p = {};
  p.lost_after_ms = 100.0;  // before coasting
  EXPECT_NE(validate(p).find("lost_after_ms"), std::string::npos);
  p = {};
  p.accel_noise_mps2 = std::numeric_limits<double>::quiet_NaN();
  EXPECT_NE(validate(p).find("accel_noise_mps2"), std::string::npos);
  p = {};
  p.gate_chi2 = 0.0;
  EXPECT_NE(validate(p).find("gate_chi2"), std::string::npos);
  FleetTracker empty(0);
  EXPECT_EQ(empty.add_fix(0, 0, make_fix(0, 0, 0)), FixResult::kInvalid);
  EXPECT_TRUE(empty.outputs(0).empty());
}

TEST(OverheadTracker, ResetForgetsTheTrack) {
  FleetTracker tr(2);
  drive(&tr, 1000, 1);
  EXPECT_TRUE(tr.output(1, 1000 * kMs).valid());
  tr.reset(1);
  EXPECT_EQ(tr.output(1, 1000 * kMs).state, TrackState::kNone);
  tr.reset(7);  // outside the fleet: nothing
  EXPECT_EQ(tr.add_fix(1, 1100 * kMs, make_fix(0, 0, 0)), FixResult::kStarted);
  const std::vector<TrackOutput> all = tr.outputs(1100 * kMs);
  ASSERT_EQ(all.size(), 2u);
  EXPECT_EQ(all[1].agv, 1u);
  EXPECT_EQ(all[1].state, TrackState::kTentative);
}

TEST(OverheadTracker, NoHeapUseAfterConstruction) {
  const long before_hook = agv::test::allocations();
  auto* probe = new int(3);
  ASSERT_GT(agv::test::allocations(), before_hook);  // the counting hook is active
  delete probe;
  TrackerParams p;
  p.history = 16;  // the ring wraps many times below
  FleetTracker tr(3, p);
  std::mt19937_64 rng(1);
  std::vector<TagFix> fixes;
  for (int k = 0; k < 400; ++k)
    fixes.push_back(noisy_fix(on_circle(0.05 * k, 2000, 0.5), 5, 0.01, &rng));
  const long before = agv::test::allocations();
  for (int k = 0; k < 400; ++k) {
    // In order, every fourth one also a late one (replayed), a gated one, an invalid one, a
    // too old one; a second vehicle in order.
    const std::int64_t t = k * 50 * kMs;
    tr.add_fix(0, t, fixes[static_cast<std::size_t>(k)]);
    if (k % 4 == 3) tr.add_fix(0, t - 90 * kMs, fixes[static_cast<std::size_t>(k - 2)]);
    tr.add_fix(1, t, fixes[static_cast<std::size_t>(k)]);
    tr.add_fix(0, t, make_fix(fixes[static_cast<std::size_t>(k)].pose.x_mm + 900, 0, 0));
    tr.add_fix(2, t, make_fix(std::numeric_limits<double>::quiet_NaN(), 0, 0));
    tr.add_fix(0, t - 5000 * kMs, fixes[static_cast<std::size_t>(k)]);
    tr.update_states(t);
    (void)tr.output(0, t + 30 * kMs);
  }
  EXPECT_EQ(agv::test::allocations(), before);
  EXPECT_GT(tr.counters().applied, 800u);
  EXPECT_GT(tr.counters().replays, 90u);
  EXPECT_GT(tr.counters().gated, 300u);
  EXPECT_GT(tr.counters().too_old, 300u);
}

}  // namespace
