#include "agv/ranging/range_models.hpp"

#include <cmath>

#include "agv/ranging/square_pose.hpp"

namespace agv::ranging {

namespace {

using Mat3 = Eigen::Matrix3d;
using Vec3 = Eigen::Vector3d;

Mat3 ranging_skew(const Vec3& v) {
  Mat3 s;
  s << 0.0, -v.z(), v.y(), v.z(), 0.0, -v.x(), -v.y(), v.x(), 0.0;
  return s;
}

// Vehicle-frame point -> (range, bearing) and the 2x3 Jacobian of that map.
bool ranging_polar(const Vec3& p_V, double* range_mm, double* bearing_rad,
                   Eigen::Matrix<double, 2, 3>* J) {
  const double r2 = p_V.x() * p_V.x() + p_V.y() * p_V.y();
  if (!(r2 > 0.0)) return false;
  const double r = std::sqrt(r2);
  *range_mm = r;
  *bearing_rad = std::atan2(p_V.y(), p_V.x());
  *J << p_V.x() / r, p_V.y() / r, 0.0, -p_V.y() / r2, p_V.x() / r2, 0.0;
  return true;
}

Vec3 ranging_mount_offset(const RangingMount& m) { return Vec3(m.x_mm, m.y_mm, m.z_mm); }

}  // namespace

Mat3 rotation_vehicle_from_camera(const RangingMount& m) {
  const Mat3 R_VB =
      (Eigen::AngleAxisd(m.yaw_rad, Vec3::UnitZ()) * Eigen::AngleAxisd(m.pitch_rad, Vec3::UnitY()) *
       Eigen::AngleAxisd(m.roll_rad, Vec3::UnitX()))
          .toRotationMatrix();
  // Columns: x_C = -y_B, y_C = -z_B, z_C = x_B, each expressed in B.
  Mat3 R_BC;
  R_BC << 0.0, 0.0, 1.0, -1.0, 0.0, 0.0, 0.0, -1.0, 0.0;
  return R_VB * R_BC;
}

SizeRange size_range(double focal_px, double size_mm, double size_px, double sigma_size_px) {
  SizeRange out;
  if (!(size_px > 0.0) || !(focal_px > 0.0)) return out;
  out.depth_mm = focal_px * size_mm / size_px;
  const double d = out.depth_mm / size_px;
  out.var_mm2 = d * d * sigma_size_px * sigma_size_px;
  return out;
}

double column_bearing_rad(const CameraIntrinsics& k, double u_px) {
  return std::atan2(-(u_px - k.cx), k.fx);
}

double column_bearing_var_rad2(const CameraIntrinsics& k, double u_px, double sigma_u_px) {
  const double c = std::cos(column_bearing_rad(k, u_px));
  const double s = c * c * sigma_u_px / k.fx;
  return s * s;
}

CameraPoint size_camera_point(const CameraIntrinsics& k, Vec2 center_px, double sigma_center_px,
                              const SizeRange& depth) {
  const double xn = (center_px.x - k.cx) / k.fx;
  const double yn = (center_px.y - k.cy) / k.fy;
  const double z = depth.depth_mm;
  CameraPoint out;
  out.p_mm = Vec3(xn * z, yn * z, z);
  Mat3 J;  // d p / d(u, v, depth)
  J << z / k.fx, 0.0, xn, 0.0, z / k.fy, yn, 0.0, 0.0, 1.0;
  const double s2 = sigma_center_px * sigma_center_px;
  out.cov_mm2 = J * Eigen::Vector3d(s2, s2, depth.var_mm2).asDiagonal() * J.transpose();
  return out;
}

RangeBearing range_bearing_from_camera_point(const RangingMount& mount, const CameraPoint& point) {
  const Mat3 R_VC = rotation_vehicle_from_camera(mount);
  const Vec3 p_V = R_VC * point.p_mm + ranging_mount_offset(mount);
  RangeBearing out;
  Eigen::Matrix<double, 2, 3> J;
  if (!ranging_polar(p_V, &out.range_mm, &out.bearing_rad, &J)) return out;
  const Eigen::Matrix<double, 2, 3> Jc = J * R_VC;
  out.cov.topLeftCorner<2, 2>() = Jc * point.cov_mm2 * Jc.transpose();
  return out;
}

RangeBearing range_bearing_from_tag_translation(const RangingMount& mount, const Vec3& t_C_mm,
                                                const Mat3& cov_t_mm2) {
  return range_bearing_from_camera_point(mount, CameraPoint{t_C_mm, cov_t_mm2});
}

namespace {

// Range, bearing and face yaw of a tag pose seen from mount, and J mapping the pose's change
// (d_omega, d_t) to them (the yaw's row zero without a yaw). False for a tag straight above or
// below the reference point (no bearing).
bool tag_pose_polar(const RangingMount& mount, const Vec3& t_C_mm, const Mat3& R_CT,
                    RangeBearing* out, Eigen::Matrix<double, 3, 6>* J) {
  const Mat3 R_VC = rotation_vehicle_from_camera(mount);
  const Vec3 p_V = R_VC * t_C_mm + ranging_mount_offset(mount);
  Eigen::Matrix<double, 2, 3> Jp;
  if (!ranging_polar(p_V, &out->range_mm, &out->bearing_rad, &Jp)) return false;
  // Face normal towards the viewer: -z_T. Under R_CT -> exp([w]x) R_CT, n_C -> n_C + w x n_C.
  const Vec3 n_C = -R_CT.col(2);
  const Vec3 n_V = R_VC * n_C;
  const double h2 = n_V.x() * n_V.x() + n_V.y() * n_V.y();
  J->setZero();
  J->block<2, 3>(0, 3) = Jp * R_VC;
  if (h2 > 1e-12) {
    out->has_yaw = true;
    out->relative_yaw_rad = std::atan2(n_V.y(), n_V.x());
    const Eigen::RowVector3d dyaw_dn(-n_V.y() / h2, n_V.x() / h2, 0.0);
    J->block<1, 3>(2, 0) = dyaw_dn * R_VC * (-ranging_skew(n_C));
  }
  return true;
}

}  // namespace

RangeBearing range_bearing_from_tag_pose(const RangingMount& mount, const Vec3& t_C_mm,
                                         const Mat3& R_CT,
                                         const Eigen::Matrix<double, 6, 6>& cov6) {
  RangeBearing out;
  Eigen::Matrix<double, 3, 6> J;
  if (!tag_pose_polar(mount, t_C_mm, R_CT, &out, &J)) return out;
  out.cov = J * cov6 * J.transpose();  // the yaw's row and column zero with J's
  return out;
}

Eigen::Matrix<double, 3, 6> tag_pose_jacobian(const RangingMount& mount, const Vec3& t_C_mm,
                                              const Mat3& R_CT) {
  RangeBearing rb;
  Eigen::Matrix<double, 3, 6> J;
  return tag_pose_polar(mount, t_C_mm, R_CT, &rb, &J) ? J : Eigen::Matrix<double, 3, 6>::Zero();
}

Mat3 tag_translation_covariance(double focal_px, double side_mm, const Vec3& t_C_mm,
                                double sigma_corner_px) {
  const double rho = t_C_mm.norm();
  if (!(rho > 0.0) || !(focal_px > 0.0) || !(side_mm > 0.0)) return Mat3::Zero();
  const double s_along = rho * rho * sigma_corner_px / (std::sqrt(2.0) * focal_px * side_mm);
  const double s_across = rho * sigma_corner_px / (std::sqrt(2.0) * focal_px);
  const Vec3 u = t_C_mm / rho;
  const Mat3 along = u * u.transpose();
  return s_along * s_along * along + s_across * s_across * (Mat3::Identity() - along);
}

Eigen::Matrix<double, 6, 6> tag_pose_covariance(double focal_px, double side_mm, const Vec3& t_C_mm,
                                                const Mat3& R_CT, double sigma_corner_px) {
  SquareCorners8 uv;
  SquareJacobian J;
  project_square(focal_px, focal_px, 0.0, 0.0, side_mm, R_CT, t_C_mm, &uv, &J);
  const Eigen::Matrix<double, 6, 6> info = J.transpose() * J;
  return sigma_corner_px * sigma_corner_px * info.inverse();
}

}  // namespace agv::ranging
