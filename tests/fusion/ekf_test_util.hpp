// What the fusion tests share: time units and a landmark fix covariance of the size the vision
// stage reports (0.2 mm, 0.03 deg by default).
#pragma once

#include <Eigen/Core>
#include <cstdint>

#include "agv/common/geometry.hpp"

namespace agv::fusion::test {

inline constexpr std::int64_t kMs = 1'000'000;
inline constexpr std::int64_t kS = 1'000'000'000;

inline Eigen::Matrix3d fix_cov(double sigma_mm = 0.2, double sigma_deg = 0.03) {
  Eigen::Matrix3d R = Eigen::Matrix3d::Zero();
  R(0, 0) = R(1, 1) = sigma_mm * sigma_mm;
  R(2, 2) = deg_to_rad(sigma_deg) * deg_to_rad(sigma_deg);
  return R;
}

}  // namespace agv::fusion::test
