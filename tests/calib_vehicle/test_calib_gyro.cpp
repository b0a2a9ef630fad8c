// Gyro calibration (tools/desk/src/calib_gyro.*) on the simulated calibration drive of
// calib_drive.hpp with a gyro of known scale error, bias and latency: imu.scale, imu.bias_degps
// and the clock offset recovered within 3 sigma, under the mounting the vehicle calibration found;
// a bad fix does not move them; a drive without turns refuses the scale and names why.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>

#include "calib_drive.hpp"
#include "calib_gyro.hpp"

using namespace agv;
using namespace agv::desk::vcal;

namespace {

calibtest::DriveTruth gyro_drive(unsigned seed) {
  calibtest::DriveTruth t = calibtest::perturbed_drive(seed);
  // The simulator's default gyro (docs/design/simulator.md "Gyro"), other signs for even seeds.
  const double sgn = seed % 2 == 0 ? -1.0 : 1.0;
  t.gyro_scale_error = 0.003 * sgn;
  t.gyro_bias_radps = deg_to_rad(0.2) * sgn;
  t.gyro_latency_s = 0.004;
  return t;
}

// The correction that undoes the simulated error (localizer::GyroCorrection: rate' = scale *
// rate + bias): rate = (1 + e) true + b  ->  true = rate / (1 + e) - b / (1 + e).
double true_scale(const calibtest::DriveTruth& t) { return 1.0 / (1.0 + t.gyro_scale_error); }
double true_bias(const calibtest::DriveTruth& t) {
  return -t.gyro_bias_radps / (1.0 + t.gyro_scale_error);
}

// The gyro calibration under the drive's true mounting and clock, odometry scale 1.
bool true_mount_gyro(const calibtest::Drive& d, const calibtest::DriveTruth& t, GyroResult* g,
                     std::string* error) {
  return calibrate_gyro(d.gyro, d.obs, d.map, calibtest::kOuterHalfMm, calibtest::kInnerHalfMm,
                        t.p.mount, 1.0, 0.0, GyroOptions{}, g, error);
}

Options vehicle_options() {
  Options o;
  o.fx_px = CameraModel::default_640x480().intrinsics.fx;
  o.pixel_sigma_px = 0.05;
  return o;
}

void print(const char* what, const calibtest::DriveTruth& t, const GyroResult& g) {
  std::printf(
      "%s seed %u: scale true %.6f est %.6f sigma %.6f (err %.2f sigma) | bias true %.4f est "
      "%.4f sigma %.4f deg/s (err %.2f sigma) | offset true %.2f est %.2f sigma %.2f ms | %d/%d "
      "frames, heading noise %.4f deg, turned %.0f deg, chi2 %.2f\n",
      what, t.seed, true_scale(t), g.scale, g.scale_sigma,
      (g.scale - true_scale(t)) / std::max(g.scale_sigma, 1e-12), rad_to_deg(true_bias(t)),
      rad_to_deg(g.bias_radps), rad_to_deg(g.bias_sigma_radps),
      (g.bias_radps - true_bias(t)) / std::max(g.bias_sigma_radps, 1e-12), t.gyro_latency_s * 1e3,
      g.clock_offset_s * 1e3, g.clock_offset_sigma_s * 1e3, g.frames_used, g.frames,
      g.heading_sigma_deg, g.turned_deg, g.chi2_per_frame);
}

}  // namespace

class CalibGyroSeeds : public ::testing::TestWithParam<unsigned> {};

// Under the mounting the vehicle calibration estimated (as `calibrate vehicle` runs it).
TEST_P(CalibGyroSeeds, RecoversScaleAndBiasWithinThreeSigma) {
  const calibtest::DriveTruth t = gyro_drive(GetParam());
  const calibtest::Drive d = calibtest::make_calibration_drive(t);
  ASSERT_FALSE(d.gyro.empty());
  Result r;
  std::string err;
  ASSERT_TRUE(calibtest::calibrate_from_nominal(d, vehicle_options(), &r, &err)) << err;
  GyroResult g;
  // Gyro clock - camera clock starts from the odometry's (as the command does); the truth is the
  // gyro's latency.
  ASSERT_TRUE(calibrate_gyro(d.gyro, d.obs, d.map, 30.0, 24.0, r.estimate.mount, 1.0,
                             r.estimate.time_offset_s, GyroOptions{}, &g, &err))
      << err;
  print("calibrated mounting", t, g);
  EXPECT_TRUE(g.scale_determined) << g.why_scale;
  EXPECT_TRUE(g.bias_determined) << g.why_bias;
  EXPECT_FALSE(g.scale_fixed);
  EXPECT_GT(g.scale_sigma, 0.0);
  EXPECT_GT(g.bias_sigma_radps, 0.0);
  EXPECT_NEAR(g.scale, true_scale(t), 3.0 * g.scale_sigma);
  EXPECT_NEAR(g.bias_radps, true_bias(t), 3.0 * g.bias_sigma_radps);
  EXPECT_NEAR(g.clock_offset_s, t.gyro_latency_s, std::max(3.0 * g.clock_offset_sigma_s, 1e-4));
  // The written filter priors: 3 sigma, floored.
  EXPECT_DOUBLE_EQ(g.prior_scale_sigma, std::max(3.0 * g.scale_sigma, 0.0005));
  EXPECT_GE(g.prior_bias_sigma_degps, 0.05);
  EXPECT_EQ(g.frames_rejected, 0);
}

INSTANTIATE_TEST_SUITE_P(Drives, CalibGyroSeeds, ::testing::Values(1u, 2u, 3u));

// Headings of the frames under the true mounting are the true headings (the sign of the rigid
// fit's yaw and the map's landmark heading): integrating a perfect gyro gives scale 1, bias 0.
TEST(CalibGyro, PerfectGyroUnderTrueMountingGivesIdentity) {
  calibtest::DriveTruth t = gyro_drive(1);
  t.gyro_scale_error = 0.0;
  t.gyro_bias_radps = 0.0;
  t.gyro_latency_s = 0.0;
  const calibtest::Drive d = calibtest::make_calibration_drive(t);
  GyroResult g;
  std::string err;
  ASSERT_TRUE(true_mount_gyro(d, t, &g, &err)) << err;
  print("true mounting, perfect gyro", t, g);
  EXPECT_NEAR(g.scale, 1.0, std::max(3.0 * g.scale_sigma, 1e-5));
  EXPECT_NEAR(g.bias_radps, 0.0, std::max(3.0 * g.bias_sigma_radps, 1e-6));
  EXPECT_LT(g.scale_sigma, 0.0005);
}

// A few frames whose fix is rotated by 3 degrees (a misread landmark): left out, estimate unmoved.
TEST(CalibGyro, BadFixesAreLeftOut) {
  const calibtest::DriveTruth t = gyro_drive(1);
  calibtest::Drive d = calibtest::make_calibration_drive(t);
  const double a = deg_to_rad(3.0), c = std::cos(a), s = std::sin(a);
  int bad = 0;
  for (size_t i = 100; i < d.obs.size() && bad < 8; i += d.obs.size() / 9, ++bad) {
    for (Vec2& x : d.obs[i].xn) x = {c * x.x - s * x.y, s * x.x + c * x.y};
  }
  GyroResult g;
  std::string err;
  ASSERT_TRUE(true_mount_gyro(d, t, &g, &err)) << err;
  print("8 bad fixes", t, g);
  EXPECT_GE(g.frames_rejected, bad);
  EXPECT_LE(g.frames_rejected, bad + 10);
  EXPECT_TRUE(g.scale_determined) << g.why_scale;
  EXPECT_NEAR(g.scale, true_scale(t), 3.0 * g.scale_sigma);
  EXPECT_NEAR(g.bias_radps, true_bias(t), 3.0 * g.bias_sigma_radps);
  ASSERT_FALSE(g.warnings.empty());
  EXPECT_NE(g.warnings[0].find("left out of the gyro calibration"), std::string::npos);
}

// Straight passes only: the scale is not observable; refused with the reason, and the bias is
// solved with the configured scale (here 1: the bias is then minus the sensor's bias).
TEST(CalibGyro, NoTurnsRefusesScale) {
  calibtest::DriveTruth t = gyro_drive(1);
  t.turns = false;
  const calibtest::Drive d = calibtest::make_calibration_drive(t);
  GyroResult g;
  std::string err;
  ASSERT_TRUE(true_mount_gyro(d, t, &g, &err)) << err;
  print("no turns", t, g);
  EXPECT_FALSE(g.scale_determined);
  EXPECT_TRUE(g.scale_fixed);
  EXPECT_DOUBLE_EQ(g.scale, 1.0);
  EXPECT_NE(g.why_scale.find("needs turns"), std::string::npos) << g.why_scale;
  EXPECT_LT(g.turned_deg, 20.0);
  EXPECT_TRUE(g.bias_determined) << g.why_bias;
  EXPECT_NEAR(g.bias_radps, -t.gyro_bias_radps, std::max(3.0 * g.bias_sigma_radps, 1e-6));
}

TEST(CalibGyro, NothingToEstimateFromNamesWhy) {
  const calibtest::Drive d = calibtest::make_calibration_drive(gyro_drive(1));
  GyroResult g;
  std::string err;
  EXPECT_FALSE(calibrate_gyro({}, d.obs, d.map, 30.0, 24.0, CameraModel::default_640x480().mount,
                              1.0, 0.0, GyroOptions{}, &g, &err));
  EXPECT_NE(err.find("gyro samples"), std::string::npos) << err;
  // Gyro samples that end before the first frame.
  std::vector<GyroSample> early(d.gyro.begin(), d.gyro.begin() + 20);
  for (auto& s : early) s.t_ns -= 100'000'000'000LL;
  EXPECT_FALSE(calibrate_gyro(early, d.obs, d.map, 30.0, 24.0, CameraModel::default_640x480().mount,
                              1.0, 0.0, GyroOptions{}, &g, &err));
  EXPECT_NE(err.find("time span"), std::string::npos) << err;
}
