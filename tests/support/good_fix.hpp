// A confident landmark fix for the tests that drive the localizer core or the firmware loop.
#pragma once

#include <cstdint>

#include "agv/vision/landmark_localizer.hpp"

namespace agv::test {

// A QR fix of `landmark_id` putting the vehicle at (x_mm, 0) heading 0, sigma 0.1 mm / 1 mrad.
inline vision::LandmarkFix good_fix(double x_mm, std::uint32_t landmark_id = 9) {
  vision::LandmarkFix fix;
  fix.status = vision::FixStatus::kOk;
  fix.landmark_id = landmark_id;
  fix.vehicle_in_world = {x_mm, 0.0, 0.0};
  fix.cov_world = Eigen::Matrix3d::Identity() * 0.01;
  fix.cov_world(2, 2) = 1e-6;
  return fix;
}

}  // namespace agv::test
