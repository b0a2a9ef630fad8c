// The tracking prediction the vision tests hand the localizer: the fused vehicle pose `v` with a
// diagonal covariance of the given position and heading sigmas.
#pragma once

#include <Eigen/Core>

#include "agv/common/geometry.hpp"
#include "agv/vision/landmark_localizer.hpp"

namespace agv::testsupport {

inline vision::Prediction predict(const Pose2& v, double sigma_mm, double sigma_deg) {
  vision::Prediction p;
  p.valid = true;
  p.vehicle_in_world = v;
  p.cov = Eigen::Vector3d(sigma_mm * sigma_mm, sigma_mm * sigma_mm,
                          deg_to_rad(sigma_deg) * deg_to_rad(sigma_deg))
              .asDiagonal();
  return p;
}

}  // namespace agv::testsupport
