// A square tag's pose from its four corners on a pinhole camera: the corners' projection and its
// Jacobian in closed form, and the least-squares refinement of a starting pose (IPPE's) on them.
// Fixed-size Eigen, no allocation: measure() runs it per landmark and per frame.
#pragma once

#include <Eigen/Dense>
#include <array>

#include "agv/common/geometry.hpp"

namespace agv::ranging {

// The square's corners in its own frame (z = 0), side 2 h, in IPPE's order: (-h, h), (h, h),
// (h, -h), (-h, -h). Rows 2i and 2i+1 of the vectors and Jacobians below are corner i's u and v.
using SquareCorners8 = Eigen::Matrix<double, 8, 1>;
using SquareJacobian = Eigen::Matrix<double, 8, 6>;

// Pinhole projection u = fx X/Z + cx, v = fy Y/Z + cy of the corners at X = R_CT P + t_C, and
// (when J is not null) its Jacobian over (d_omega, d_t): R_CT -> exp([d_omega]x) R_CT, t_C -> t_C
// + d_t (the convention of range_bearing_from_tag_pose). False when a corner is not in front of
// the camera (Z <= 0) or a value is not finite; uv and J are still the formulas' values then.
bool project_square(double fx, double fy, double cx, double cy, double side_mm,
                    const Eigen::Matrix3d& R_CT, const Eigen::Vector3d& t_C_mm, SquareCorners8* uv,
                    SquareJacobian* J);

struct SquarePose {
  bool ok = false;  // a finite pose with every corner in front of the camera
  Eigen::Matrix3d R_CT = Eigen::Matrix3d::Identity();
  Eigen::Vector3d t_C_mm = Eigen::Vector3d::Zero();
  double squared_error_px2 = 0.0;  // sum over the eight coordinates at the returned pose
  int iterations = 0;
};

// Levenberg-Marquardt (Gauss-Newton while it descends) from (R_CT, t_C_mm) to the pose that
// minimises the squared pinhole reprojection error of the four corners `image_px` (IPPE's order,
// undistorted pixels). Never returns a pose worse than the start; at most max_iterations steps.
SquarePose refine_square_pose(double fx, double fy, double cx, double cy, double side_mm,
                              const std::array<Vec2, 4>& image_px, const Eigen::Matrix3d& R_CT,
                              const Eigen::Vector3d& t_C_mm, int max_iterations = 50);

}  // namespace agv::ranging
