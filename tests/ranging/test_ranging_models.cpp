// Range models: pinhole range from size, column bearing, camera point -> vehicle range/bearing,
// tag pose -> range/bearing/yaw, each against an independent computation (direct geometry,
// central differences, the Fisher information of the four corners).
#include <gtest/gtest.h>

#include <Eigen/Dense>
#include <cmath>

#include "agv/ranging/range_models.hpp"

namespace agv::ranging {
namespace {

using Eigen::Matrix3d;
using Eigen::Vector3d;

CameraIntrinsics forward_camera() {
  return {.width_px = 1280, .height_px = 800, .fx = 900.0, .fy = 900.0, .cx = 639.5, .cy = 399.5};
}

TEST(RangingModels, SizeRangeIsSimilarTrianglesWithFirstOrderVariance) {
  const SizeRange r = size_range(900.0, 150.0, 27.0, 0.3);
  EXPECT_NEAR(r.depth_mm, 5000.0, 1e-9);
  EXPECT_NEAR(std::sqrt(r.var_mm2), 5000.0 / 27.0 * 0.3, 1e-9);
  EXPECT_EQ(size_range(900.0, 150.0, 0.0, 0.3).depth_mm, 0.0);
}

TEST(RangingModels, ColumnBearingIsPositiveToTheLeftOfThePrincipalPoint) {
  const CameraIntrinsics k = forward_camera();
  EXPECT_EQ(column_bearing_rad(k, k.cx), 0.0);
  EXPECT_NEAR(column_bearing_rad(k, k.cx - 900.0), kPi / 4, 1e-15);
  EXPECT_NEAR(column_bearing_rad(k, k.cx + 900.0), -kPi / 4, 1e-15);
  const double h = 1e-4;
  const double d = (column_bearing_rad(k, 100.0 + h) - column_bearing_rad(k, 100.0 - h)) / (2 * h);
  EXPECT_NEAR(std::sqrt(column_bearing_var_rad2(k, 100.0, 0.5)), std::abs(d) * 0.5, 1e-9);
}

TEST(RangingModels, MountAxes) {
  RangingMount m;
  Matrix3d R = rotation_vehicle_from_camera(m);
  EXPECT_TRUE(R.col(2).isApprox(Vector3d(1, 0, 0), 1e-15));   // optical axis forward
  EXPECT_TRUE(R.col(0).isApprox(Vector3d(0, -1, 0), 1e-15));  // image right = vehicle right
  EXPECT_TRUE(R.col(1).isApprox(Vector3d(0, 0, -1), 1e-15));  // image down = down
  m.yaw_rad = kPi / 2;
  R = rotation_vehicle_from_camera(m);
  EXPECT_NEAR((R.col(2) - Vector3d(0, 1, 0)).norm(), 0.0, 1e-15);  // looks left
  m.yaw_rad = 0.0;
  m.pitch_rad = 0.1;
  R = rotation_vehicle_from_camera(m);
  EXPECT_LT(R(2, 2), 0.0);  // positive pitch looks down
}

RangingMount tilted_mount() {
  return {.x_mm = 350.0,
          .y_mm = -120.0,
          .z_mm = 900.0,
          .roll_rad = 0.03,
          .pitch_rad = -0.05,
          .yaw_rad = 0.4};
}

TEST(RangingModels, CameraPointToVehicleRangeBearingMatchesDirectGeometry) {
  const RangingMount m = tilted_mount();
  const Vector3d p_V(4200.0, 2500.0, 1400.0);
  const Matrix3d R_VC = rotation_vehicle_from_camera(m);
  const Vector3d p_C = R_VC.transpose() * (p_V - Vector3d(m.x_mm, m.y_mm, m.z_mm));
  CameraPoint cp{p_C, Matrix3d::Identity() * 100.0};
  const RangeBearing rb = range_bearing_from_camera_point(m, cp);
  EXPECT_NEAR(rb.range_mm, std::hypot(4200.0, 2500.0), 1e-9);
  EXPECT_NEAR(rb.bearing_rad, std::atan2(2500.0, 4200.0), 1e-13);
  EXPECT_FALSE(rb.has_yaw);
  // Covariance against central differences of the whole transform.
  Eigen::Matrix<double, 2, 3> J;
  for (int k = 0; k < 3; ++k) {
    CameraPoint a = cp, b = cp;
    a.p_mm[k] += 1e-3;
    b.p_mm[k] -= 1e-3;
    const RangeBearing ra = range_bearing_from_camera_point(m, a);
    const RangeBearing rb2 = range_bearing_from_camera_point(m, b);
    J(0, k) = (ra.range_mm - rb2.range_mm) / 2e-3;
    J(1, k) = (ra.bearing_rad - rb2.bearing_rad) / 2e-3;
  }
  const Eigen::Matrix2d expect = J * cp.cov_mm2 * J.transpose();
  EXPECT_NEAR((rb.cov.topLeftCorner<2, 2>() - expect).norm() / expect.norm(), 0.0, 1e-6);
}

TEST(RangingModels, SizePointBackProjectsTheCentreToTheDepth) {
  const CameraIntrinsics k = forward_camera();
  const SizeRange d = size_range(k.fx, 150.0, 30.0, 0.3);
  const CameraPoint p = size_camera_point(k, {k.cx + 90.0, k.cy - 45.0}, 0.15, d);
  EXPECT_NEAR(p.p_mm.z(), 4500.0, 1e-9);
  EXPECT_NEAR(p.p_mm.x(), 450.0, 1e-9);
  EXPECT_NEAR(p.p_mm.y(), -225.0, 1e-9);
  EXPECT_NEAR(p.cov_mm2(2, 2), d.var_mm2, 1e-9);
  EXPECT_NEAR(p.cov_mm2(0, 2), 0.1 * d.var_mm2, 1e-9);  // x = xn * depth: correlated with depth
}

Matrix3d exp_so3(const Vector3d& w) {
  const double a = w.norm();
  if (a == 0.0) return Matrix3d::Identity();
  return Eigen::AngleAxisd(a, w / a).toRotationMatrix();
}

TEST(RangingModels, TagPoseGivesTheFaceNormalYawAndItsCovariance) {
  RangingMount m;  // level, forward
  // A tag straight ahead, turned by alpha about the vertical (y_C) axis.
  const double alpha = 0.3;
  const Matrix3d R_CT = Eigen::AngleAxisd(alpha, Vector3d::UnitY()).toRotationMatrix();
  const Vector3d t(0.0, 0.0, 5000.0);
  Eigen::Matrix<double, 6, 6> cov = Eigen::Matrix<double, 6, 6>::Zero();
  cov.diagonal() << 1e-4, 2e-4, 3e-4, 25.0, 36.0, 400.0;
  cov(3, 5) = cov(5, 3) = 10.0;
  const RangeBearing rb = range_bearing_from_tag_pose(m, t, R_CT, cov);
  ASSERT_TRUE(rb.has_yaw);
  EXPECT_NEAR(rb.range_mm, 5000.0, 1e-9);
  EXPECT_NEAR(rb.bearing_rad, 0.0, 1e-15);
  // Facing the camera the normal points back along -x_V (yaw pi); turning the tag about the
  // camera's down axis by alpha turns its normal by -alpha seen from above.
  EXPECT_NEAR(wrap_angle_rad(rb.relative_yaw_rad - (kPi - alpha)), 0.0, 1e-12);
  // Yaw covariance against central differences over the rotation perturbation.
  Eigen::Matrix<double, 3, 6> J = Eigen::Matrix<double, 3, 6>::Zero();
  const double h = 1e-6;
  for (int k = 0; k < 6; ++k) {
    Eigen::Matrix<double, 6, 1> d = Eigen::Matrix<double, 6, 1>::Zero();
    d[k] = h;
    auto eval = [&](double sgn) {
      const Matrix3d R = exp_so3(sgn * d.head<3>()) * R_CT;
      return range_bearing_from_tag_pose(m, t + sgn * d.tail<3>(), R, cov);
    };
    const RangeBearing a = eval(1.0), b = eval(-1.0);
    J(0, k) = (a.range_mm - b.range_mm) / (2 * h);
    J(1, k) = wrap_angle_rad(a.bearing_rad - b.bearing_rad) / (2 * h);
    J(2, k) = wrap_angle_rad(a.relative_yaw_rad - b.relative_yaw_rad) / (2 * h);
  }
  const Matrix3d expect = J * cov * J.transpose();
  EXPECT_NEAR((rb.cov - expect).norm() / expect.norm(), 0.0, 1e-5);
}

// Fisher information of the eight corner coordinates over the six pose parameters, by central
// differences of the projection: the translation block of its inverse is the first-order
// covariance the closed form approximates.
Matrix3d corner_fisher_translation_cov(double f, double side, const Vector3d& t, double sigma) {
  auto project = [&](const Eigen::Matrix<double, 6, 1>& x) {
    Eigen::Matrix<double, 8, 1> uv;
    const Matrix3d R = exp_so3(x.head<3>());
    const double hs = side / 2;
    const double cs[4][2] = {{-hs, -hs}, {hs, -hs}, {hs, hs}, {-hs, hs}};
    for (int i = 0; i < 4; ++i) {
      const Vector3d X = R * Vector3d(cs[i][0], cs[i][1], 0.0) + t + x.tail<3>();
      uv[2 * i] = f * X.x() / X.z();
      uv[2 * i + 1] = f * X.y() / X.z();
    }
    return uv;
  };
  Eigen::Matrix<double, 8, 6> J;
  for (int k = 0; k < 6; ++k) {
    Eigen::Matrix<double, 6, 1> d = Eigen::Matrix<double, 6, 1>::Zero();
    d[k] = k < 3 ? 1e-7 : 1e-4;
    J.col(k) = (project(d) - project(-d)) / (2 * d[k]);
  }
  const Eigen::Matrix<double, 6, 6> info = J.transpose() * J / (sigma * sigma);
  return info.inverse().bottomRightCorner<3, 3>();
}

TEST(RangingModels, TagTranslationCovarianceMatchesTheCornerFisherInformation) {
  for (double z : {2000.0, 5000.0, 8000.0}) {
    const Vector3d t(0.0, 0.0, z);
    const Matrix3d model = tag_translation_covariance(900.0, 150.0, t, 0.3);
    const Matrix3d fisher = corner_fisher_translation_cov(900.0, 150.0, t, 0.3);
    for (int i = 0; i < 3; ++i) {
      EXPECT_NEAR(std::sqrt(model(i, i)) / std::sqrt(fisher(i, i)), 1.0, 0.02)
          << "z " << z << " axis " << i;
    }
    const Matrix3d library =
        tag_pose_covariance(900.0, 150.0, t, Matrix3d::Identity(), 0.3).bottomRightCorner<3, 3>();
    EXPECT_NEAR((library - fisher).norm() / fisher.norm(), 0.0, 1e-4);
  }
}

}  // namespace
}  // namespace agv::ranging
