// Range and bearing to a landmark seen at a distance by a forward or side camera: from the
// landmark's apparent size (pinhole similar triangles) or from a full tag pose, carried from the
// camera frame to a horizontal range/bearing in the vehicle frame with a propagated covariance.
// Methods, conventions and measured noise: docs/design/ranging.md.
#pragma once

#include <Eigen/Dense>

#include "agv/common/camera_model.hpp"
#include "agv/common/geometry.hpp"

namespace agv::ranging {

// Where a forward or side camera sits on the vehicle (6 DoF). The camera body frame B has
// x_B = optical axis, y_B = image left, z_B = image up; it relates to the OpenCV camera frame C
// (x right, y down, z optical axis) by x_C = -y_B, y_C = -z_B, z_C = x_B. Its orientation in the
// vehicle frame V is the z-y'-x'' sequence R_VB = Rz(yaw) * Ry(pitch) * Rx(roll). All zero: a
// level camera looking along vehicle +x; yaw +pi/2 looks to the vehicle's left; positive pitch
// tilts the optical axis down; positive roll (about the optical axis) lowers the camera's right
// side.
struct RangingMount {
  double x_mm = 0.0;  // optical centre in V
  double y_mm = 0.0;
  double z_mm = 0.0;
  double roll_rad = 0.0;
  double pitch_rad = 0.0;
  double yaw_rad = 0.0;
};

// R_VC: columns are the camera axes x_C, y_C, z_C expressed in V.
Eigen::Matrix3d rotation_vehicle_from_camera(const RangingMount& mount);

// A point in the camera frame with its covariance (mm, mm^2).
struct CameraPoint {
  Eigen::Vector3d p_mm = Eigen::Vector3d::Zero();
  Eigen::Matrix3d cov_mm2 = Eigen::Matrix3d::Zero();
};

// Horizontal range and bearing of a landmark from the vehicle reference point, in V: range is the
// floor-plane distance, bearing is counter-clockwise from vehicle +x. When the observation comes
// from a full tag pose, relative_yaw_rad is the direction in V (counter-clockwise from +x, floor
// plane) of the landmark's face normal, pointing out of its printed face towards the viewer; the
// vehicle heading in W is then the landmark's surveyed facing direction minus relative_yaw_rad.
// cov is over (range_mm, bearing_rad, relative_yaw_rad); without a yaw its third row and column
// are zero and has_yaw is false.
struct RangeBearing {
  double range_mm = 0.0;
  double bearing_rad = 0.0;
  double relative_yaw_rad = 0.0;
  bool has_yaw = false;
  Eigen::Matrix3d cov = Eigen::Matrix3d::Zero();
  // The share of cov that every frame of this landmark seen from the same place repeats (the
  // mount's and the lens calibration's doubt, ObserveOptions): frames averaged together shrink
  // the rest of cov, never this.
  Eigen::Matrix3d systematic_cov = Eigen::Matrix3d::Zero();
};

// Pinhole range from apparent size: a landmark edge of size_mm perpendicular to the optical axis
// spans size_px = f * size_mm / depth pixels, so depth = f * size_mm / size_px. This is the depth
// along the optical axis, which equals the distance to the camera only on the axis. Variance by
// first order: d(depth)/d(size_px) = -depth / size_px. Invalid (depth 0) for size_px <= 0.
struct SizeRange {
  double depth_mm = 0.0;
  double var_mm2 = 0.0;
};
SizeRange size_range(double focal_px, double size_mm, double size_px, double sigma_size_px);

// Bearing of an undistorted image column in the camera's own horizontal plane, counter-clockwise
// (towards image left) from the optical axis: atan2(-(u - cx), fx). Its variance for a column
// noise sigma_u_px is (cos^2(bearing) * sigma_u_px / fx)^2.
double column_bearing_rad(const CameraIntrinsics& k, double u_px);
double column_bearing_var_rad2(const CameraIntrinsics& k, double u_px, double sigma_u_px);

// The camera-frame point of a size-ranged landmark: its undistorted image centre (u, v) back-
// projected to the depth from its size; the centre's noise is sigma_center_px per axis.
CameraPoint size_camera_point(const CameraIntrinsics& k, Vec2 center_px, double sigma_center_px,
                              const SizeRange& depth);

// Camera-frame point -> horizontal range/bearing from the vehicle reference point, with the
// covariance propagated through the mount's rigid transform and the polar conversion (Jacobian).
// A point directly above or below the reference point has no bearing: range 0, cov zero.
RangeBearing range_bearing_from_camera_point(const RangingMount& mount, const CameraPoint& point);

// A tag's full pose: translation t_C of its centre and rotation R_CT (tag frame T in the camera
// frame; OpenCV/AprilTag convention: z_T points into the tag, away from its printed face).
// cov6 is over (d_omega, d_t): d_omega the small rotation vector in C with R_CT = exp([d_omega]x)
// R_CT_estimate, then d_t in mm. Gives range, bearing and relative yaw with their covariance.
RangeBearing range_bearing_from_tag_pose(const RangingMount& mount, const Eigen::Vector3d& t_C_mm,
                                         const Eigen::Matrix3d& R_CT,
                                         const Eigen::Matrix<double, 6, 6>& cov6);

// The first-order change of that range, bearing and relative yaw for a change (d_omega, d_t) of
// the tag pose, as cov6 is over; the yaw's row zero where the face has no yaw, all zero where
// the tag has no bearing.
Eigen::Matrix<double, 3, 6> tag_pose_jacobian(const RangingMount& mount,
                                              const Eigen::Vector3d& t_C_mm,
                                              const Eigen::Matrix3d& R_CT);

// The same without a rotation (translation covariance only): range and bearing, no yaw.
RangeBearing range_bearing_from_tag_translation(const RangingMount& mount,
                                                const Eigen::Vector3d& t_C_mm,
                                                const Eigen::Matrix3d& cov_t_mm2);

// First-order covariance of a square tag's pose translation from its four corners' pixel noise
// (sigma_corner_px per coordinate, independent), for a tag of side side_mm roughly facing the
// camera at t_C. With the corners at +-a (a = f s / 2 rho) around the centre, the scale is
// decoupled from the other pose parameters by the square's symmetry, so the range along the ray
// has sigma = rho^2 sigma_c / (sqrt(2) f s); across the ray the centre shift is confounded with
// the tag's out-of-plane rotation (both move all four corners together), which doubles the
// variance of the four-corner mean: sigma = rho sigma_c / (sqrt(2) f) per axis.
Eigen::Matrix3d tag_translation_covariance(double focal_px, double side_mm,
                                           const Eigen::Vector3d& t_C_mm, double sigma_corner_px);

// First-order covariance of a square tag's full pose (over (d_omega, d_t) as in
// range_bearing_from_tag_pose) from its corners' pixel noise, for any pose: the inverse of the
// Fisher information of the eight corner coordinates of a pinhole camera with focal_px, the
// Jacobian in closed form (project_square). Obliquity weakens the scale (range) information, which
// the closed form above, derived facing the camera, does not see.
Eigen::Matrix<double, 6, 6> tag_pose_covariance(double focal_px, double side_mm,
                                                const Eigen::Vector3d& t_C_mm,
                                                const Eigen::Matrix3d& R_CT,
                                                double sigma_corner_px);

}  // namespace agv::ranging
