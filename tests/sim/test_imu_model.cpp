// The simulated MEMS gyro (docs/design/simulator.md "Gyro"): each error term has the statistics its
// parameter states, and the samples are the true mean yaw rate over their period.
#include <gtest/gtest.h>

#include <cmath>
#include <numeric>

#include "../support/gyro_errors.hpp"
#include "agv/sim/imu_model.hpp"

using namespace agv;
using namespace agv::sim;

namespace {

// Every error off; tests switch on the one they measure.
GyroParams ideal() {
  GyroParams p;
  testsupport::switch_off_gyro_errors(&p);
  return p;
}

Trajectory make(TrajectoryKind k) {
  TrajectoryParams tp;
  tp.kind = k;
  Trajectory t;
  std::string err;
  EXPECT_TRUE(make_trajectory(tp, &t, &err)) << err;
  return t;
}

const Trajectory kStandstill{};  // no path: the vehicle stands at the origin for ever

constexpr std::int64_t kS = 1'000'000'000;

double stddev(const std::vector<double>& v) {
  const double m = std::accumulate(v.begin(), v.end(), 0.0) / static_cast<double>(v.size());
  double s = 0.0;
  for (double x : v) s += (x - m) * (x - m);
  return std::sqrt(s / static_cast<double>(v.size() - 1));
}

}  // namespace

TEST(GyroModel, DefaultsAreTheDocumentedIndustrialGyro) {
  const GyroParams p;
  EXPECT_DOUBLE_EQ(rad_to_deg(p.noise_density_radps_rthz), 0.01);
  EXPECT_DOUBLE_EQ(rad_to_deg(p.bias_radps), 0.2);
  EXPECT_DOUBLE_EQ(rad_to_deg(p.bias_instability_radps), 0.005);
  EXPECT_DOUBLE_EQ(p.scale_error, 0.003);
  EXPECT_DOUBLE_EQ(rad_to_deg(p.range_radps), 250.0);
  EXPECT_EQ(p.rate_hz, 200.0);
  EXPECT_EQ(p.latency_ns, 0);
  std::string err;
  EXPECT_TRUE(check_gyro_params(p, &err)) << err;
  const auto s = simulate_gyro(p, kStandstill, 10 * kS);
  ASSERT_EQ(s.size(), 2001u);  // 200 Hz, both ends included
  EXPECT_EQ(s[1].t_ns - s[0].t_ns, 5'000'000);
}

// Allan-like: the mean of M samples of white rate noise has sigma = density / sqrt(M * period),
// whatever M (the signature of angle random walk).
TEST(GyroModel, WhiteNoiseMatchesTheDensity) {
  GyroParams p = ideal();
  p.noise_density_radps_rthz = deg_to_rad(0.01);
  const auto s = simulate_gyro(p, kStandstill, 400 * kS);  // 80001 samples
  for (const int m : {1, 10, 100}) {
    std::vector<double> means;
    for (std::size_t i = 0; i + m <= s.size(); i += m) {
      double sum = 0.0;
      for (int j = 0; j < m; ++j) sum += s[i + j].gyro_z_radps;
      means.push_back(sum / m);
    }
    const double density = stddev(means) * std::sqrt(m * 0.005);
    // sigma of a sample sigma from n values ~ 1/sqrt(2n): 0.25 % .. 2.5 %; allow 4 of them.
    const double tol = 4.0 / std::sqrt(2.0 * static_cast<double>(means.size()));
    EXPECT_NEAR(density / p.noise_density_radps_rthz, 1.0, tol) << "mean of " << m;
  }
}

TEST(GyroModel, ConstantBiasAtStandstill) {
  GyroParams p = ideal();
  p.bias_radps = deg_to_rad(0.2);
  for (const ImuSample& s : simulate_gyro(p, kStandstill, 2 * kS)) {
    EXPECT_DOUBLE_EQ(s.gyro_z_radps, p.bias_radps);
  }
  // With the noise: the long mean is the bias (sigma of a 100 s mean: 0.001 deg/s).
  p.noise_density_radps_rthz = deg_to_rad(0.01);
  const auto s = simulate_gyro(p, kStandstill, 100 * kS);
  double sum = 0.0;
  for (const ImuSample& x : s) sum += x.gyro_z_radps;
  EXPECT_NEAR(rad_to_deg(sum / static_cast<double>(s.size())), 0.2, 0.004);
}

// On the circle after the start ramp the true rate is constant (v / R).
TEST(GyroModel, ScaleError) {
  const Trajectory circle = make(TrajectoryKind::kCircle);
  GyroParams p = ideal();
  p.scale_error = 0.003;
  const auto s = simulate_gyro(p, circle, 20 * kS);
  int checked = 0;
  for (const ImuSample& x : s) {
    if (x.t_ns < 2 * kS) continue;
    const double truth = trajectory_state(circle, x.t_ns).omega_radps;
    ASSERT_GT(truth, 0.4);
    EXPECT_NEAR(x.gyro_z_radps / truth, 1.003, 1e-9) << x.t_ns;
    ++checked;
  }
  EXPECT_GT(checked, 3000);
}

// A real sensor reports its full scale, not more: samples are clipped to +-range, both signs.
TEST(GyroModel, SaturatesAtTheRange) {
  const Trajectory fig8 = make(TrajectoryKind::kFigure8);  // +-0.5 rad/s (28.6 deg/s) arcs
  GyroParams p;                                            // every default error on
  p.range_radps = deg_to_rad(20.0);
  const auto s = simulate_gyro(p, fig8, 60 * kS);
  int pos = 0, neg = 0;
  for (const ImuSample& x : s) {
    ASSERT_LE(std::abs(x.gyro_z_radps), p.range_radps);
    pos += x.gyro_z_radps == p.range_radps;
    neg += x.gyro_z_radps == -p.range_radps;
  }
  EXPECT_GT(pos, 1000);
  EXPECT_GT(neg, 1000);
  // Within range nothing is clipped.
  p.range_radps = deg_to_rad(250.0);
  for (const ImuSample& x : simulate_gyro(p, fig8, 60 * kS)) {
    ASSERT_LT(std::abs(x.gyro_z_radps), deg_to_rad(40.0));
  }
}

// Latency (the gyro's clock offset) moves the stamps only.
TEST(GyroModel, LatencyShiftsTheStamps) {
  const Trajectory line = make(TrajectoryKind::kLine);
  GyroParams p;
  const auto a = simulate_gyro(p, line, 10 * kS);
  p.latency_ns = 7'000'000;
  const auto b = simulate_gyro(p, line, 10 * kS);
  ASSERT_EQ(a.size(), b.size());
  for (std::size_t i = 0; i < a.size(); ++i) {
    EXPECT_EQ(b[i].t_ns, a[i].t_ns + 7'000'000);
    EXPECT_EQ(b[i].gyro_z_radps, a[i].gyro_z_radps);
  }
  EXPECT_EQ(a[0].t_ns, 0);
}

// Error-free samples are the mean rate over their period: summed, they give exactly the heading
// turned, arc entries and exits included (figure8: +2 pi, then -2 pi).
TEST(GyroModel, SamplesIntegrateToTheHeadingTurned) {
  const Trajectory fig8 = make(TrajectoryKind::kFigure8);
  const auto s = simulate_gyro(ideal(), fig8, 30 * kS);
  double turned = 0.0, max_err = 0.0;
  for (std::size_t i = 1; i < s.size(); ++i) {
    turned += s[i].gyro_z_radps * 0.005;
    const double truth = trajectory_state(fig8, s[i].t_ns).pose.theta_rad;
    max_err = std::max(max_err, std::abs(wrap_angle_rad(fig8.start.theta_rad + turned - truth)));
  }
  EXPECT_LT(max_err, 1e-9);
}

// Bias instability: a Gauss-Markov process with the stated sigma and correlation time.
TEST(GyroModel, GaussMarkovBias) {
  GyroParams p = ideal();
  p.rate_hz = 10.0;
  p.bias_instability_radps = deg_to_rad(0.005);
  p.bias_correlation_s = 1.0;
  const auto s = simulate_gyro(p, kStandstill, 4000 * kS);  // 4000 correlation times
  std::vector<double> v;
  for (const ImuSample& x : s) v.push_back(x.gyro_z_radps);
  EXPECT_NEAR(stddev(v) / p.bias_instability_radps, 1.0, 0.08);
  // Correlation at a lag of one correlation time (10 samples): e^-1.
  double c0 = 0.0, c10 = 0.0;
  for (std::size_t i = 0; i + 10 < v.size(); ++i) {
    c0 += v[i] * v[i];
    c10 += v[i] * v[i + 10];
  }
  EXPECT_NEAR(c10 / c0, std::exp(-1.0), 0.06);
}

// Bias random walk: after t the bias has sigma K sqrt(t) (over many seeds).
TEST(GyroModel, BiasRandomWalk) {
  GyroParams p = ideal();
  p.rate_hz = 10.0;
  p.bias_random_walk_radps_rts = deg_to_rad(1e-3);
  std::vector<double> ends;
  for (std::uint64_t seed = 1; seed <= 400; ++seed) {
    p.seed = seed;
    ends.push_back(simulate_gyro(p, kStandstill, 100 * kS).back().gyro_z_radps);
  }
  EXPECT_NEAR(stddev(ends) / (p.bias_random_walk_radps_rts * std::sqrt(100.0)), 1.0, 0.15);
}

TEST(GyroModel, SeededAndChecked) {
  const Trajectory line = make(TrajectoryKind::kLine);
  GyroParams p;
  const auto a = simulate_gyro(p, line, 5 * kS), b = simulate_gyro(p, line, 5 * kS);
  p.seed = 2;
  const auto c = simulate_gyro(p, line, 5 * kS);
  ASSERT_EQ(a.size(), c.size());
  int same = 0;
  for (std::size_t i = 0; i < a.size(); ++i) {
    EXPECT_EQ(a[i].gyro_z_radps, b[i].gyro_z_radps);
    same += a[i].gyro_z_radps == c[i].gyro_z_radps;
  }
  EXPECT_EQ(same, 0);
  std::string err;
  p.rate_hz = 0.0;
  EXPECT_FALSE(check_gyro_params(p, &err));
  EXPECT_NE(err.find("rate"), std::string::npos) << err;
  EXPECT_TRUE(simulate_gyro(p, line, kS).empty());
  p = GyroParams{};
  p.range_radps = -1.0;
  EXPECT_FALSE(check_gyro_params(p, &err));
  p = GyroParams{};
  p.noise_density_radps_rthz = std::nan("");
  EXPECT_FALSE(check_gyro_params(p, &err));
}
