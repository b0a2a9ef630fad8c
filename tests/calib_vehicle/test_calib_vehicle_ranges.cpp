// calibrate vehicle results against the configuration's ranges (issue 36): time_offset_ms 719.94
// and speed_scale 0.327 were written as "ok", and --check-config then rejected both. The ranges
// are the key table's (key_ranges.hpp), not copies.
#include <gtest/gtest.h>

#include <cmath>

#include "agv/config/keys.hpp"
#include "key_ranges.hpp"

namespace {

TEST(CalibVehicleRanges, ResultsTheConfigurationRejectsAreNamed) {
  const std::string t = agv::desk::outside_key_range("odometry.time_offset_ms", 719.94);
  EXPECT_NE(t.find("odometry.time_offset_ms 719.94 is outside the accepted -500..500 ms"),
            std::string::npos)
      << t;
  const std::string s = agv::desk::outside_key_range("odometry.speed_scale", 0.327);
  EXPECT_NE(s.find("odometry.speed_scale 0.327 is outside"), std::string::npos) << s;
  EXPECT_FALSE(agv::desk::outside_key_range("mounting.height_mm", std::nan("")).empty());
  EXPECT_TRUE(agv::desk::outside_key_range("odometry.time_offset_ms", 12.0).empty());
  EXPECT_TRUE(agv::desk::outside_key_range("odometry.speed_scale", 1.02).empty());
  // The limits follow the table: its edges are accepted, one step beyond is not.
  for (const char* name : {"odometry.time_offset_ms", "odometry.speed_scale",
                           "odometry.yaw_rate_scale", "mounting.height_mm", "mounting.roll_deg"}) {
    const agv::config::Key* k = agv::config::find_key(name);
    ASSERT_NE(k, nullptr) << name;
    EXPECT_TRUE(agv::desk::outside_key_range(name, k->lo).empty()) << name;
    EXPECT_TRUE(agv::desk::outside_key_range(name, k->hi).empty()) << name;
    EXPECT_FALSE(agv::desk::outside_key_range(name, k->hi + 1e-9 * (1 + k->hi)).empty()) << name;
  }
}

}  // namespace
