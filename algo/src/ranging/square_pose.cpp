#include "agv/ranging/square_pose.hpp"

#include <cmath>

namespace agv::ranging {

namespace {

Eigen::Matrix3d square_pose_exp(const Eigen::Vector3d& w) {
  const double a = w.norm();
  if (!(a > 0.0)) return Eigen::Matrix3d::Identity();
  return Eigen::AngleAxisd(a, w / a).toRotationMatrix();
}

SquareCorners8 square_pose_target(const std::array<Vec2, 4>& image_px) {
  SquareCorners8 m;
  for (int i = 0; i < 4; ++i) {
    m[2 * i] = image_px[static_cast<std::size_t>(i)].x;
    m[2 * i + 1] = image_px[static_cast<std::size_t>(i)].y;
  }
  return m;
}

}  // namespace

bool project_square(double fx, double fy, double cx, double cy, double side_mm,
                    const Eigen::Matrix3d& R_CT, const Eigen::Vector3d& t_C_mm, SquareCorners8* uv,
                    SquareJacobian* J) {
  const double h = side_mm / 2.0;
  const double corners[4][2] = {{-h, h}, {h, h}, {h, -h}, {-h, -h}};
  bool in_front = true;
  for (int i = 0; i < 4; ++i) {
    const Eigen::Vector3d RP = R_CT.col(0) * corners[i][0] + R_CT.col(1) * corners[i][1];
    const Eigen::Vector3d X = RP + t_C_mm;
    in_front = in_front && X.z() > 0.0 && X.allFinite();
    const double iz = 1.0 / X.z(), x = X.x() * iz, y = X.y() * iz;
    (*uv)[2 * i] = fx * x + cx;
    (*uv)[2 * i + 1] = fy * y + cy;
    if (J == nullptr) continue;
    // d(u, v)/dX, then dX/d_omega = -[R P]x and dX/d_t = I.
    Eigen::Matrix<double, 2, 3> dp;
    dp << fx * iz, 0.0, -fx * x * iz, 0.0, fy * iz, -fy * y * iz;
    Eigen::Matrix3d minus_skew;
    minus_skew << 0.0, RP.z(), -RP.y(), -RP.z(), 0.0, RP.x(), RP.y(), -RP.x(), 0.0;
    J->block<2, 3>(2 * i, 0) = dp * minus_skew;
    J->block<2, 3>(2 * i, 3) = dp;
  }
  return in_front && uv->allFinite();
}

SquarePose refine_square_pose(double fx, double fy, double cx, double cy, double side_mm,
                              const std::array<Vec2, 4>& image_px, const Eigen::Matrix3d& R_CT,
                              const Eigen::Vector3d& t_C_mm, int max_iterations) {
  SquarePose out;
  const SquareCorners8 target = square_pose_target(image_px);
  SquareCorners8 uv;
  SquareJacobian J;
  if (!project_square(fx, fy, cx, cy, side_mm, R_CT, t_C_mm, &uv, &J)) return out;
  out.R_CT = R_CT;
  out.t_C_mm = t_C_mm;
  out.squared_error_px2 = (uv - target).squaredNorm();
  if (!std::isfinite(out.squared_error_px2)) return out;
  out.ok = true;
  double lambda = 0.0;  // Gauss-Newton until a step fails to descend
  for (int it = 0; it < max_iterations; ++it) {
    const Eigen::Matrix<double, 6, 6> A = J.transpose() * J;
    const Eigen::Matrix<double, 6, 1> g = J.transpose() * (uv - target);
    bool stepped = false;
    Eigen::Matrix<double, 6, 1> d = Eigen::Matrix<double, 6, 1>::Zero();
    while (lambda < 1e12) {
      Eigen::Matrix<double, 6, 6> Ad = A;
      Ad.diagonal() *= 1.0 + lambda;
      d = -Ad.ldlt().solve(g);
      if (!d.allFinite()) break;
      const Eigen::Matrix3d R = square_pose_exp(d.head<3>()) * out.R_CT;
      const Eigen::Vector3d t = out.t_C_mm + d.tail<3>();
      SquareCorners8 uv_new;
      SquareJacobian J_new;
      if (project_square(fx, fy, cx, cy, side_mm, R, t, &uv_new, &J_new)) {
        const double e = (uv_new - target).squaredNorm();
        if (e <= out.squared_error_px2) {
          out.R_CT = R;
          out.t_C_mm = t;
          out.squared_error_px2 = e;
          uv = uv_new;
          J = J_new;
          lambda *= 0.1;
          stepped = true;
          break;
        }
      }
      lambda = lambda > 0.0 ? 10.0 * lambda : 1e-3;
    }
    out.iterations = it + 1;
    // Converged: the step moved the corners by well under a nanopixel, or nothing descends.
    if (!stepped || (J * d).cwiseAbs().maxCoeff() < 1e-10) break;
  }
  return out;
}

}  // namespace agv::ranging
