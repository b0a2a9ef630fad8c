// Covariance of the vision stage's world pose. One function for the product (LandmarkLocalizer
// fills LandmarkFix::cov_world with it) and for the evaluation tools that simulate fixes
// (tools/eval/fusion), so a simulated fix carries exactly the covariance a real one would.
#pragma once

#include <Eigen/Core>

#include "agv/common/geometry.hpp"

namespace agv::vision {

// Covariance of W<-V = (W<-L) (+) inverse(V<-L) (x_mm, y_mm, theta_rad) from the covariance of
// the measured V<-L (x_mm, y_mm, theta_rad), by first-order propagation with a central-difference
// Jacobian. The landmark's world pose is exact (surveyed or Reed-Solomon-checked payload). The
// result is J C J^T as computed, not symmetrised: off-diagonal pairs differ by up to ~1.5e-16
// relative (rounding), far inside the 1e-9 that Ekf::add_fix tolerates; the EKF's LLT and
// eigen solvers read one triangle and its covariance update is symmetrised.
Eigen::Matrix3d vehicle_in_world_covariance(const Pose2& world_landmark,
                                            const Pose2& landmark_in_vehicle,
                                            const Eigen::Matrix3d& cov_landmark_in_vehicle);

}  // namespace agv::vision
