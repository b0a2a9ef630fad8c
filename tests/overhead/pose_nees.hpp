// The squared Mahalanobis distance of a pose error (x, y, theta) under its 3 x 3 covariance, the
// normalised estimation error squared the overhead tests check the reported sigmas with.
#pragma once

#include <array>

#include "agv/common/geometry.hpp"

namespace agv::overhead::test {

inline double pose_nees(const Pose2& est, const std::array<double, 9>& c, const Pose2& truth) {
  const double e[3] = {est.x_mm - truth.x_mm, est.y_mm - truth.y_mm,
                       wrap_angle_rad(est.theta_rad - truth.theta_rad)};
  // e^T C^-1 e through the adjugate of the symmetric covariance.
  const double a00 = c[4] * c[8] - c[5] * c[7], a01 = c[2] * c[7] - c[1] * c[8],
               a02 = c[1] * c[5] - c[2] * c[4], a11 = c[0] * c[8] - c[2] * c[6],
               a12 = c[2] * c[3] - c[0] * c[5], a22 = c[0] * c[4] - c[1] * c[3];
  const double det =
      c[0] * a00 + c[1] * (c[5] * c[6] - c[3] * c[8]) + c[2] * (c[3] * c[7] - c[4] * c[6]);
  const double q = e[0] * (a00 * e[0] + a01 * e[1] + a02 * e[2]) +
                   e[1] * (a01 * e[0] + a11 * e[1] + a12 * e[2]) +
                   e[2] * (a02 * e[0] + a12 * e[1] + a22 * e[2]);
  return q / det;
}

}  // namespace agv::overhead::test
