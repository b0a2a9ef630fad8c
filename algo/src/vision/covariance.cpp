// Stage 6 of the pipeline (docs/design/vision.md), the covariance of the result: of the landmark in
// the vehicle frame from the joint fit's normal equations, and of the vehicle in the world from
// that (pose_covariance.hpp).
#include <Eigen/Dense>
#include <algorithm>

#include "agv/vision/pose_covariance.hpp"
#include "stage_common.hpp"

namespace agv::vision {

namespace {

// Central-difference steps of the world-pose Jacobian: well below the smallest measurement sigmas
// (sigma floors 0.05 mm and 0.01 deg = 1.7e-4 rad), so the linearisation is local, and well above
// the rounding of world coordinates of a few hundred metres (~1e-10 mm), so the differences are
// not rounding noise. The map is a rotation plus lever arm, smooth at this scale.
constexpr double kJacobianStepMm = 1e-4;
constexpr double kJacobianStepRad = 1e-7;

}  // namespace

// The fit covariance assumes independent edge points: (J^T J)^-1 s^2 over (c_x, c_y, beta), with
// the size parameters marginalised out when they were fitted (n_params 4 or 5), inflated and
// floored as VisionConfig says. Each point counts as the edge_row_step rows it stands for, as in
// the point minimums: cov_inflation was measured at step 1, where it stands for the correlation of
// neighbouring rows (shared blur), and the rows between the points taken are no less correlated
// with them; measured (docs/design/vision.md "Row step"), the error grows by far less than
// sqrt(step).
Eigen::Matrix3d fit_covariance(const NormalEquations& ne, int n_params, const VisionConfig& cfg) {
  const double dof = std::max(1.0, ne.sum_w - n_params);
  const double s2 = ne.ssr / dof / std::max(1, cfg.edge_row_step);
  Eigen::Matrix3d cv3;
  if (n_params == 5) {
    const Eigen::Matrix<double, 5, 5> inv =
        ne.jtj.ldlt().solve(Eigen::Matrix<double, 5, 5>::Identity());
    cv3 = inv.topLeftCorner<3, 3>() * s2 * cfg.cov_inflation;
  } else if (n_params == 4) {
    const Eigen::Matrix4d inv =
        ne.jtj.topLeftCorner<4, 4>().ldlt().solve(Eigen::Matrix4d::Identity());
    cv3 = inv.topLeftCorner<3, 3>() * s2 * cfg.cov_inflation;
  } else {
    cv3 = ne.jtj.topLeftCorner<3, 3>().ldlt().solve(Eigen::Matrix3d::Identity()) * s2 *
          cfg.cov_inflation;
  }
  cv3(0, 0) += cfg.sigma_floor_mm * cfg.sigma_floor_mm;
  cv3(1, 1) += cfg.sigma_floor_mm * cfg.sigma_floor_mm;
  cv3(2, 2) += deg_to_rad(cfg.sigma_floor_deg) * deg_to_rad(cfg.sigma_floor_deg);
  return cv3;
}

Eigen::Matrix3d vehicle_in_world_covariance(const Pose2& world_landmark,
                                            const Pose2& landmark_in_vehicle,
                                            const Eigen::Matrix3d& cov_landmark_in_vehicle) {
  Eigen::Matrix3d jac;
  const double eps[3] = {kJacobianStepMm, kJacobianStepMm, kJacobianStepRad};
  for (int j = 0; j < 3; ++j) {
    Pose2 a = landmark_in_vehicle, b = landmark_in_vehicle;
    double* pa = j == 0 ? &a.x_mm : j == 1 ? &a.y_mm : &a.theta_rad;
    double* pb = j == 0 ? &b.x_mm : j == 1 ? &b.y_mm : &b.theta_rad;
    *pa += eps[j];
    *pb -= eps[j];
    const Pose2 wa = compose(world_landmark, inverse(a)), wb = compose(world_landmark, inverse(b));
    jac(0, j) = (wa.x_mm - wb.x_mm) / (2 * eps[j]);
    jac(1, j) = (wa.y_mm - wb.y_mm) / (2 * eps[j]);
    jac(2, j) = wrap_angle_rad(wa.theta_rad - wb.theta_rad) / (2 * eps[j]);
  }
  // Assigned to an existing matrix, not constructed from the expression: Eigen evaluates the two
  // forms along different paths, which round some off-diagonal entries differently in the last
  // bit. This form is the one the localizer always used, so its fixes stay bit-identical.
  Eigen::Matrix3d cov_world;
  cov_world = jac * cov_landmark_in_vehicle * jac.transpose();
  return cov_world;
}

}  // namespace agv::vision
