// What the localizer core's tests share: the configuration they drive it with and a good fix
// (tests/support/good_fix.hpp: landmark 9 at (x_mm, 0)).
#pragma once

#include <cstdint>

#include "../support/good_fix.hpp"
#include "agv/localizer/localizer.hpp"

namespace agv::localizer_test {

inline constexpr std::int64_t kMs = 1'000'000;

inline localizer::LocalizerConfig test_config() {
  localizer::LocalizerConfig c;
  c.fusion.health.odom_timeout_ns = 50 * kMs;  // the core's ONE odometry timeout
  c.heartbeat_period_ns = 1000 * kMs;
  c.camera_timeout_ns = 200 * kMs;
  return c;
}

using test::good_fix;

}  // namespace agv::localizer_test
