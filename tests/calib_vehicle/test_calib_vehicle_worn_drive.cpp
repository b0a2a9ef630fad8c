// Worn-floor regression: on a calibration drive where one of three landmarks is worn (its corners
// off the printed square by about 0.1 mm, the same in every frame, plus more noise), the
// reported sigmas must cover the error. Without the wear model they assume independent pixel
// noise on printed-exact corners: pitch 18 sigma, height 32 sigma off on a worn floor. Uses only
// the interface the clean-floor calibration also had, so it builds and fails without the model.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>

#include "calib_drive.hpp"

using namespace agv;
using namespace agv::desk::vcal;

namespace {

calibtest::DriveTruth worn_drive(unsigned seed) {
  calibtest::DriveTruth t = calibtest::perturbed_drive(seed);
  t.duration_s = 45;
  t.worn = {2};
  t.wear_mm = 0.1;
  t.wear_noise_px = 0.2;
  return t;
}

}  // namespace

class CalibVehicleWornDrive : public ::testing::TestWithParam<unsigned> {};

TEST_P(CalibVehicleWornDrive, SigmaCoversTheError) {
  const calibtest::DriveTruth truth = worn_drive(GetParam());
  const calibtest::Drive d = calibtest::make_calibration_drive(truth);
  Options opt;
  opt.fx_px = CameraModel::default_640x480().intrinsics.fx;
  opt.pixel_sigma_px = 0.05;  // the clean landmarks' corner noise
  Result r;
  std::string err;
  ASSERT_TRUE(calibtest::calibrate_from_nominal(d, opt, &r, &err)) << err;
  const std::array<double, 11> tv = calibtest::reported_truth(truth.p);
  ASSERT_EQ(r.params.size(), 11u);
  std::printf("worn landmark 2, seed %u: RMS %.3f -> %.3f px\n", GetParam(), r.rms_before_px,
              r.rms_after_px);
  for (size_t i = 0; i < 11; ++i) {
    const ParamReport& p = r.params[i];
    const double z = std::abs(p.value - tv[i]) / p.sigma;
    std::printf("%-30s error %+11.5f sigma %10.5f  %5.2f sigma\n", p.name.c_str(), p.value - tv[i],
                p.sigma, z);
    EXPECT_LE(z, 3.0) << p.name;
  }
}

INSTANTIATE_TEST_SUITE_P(Seeds, CalibVehicleWornDrive, ::testing::Values(1u, 2u));
