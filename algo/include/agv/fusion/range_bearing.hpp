// A range-bearing observation of a landmark seen at a distance (a forward or side camera reading a
// tag on a rack or wall), the input of Ekf::add_range_bearing. Frames: docs/design/frames.md
// (site frame, vehicle frame: x forward, y left; mm, rad counter-clockwise).
#pragma once

#include <Eigen/Core>

namespace agv::fusion {

struct RangeBearingObs {
  // The landmark's surveyed position, site frame.
  Eigen::Vector2d landmark_xy_mm = Eigen::Vector2d::Zero();
  // The sensor's (camera's optical centre) position and yaw in the vehicle frame.
  Eigen::Vector2d sensor_xy_mm = Eigen::Vector2d::Zero();
  double sensor_yaw_rad = 0.0;
  // Horizontal distance sensor -> landmark, and the landmark's direction in the sensor frame,
  // counter-clockwise from the sensor's forward axis.
  double range_mm = 0.0;
  double bearing_rad = 0.0;
  // Covariance of (range_mm, bearing_rad).
  Eigen::Matrix2d R = Eigen::Matrix2d::Identity();
  // 1 sigma of an error every bearing of this sensor shares (its yaw as mounted against as
  // calibrated): frames fused as independent would average it away, so an update leaves the
  // heading variance at least at the smaller of its prior value and this squared.
  double common_bearing_sigma_rad = 0.0;
  // The share of R that repeats in every frame of this landmark seen from about here (the
  // mount's roll, pitch and offsets, the lens calibration: ranging::sensor_range_bearing), at most
  // R. Frames fused as independent would shrink it: the position variance is kept at least at
  // its range share along the line of sight and its bearing share times the range squared across.
  Eigen::Matrix2d R_systematic = Eigen::Matrix2d::Zero();
};

}  // namespace agv::fusion
