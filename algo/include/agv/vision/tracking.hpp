// Search windows from the fused pose's prediction (docs/design/tracking.md): which image rectangles
// can hold a mapped landmark, given the predicted vehicle pose and its covariance, so detection can
// skip the rest of the frame. Pure: camera model, landmark geometry and map in, rectangles out.
#pragma once

#include <Eigen/Core>
#include <cstdint>
#include <memory>
#include <vector>

#include "agv/common/camera_model.hpp"
#include "agv/common/geometry.hpp"
#include "agv/common/landmark.hpp"
#include "agv/common/landmark_index.hpp"
#include "agv/vision/landmark_localizer.hpp"

namespace agv::vision {

// One mapped landmark's window: pixel rectangle [x0, x1) x [y0, y1), clipped to the image.
struct SearchWindow {
  std::uint32_t landmark_id = 0;
  int x0 = 0, y0 = 0, x1 = 0, y1 = 0;
  Vec2 centre_px;             // predicted landmark centre (may lie outside the image)
  double up_angle_rad = 0.0;  // predicted image angle of a border normal (mod 90 deg)
  // Standard deviation of that angle (the heading sigma): detection may try only the corner
  // template rotations within a few of it.
  double up_angle_sigma_rad = 0.0;
  // Largest standard deviation (pixels, at the camera's mean scale) of an outer corner's
  // predicted position: the tracked detection searches each corner within window_sigmas of it.
  double corner_sigma_px = 0.0;
};

// The trust rule: the prediction is valid and finite, the largest eigenvalue of its position
// covariance is at most max_position_sigma_mm^2 and its heading variance at most
// max_heading_sigma_deg^2. Otherwise: full-frame search.
bool prediction_trusted(const Prediction& pred, const TrackingConfig& cfg);

// Window growth for detection (mm on the floor beyond the outer border corners): the template
// reach and the outside ring of the ring check (1.5 border widths) plus half the adaptive
// threshold's block, so every pixel the full-frame detection reads for this landmark is inside
// the window and gets the same binarization (a window must give the same fix as the full search).
double detection_margin_mm(const VisionConfig& vision, const LandmarkGeometry& geom,
                           const CameraModel& cam);

class WindowPlanner {
 public:
  // The map must outlive the planner (null: no windows).
  WindowPlanner(const VisionConfig& vision, const CameraModel& cam, const LandmarkGeometry& geom,
                const LandmarkMap* map);

  // Windows of the mapped landmarks whose grown outer square intersects the image; empty when
  // the prediction is not trusted (prediction_trusted) or tracking is disabled.
  void plan(const Prediction& pred, std::vector<SearchWindow>* out) const;

  // Standard deviation (mm, largest axis) of where a fixed floor point appears in the vehicle
  // frame, for a point at p_vehicle and the vehicle's covariance cov_vehicle_axes (the position
  // block rotated into vehicle axes): sqrt of the largest eigenvalue of J cov J^T.
  static double point_sigma_mm(Vec2 p_vehicle, const Eigen::Matrix3d& cov_vehicle_axes);

  double margin_mm() const { return margin_mm_; }
  // The spatial index over the map's landmarks (null without a map), shared with the localizer's
  // other map lookups so that a large map is indexed once.
  const LandmarkIndex* index() const { return index_.get(); }

 private:
  bool window_for(const Pose2& vehicle_in_world, const Eigen::Matrix3d& cov,
                  const LandmarkMapEntry& e, SearchWindow* w) const;

  TrackingConfig cfg_;
  CameraModel cam_;
  // cam_'s floor mapping, built once: CameraModel::vehicle_to_pixel builds one per point (the
  // mount's trigonometry), 34 times per window.
  FloorProjector floor_;
  LandmarkGeometry geom_;
  const LandmarkMap* map_;
  std::shared_ptr<const LandmarkIndex> index_;
  // plan()'s candidates from the index, kept for their storage.
  mutable std::vector<const LandmarkMapEntry*> near_;
  double margin_mm_ = 0.0;
  double footprint_radius_mm_ = 0.0;  // farthest imaged floor point from the vehicle origin
};

// A fused estimate with its velocities at t_ns: what the threaded loop's output thread publishes
// for the vision worker (firmware/src/pipeline.cpp). valid = the pose output was valid.
struct MotionSnapshot {
  bool valid = false;
  std::int64_t t_ns = 0;
  Pose2 vehicle_in_world;
  Eigen::Matrix3d cov = Eigen::Matrix3d::Zero();
  double v_mm_per_s = 0.0;
  double omega_rad_per_s = 0.0;
};
// Constant-velocity extrapolation of a snapshot to a frame's exposure t_ns (the snapshot is a few
// milliseconds old, or newer than the exposure): the pose moved along the arc of (v, omega) over
// dt, the covariance propagated through the motion Jacobian plus (pos_growth_mm_per_s * |dt|)^2 on
// x and y and (heading_growth_rad_per_s * |dt|)^2 on theta for velocity changes the snapshot
// cannot know. Invalid snapshot: invalid prediction.
Prediction extrapolate(const MotionSnapshot& s, std::int64_t t_ns, double pos_growth_mm_per_s,
                       double heading_growth_rad_per_s);

}  // namespace agv::vision
