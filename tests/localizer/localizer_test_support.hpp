// What the localizer core's tests share: the configuration they drive it with and a good fix.
#pragma once

#include <cstdint>

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

// A QR fix of landmark 9 putting the vehicle at (x_mm, 0) heading 0, sigma 0.1 mm / 1 mrad.
inline vision::LandmarkFix good_fix(double x_mm) {
  vision::LandmarkFix fix;
  fix.status = vision::FixStatus::kOk;
  fix.landmark_id = 9;
  fix.vehicle_in_world = {x_mm, 0.0, 0.0};
  fix.cov_world = Eigen::Matrix3d::Identity() * 0.01;
  fix.cov_world(2, 2) = 1e-6;
  return fix;
}

}  // namespace agv::localizer_test
