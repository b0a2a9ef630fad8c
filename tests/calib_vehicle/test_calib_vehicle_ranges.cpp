// calibrate vehicle results against the configuration's ranges: time_offset_ms 719.94
// and speed_scale 0.327 were written as "ok", and --check-config then rejected both. The ranges
// are the key table's (key_ranges.hpp), not copies.
#include <gtest/gtest.h>

#include <cmath>

#include "agv/config/keys.hpp"
#include "calib_vehicle.hpp"
#include "key_ranges.hpp"

namespace {

TEST(CalibVehicleRanges, ResultsTheConfigurationRejectsAreNamed) {
  const std::string t = agv::desk::outside_key_range("camera.time_offset_ms", 719.94);
  EXPECT_NE(t.find("camera.time_offset_ms 719.94 is outside the accepted -500..500 ms"),
            std::string::npos)
      << t;
  const std::string s = agv::desk::outside_key_range("odometry.speed_scale", 0.327);
  EXPECT_NE(s.find("odometry.speed_scale 0.327 is outside"), std::string::npos) << s;
  EXPECT_FALSE(agv::desk::outside_key_range("mounting.height_mm", std::nan("")).empty());
  EXPECT_TRUE(agv::desk::outside_key_range("camera.time_offset_ms", 12.0).empty());
  EXPECT_TRUE(agv::desk::outside_key_range("odometry.speed_scale", 1.02).empty());
  // The limits follow the table: its edges are accepted, one step beyond is not.
  for (const char* name : {"camera.time_offset_ms", "odometry.speed_scale",
                           "odometry.yaw_rate_scale", "mounting.height_mm", "mounting.roll_deg"}) {
    const agv::config::Key* k = agv::config::find_key(name);
    ASSERT_NE(k, nullptr) << name;
    EXPECT_TRUE(agv::desk::outside_key_range(name, k->lo).empty()) << name;
    EXPECT_TRUE(agv::desk::outside_key_range(name, k->hi).empty()) << name;
    EXPECT_FALSE(agv::desk::outside_key_range(name, k->hi + 1e-9 * (1 + k->hi)).empty()) << name;
  }
}

}  // namespace

// What commissioning determined narrows the filter's priors ("what the calibration has learned
// must shrink the uncertainty it causes"); every written key exists in the key table and
// accepts its value; what was not determined keeps the default prior.
TEST(CalibVehiclePriors, DeterminedOdometryNarrowsTheFilterPriors) {
  namespace vcal = agv::desk::vcal;
  vcal::Result r;
  auto add = [&r](const char* name, double value, double sigma, bool determined) {
    vcal::ParamReport p;
    p.name = name;
    p.value = value;
    p.sigma = sigma;
    p.determined = determined;
    r.params.push_back(p);
  };
  add("odometry.speed_scale", 1.02, 0.0003, true);       // 3 sigma 0.00088: the floor
  add("odometry.yaw_rate_scale", 0.5, 0.002, true);      // relative 0.004, 3 sigma 0.012
  add("odometry.yaw_rate_bias_degps", 0.3, 0.04, true);  // 3 sigma 0.12 deg/s
  add("odometry.yaw_per_metre_deg", 0.1, 0.01, false);   // not determined: not written
  add("camera.time_offset_ms", 12.0, 0.1, true);         // no filter state
  const std::vector<vcal::FilterPrior> priors = vcal::odometry_priors(r);
  ASSERT_EQ(priors.size(), 3u);
  EXPECT_EQ(priors[0].key, "init_v_scale_sigma");
  EXPECT_DOUBLE_EQ(priors[0].value, vcal::kMinPriorScale);
  EXPECT_EQ(priors[1].key, "init_omega_scale_sigma");
  EXPECT_NEAR(priors[1].value, 0.012, 1e-12);
  EXPECT_EQ(priors[2].key, "init_omega_bias_sigma_degps");
  EXPECT_NEAR(priors[2].value, 0.12, 1e-12);
  for (const auto& p : priors) {
    const agv::config::Key* k = agv::config::find_key("fusion." + p.key);
    ASSERT_NE(k, nullptr) << p.key;
    EXPECT_TRUE(agv::desk::outside_key_range(k->name, p.value).empty()) << p.key;
    // Narrower than the default prior of a vehicle nobody measured.
    EXPECT_LT(p.value, std::get<double>(k->def)) << p.key;
  }
  r.params[3].determined = true;  // a tiny sigma still gets the floor
  EXPECT_DOUBLE_EQ(vcal::odometry_priors(r)[3].value, vcal::kMinPriorDegpm);
}
