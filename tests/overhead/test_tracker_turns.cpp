// The overhead tracker on a vehicle of the simulated fleet's kind: turns on the spot that start and
// stop in a step (0 <-> 0.8 rad/s), straight drives with ramped speed, fixes as precise as a 60 px
// tag's at 6 m (0.05 mm, 0.013 deg) at 10 Hz. The turn-rate density must be small enough that the
// turn rate stays still between turns (the heading extrapolated to the next fix stays on the
// truth), and a fix that shows a turn starting or stopping must not be gated but followed at once
// (tracker.hpp: maneuver_alpha_noise_radps2).
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <random>
#include <vector>

#include "agv/overhead/tracker.hpp"

using namespace agv;
using namespace agv::overhead;

namespace {

constexpr std::int64_t kMs = 1'000'000;

struct Truth {
  Pose2 pose;
  double v_mps = 0.0, omega_radps = 0.0;
};

// Rest 1 s, a quarter turn left, rest 1 s, 2 m straight (0.5 m/s^2 to 1 m/s and down), a half
// turn right, rest; integrated at 1 ms.
std::vector<Truth> drive() {
  std::vector<Truth> out;
  Truth s;
  s.pose = {1000.0, 2000.0, 0.3};
  auto run = [&](double seconds, auto&& rates) {
    for (int i = 0; i < static_cast<int>(seconds * 1000.0 + 0.5); ++i) {
      rates(i * 1e-3, &s);
      const double dt = 1e-3;
      s.pose.x_mm += 1000.0 * s.v_mps * dt * std::cos(s.pose.theta_rad + 0.5 * s.omega_radps * dt);
      s.pose.y_mm += 1000.0 * s.v_mps * dt * std::sin(s.pose.theta_rad + 0.5 * s.omega_radps * dt);
      s.pose.theta_rad = wrap_angle_rad(s.pose.theta_rad + s.omega_radps * dt);
      out.push_back(s);
    }
  };
  auto rest = [](double, Truth* t) { t->v_mps = t->omega_radps = 0.0; };
  auto turn = [](double w) {
    return [w](double, Truth* t) { t->v_mps = 0.0, t->omega_radps = w; };
  };
  run(1.0, rest);
  run(0.5 * kPi / 0.8, turn(0.8));
  run(1.0, rest);
  run(3.0, [](double t, Truth* x) {
    x->omega_radps = 0.0;
    x->v_mps = t < 2.0 ? std::min(1.0, 0.5 * t) : std::max(0.0, 1.0 - 0.5 * (t - 2.0) * 2.0);
  });
  run(1.0, rest);
  run(kPi / 0.8, turn(-0.8));
  run(1.0, rest);
  return out;
}

TagFix fix_of(const Pose2& truth, std::mt19937_64* rng) {
  const double sigma_mm = 0.05, sigma_rad = deg_to_rad(0.013);
  std::normal_distribution<double> n(0.0, 1.0);
  const double ex = sigma_mm * n(*rng);
  const double ey = sigma_mm * n(*rng);
  const double et = sigma_rad * n(*rng);
  TagFix f;
  f.pose = {truth.x_mm + ex, truth.y_mm + ey, wrap_angle_rad(truth.theta_rad + et)};
  f.cov = {sigma_mm * sigma_mm, 0, 0, 0, sigma_mm * sigma_mm, 0, 0, 0, sigma_rad * sigma_rad};
  return f;
}

struct Followed {
  std::vector<double> steady_deg;  // heading error 99 ms after a fix, no turn rate step between
  // The same after the second fix that follows a turn's start or end (the first cannot tell when
  // in the frame interval the step came).
  double worst_after_step_deg = 0.0;
  std::uint64_t gated = 0;
};

Followed follow(const TrackerParams& p, std::uint64_t seed) {
  const std::vector<Truth> truth = drive();
  FleetTracker tr(1, p);
  std::mt19937_64 rng(seed);
  Followed r;
  int since_step = 100;
  for (std::size_t k = 0; k + 100 < truth.size(); k += 100) {  // a fix every 100 ms
    const std::int64_t t_ns = static_cast<std::int64_t>(k) * kMs;
    const FixResult res = tr.add_fix(0, t_ns, fix_of(truth[k].pose, &rng));
    if (res == FixResult::kGated) ++r.gated;
    bool step = false;  // the turn rate changes before the output: no filter can know
    for (std::size_t j = k > 100 ? k - 100 : 0; j < k + 99; ++j) {
      step = step || truth[j + 1].omega_radps != truth[j].omega_radps;
    }
    since_step = step ? 0 : since_step + 1;
    const TrackOutput o = tr.output(0, t_ns + 99 * kMs);
    if (!o.valid()) continue;
    const double err =
        std::abs(rad_to_deg(wrap_angle_rad(o.pose.theta_rad - truth[k + 99].pose.theta_rad)));
    if (since_step == 2) r.worst_after_step_deg = std::max(r.worst_after_step_deg, err);
    if (since_step > 0) r.steady_deg.push_back(err);
  }
  return r;
}

double p95(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  return v[static_cast<std::size_t>(0.95 * static_cast<double>(v.size() - 1))];
}

TEST(OverheadTrackerTurns, TurnRateStillBetweenTurnsAndFollowedAtOnce) {
  // Before the two-model prior (a single density of 2 rad/s^2, which the turn steps needed): p95
  // 0.58-0.71 deg between turns, 0.16-0.39 deg after the second fix.
  for (std::uint64_t seed = 1; seed <= 5; ++seed) {
    const Followed r = follow(TrackerParams{}, seed);
    std::printf(
        "seed %llu: heading 99 ms after a fix p95 %.4f deg (%zu), after a step %.4f deg, "
        "gated %llu\n",
        static_cast<unsigned long long>(seed), p95(r.steady_deg), r.steady_deg.size(),
        r.worst_after_step_deg, static_cast<unsigned long long>(r.gated));
    EXPECT_EQ(r.gated, 0u);
    EXPECT_LT(p95(r.steady_deg), 0.3);
    EXPECT_LT(r.worst_after_step_deg, 0.12);
  }
}

TEST(OverheadTrackerTurns, AGapAcrossATurnStartReportsTheTurnItCouldNotSee) {
  // No fix from 0.9 s to 1.6 s while the first turn starts (1.0 s, 0.8 rad/s on the spot), as a
  // covered tag's vehicle that the tray fit does not find: the output (and the search window drawn
  // from it) must allow for the turn once the track coasts. With the steady density over the whole
  // gap the heading was 4.96 sigma off (0.199 rad under 0.040 at 1.25 s).
  const std::vector<Truth> truth = drive();
  FleetTracker tr(1, TrackerParams{});
  std::mt19937_64 rng(7);
  double worst_ratio = 0.0;
  for (std::size_t k = 0; k <= 1600; k += 10) {
    const std::int64_t t_ns = static_cast<std::int64_t>(k) * kMs;
    const bool gap = k > 900 && k < 1600;
    if (k % 100 == 0 && !gap) {
      EXPECT_EQ(tr.add_fix(0, t_ns, fix_of(truth[k].pose, &rng)),
                k == 0 ? FixResult::kStarted : FixResult::kApplied)
          << k;
    }
    if (!gap) continue;
    const TrackOutput o = tr.output(0, t_ns);
    ASSERT_TRUE(o.valid()) << k;
    // Within coast_after_ms of the fix the next one would have shown a turn's start: the steady
    // model holds by assumption there.
    if (static_cast<double>(k - 900) <= TrackerParams{}.coast_after_ms) continue;
    const double err = std::abs(wrap_angle_rad(o.pose.theta_rad - truth[k].pose.theta_rad));
    worst_ratio = std::max(worst_ratio, err / o.sigma_theta_rad);
  }
  std::printf("worst heading error / sigma in the gap: %.2f\n", worst_ratio);
  EXPECT_LT(worst_ratio, 3.0);
}

}  // namespace
