// Landmarks on racks, pillars and walls seen by a forward or side camera: each tag36h11 landmark
// found in a frame (libapriltag and the border-line corner refinement of the overhead detector)
// measured two ways on the same refined corners:
//  - the papers' way: range from the apparent height (pinhole similar triangles) and bearing from
//    the image column;
//  - the tag's pose from its four undistorted corners (IPPE square solver, both solutions refined
//    by Levenberg-Marquardt), giving horizontal range, bearing and the landmark's relative yaw with
//    a covariance from the corner noise (range_models.hpp).
// A code seen through a reflection (mirrored) is refused by name, so is a site whose landmark
// table repeats an id. Given the vehicle's pose prior (the EKF's), detection runs only in windows
// around the landmarks the prior puts in view, with a full sweep when there is no usable prior
// and at an interval. Conventions and measured figures: docs/design/ranging.md.
#pragma once

#include <array>
#include <cstdint>
#include <memory>
#include <opencv2/core.hpp>
#include <span>
#include <string>
#include <vector>

#include "agv/common/camera_model.hpp"
#include "agv/overhead/tag_detect.hpp"
#include "agv/ranging/fix.hpp"
#include "agv/ranging/range_models.hpp"
#include "agv/site/site.hpp"

namespace agv::ranging {

enum class TableStatus {
  kOk,
  kDuplicateId,   // two tag36h11 wall landmarks share an id: which one was seen is unknowable
  kBadLandmark,   // size_mm not positive or a coordinate not finite
  kBadIntrinsics  // focal lengths not positive or image size empty
};
const char* table_status_name(TableStatus status);

enum class RefusalReason {
  kUnknownId,    // decoded, but no wall landmark of the site has this id
  kMirrored,     // the code reads correctly only mirrored: seen through a reflection
  kTooSmall,     // shorter side under min_side_px: its pose would be noise
  kTouchesEdge,  // a corner within edge_margin_px of the image border (partly outside)
  kNoPose        // the pose solver failed or put the tag behind the camera
};
const char* refusal_reason_name(RefusalReason reason);

// Where the frame is also read mirrored (a code read correctly only mirrored is seen through a
// reflection).
enum class MirrorCheck {
  kOff,
  // Each direct read not confirmed by the pose prior is read again mirrored in its own small
  // window: a direct read that is the mirror image of another code is refused. A mirrored tag
  // that does not decode directly stays unseen (not named).
  kOwnWindow,
  // Everything searched is read mirrored as well (the whole frame on a full sweep, each window
  // otherwise): mirrored tags are also named when the direct read misses them. On a full sweep
  // this is a second full-frame detection, twice the cost.
  kFullFrame
};

// Why a frame was read the way it was (ObserveResult::reason).
enum class SweepReason {
  kWindows,         // predicted windows only
  kNoPrior,         // full sweep: no pose prior given
  kUncertainPrior,  // full sweep: the prior's covariance over WindowOptions' limits (or not finite)
  kInterval,        // the frame index is a multiple of the sweep interval: the windows plus the
                    // whole frame at ObserveOptions::interval_sweep_decimate, or a full sweep
  kWindowsTooLarge  // full sweep: the windows would search about as many pixels as it does
};
const char* sweep_reason_name(SweepReason reason);

struct ObserveOptions {
  // Corner noise used for the covariances: max(floor, scale * the detector's edge-fit sigma).
  // The edge fit sees the image noise, not the lens calibration's residual or the anti-aliasing
  // bias of a small square, hence the floor.
  double corner_sigma_floor_px = 0.15;
  double corner_sigma_scale = 1.0;
  double min_side_px = 10.0;
  double edge_margin_px = 2.0;
  // A tag seen through a reflection is refused by name rather than, with bit errors, misread.
  MirrorCheck mirror_check = MirrorCheck::kOwnWindow;
  // libapriltag's quad decimation on a full sweep (windows are searched at full resolution): 2
  // costs a quarter but misses some of the smallest tags (150 mm beyond about 7 m at f = 1000 px).
  double full_sweep_decimate = 1.0;
  // libapriltag's quad decimation for the interval's search of the whole frame
  // (WindowOptions::full_sweep_interval_frames) when the prior is usable: the windows are read as
  // on any frame and this search adds the tags they did not read, at about a third of a full
  // sweep's cost for 2; it misses some of the smallest tags, which the windows read once the
  // prior expects them. 1: a full sweep at full_sweep_decimate in place of the windows.
  double interval_sweep_decimate = 2.0;
  // The two IPPE solutions' reprojection errors closer than this ratio: the tag's yaw is
  // ambiguous (a small or distant tag), has_yaw is false; range and bearing stay.
  double yaw_ambiguity_ratio = 2.0;
  // libapriltag on the whole frame: texture of racks needs a lower contrast floor than the
  // ceiling cameras' default.
  int quad_min_white_black_diff = 20;
  // The mount's calibration uncertainty (1 sigma per angle and per axis). Roll, pitch and the
  // offsets move each landmark's bearing differently (by its height in the image), so they go
  // into each observation's covariance; the yaw turns all bearings alike and goes into the fix's
  // covariance instead (add_mount_yaw_uncertainty), where it does not blur the bearing
  // differences the fix relies on.
  double mount_sigma_rad = 0.0;
  double mount_sigma_mm = 0.0;
  // The lens calibration's residual: a systematic error of an undistorted point that differs
  // across the image (distortion terms, principal point; 1 sigma, px) widens each bearing by
  // sigma / fx; a relative focal-length error (1 sigma, on fx and fy apart) scales the whole
  // view: each range, each bearing off the image centre and, on one axis, each face yaw (the
  // tag's width against its height; far more near face-on). It is one error for all landmarks of
  // a frame (LandmarkObservation::focal_pose_step), which the fixes keep as one
  // (ranging::lens_cov_change).
  double calibration_sigma_px = 0.0;
  double focal_sigma_rel = 0.0;
};

// The papers' reading of the same corners: the pinhole formula L = f H / h taken as the
// distance, the bearing from the image column alone (the mount's yaw added).
struct PaperMeasure {
  double distance_mm = 0.0;
  double bearing_rad = 0.0;  // vehicle frame, from the camera's optical centre
};

// One landmark measured in one frame.
struct LandmarkObservation {
  std::uint32_t id = 0;
  std::size_t landmark_index = 0;  // into the landmarks the observer was built with
  Vec2 landmark_xy_mm;             // surveyed centre, site frame
  double landmark_facing_rad = 0.0;
  std::array<Vec2, 4> corners_px{};  // refined, distorted, page order TL TR BR BL
  std::array<Vec2, 4> corners_undistorted_px{};
  double corner_sigma_px = 0.0;  // used for both covariances
  RangeBearing size;             // range from the apparent height read as depth, no yaw
  RangeBearing pose;             // from the tag pose, with the relative yaw unless ambiguous
  PaperMeasure paper;
  // The pose: tag frame T (x page right, y page down, z into the face) in the camera frame C,
  // and its covariance over (small rotation in C, translation mm) as in range_models.hpp.
  Eigen::Vector3d t_C_mm = Eigen::Vector3d::Zero();
  Eigen::Matrix3d R_CT = Eigen::Matrix3d::Identity();
  Eigen::Matrix<double, 6, 6> cov6 = Eigen::Matrix<double, 6, 6>::Zero();
  double reprojection_rms_px = 0.0;
  // The calibration's share of the covariances above (ObserveOptions), kept for
  // sensor_range_bearing: bearing variance and relative range variance.
  double calibration_bearing_var_rad2 = 0.0;
  double calibration_range_var_rel2 = 0.0;
  // The tag pose's first-order change (small rotation in C, translation mm, as cov6) for a focal
  // length believed longer than the lens's by ObserveOptions::focal_sigma_rel: column 0 fx,
  // column 1 fy. One error for every landmark of the frame, so kept apart from the covariances
  // (lens_response). Zero when no focal doubt is stated or the step failed.
  Eigen::Matrix<double, 6, 2> focal_pose_step = Eigen::Matrix<double, 6, 2>::Zero();
  // lens_response from the observer's mount: what it added to pose.cov (the face yaw's row zero
  // where the pose has no yaw).
  Eigen::Matrix<double, 3, 2> pose_lens_response = Eigen::Matrix<double, 3, 2>::Zero();
};

// The change of (range, bearing, face yaw) as seen from mount for each column of
// obs.focal_pose_step: how one error of the lens's focal lengths, shared by all landmarks of a
// frame, moves this one.
Eigen::Matrix<double, 3, 2> lens_response(const RangingMount& mount,
                                          const LandmarkObservation& obs);

struct RefusedLandmark {
  std::uint32_t id = 0;
  RefusalReason reason = RefusalReason::kUnknownId;
  std::array<Vec2, 4> corners_px{};
};

struct ObserveResult {
  std::vector<LandmarkObservation> seen;
  std::vector<RefusedLandmark> refused;
  bool full_sweep = true;
  SweepReason reason = SweepReason::kNoPrior;
  std::size_t windows_searched = 0;  // after merging overlapping windows; 0 on a full sweep
  std::size_t predicted_reads = 0;   // landmarks read on the predicted path (no window search)
};

// The vehicle's pose and its covariance over (x_mm, y_mm, theta_rad), site frame (the EKF's).
struct PosePrior {
  Pose2 pose;
  Eigen::Matrix3d cov = Eigen::Matrix3d::Zero();
};

struct WindowOptions {
  // A window covers the predicted corners plus sigma_count projected sigmas (pose prior, mount
  // and lens calibration sigmas of ObserveOptions) plus a margin: libapriltag needs the tag's white
  // border and some background around it to find the quad.
  double sigma_count = 3.0;
  double margin_px = 16.0;
  double margin_side_share = 0.25;  // of the predicted tag's side, when more than margin_px
  // A prior worse than these (worst position axis, heading; 1 sigma) gets a full sweep.
  double max_position_sd_mm = 150.0;
  double max_heading_sd_rad = 0.035;
  // Windows whose pixels searched (each window's area over its decimation squared) add up to
  // more than this share of the frame: a full sweep instead.
  double max_window_share = 0.3;
  // Every this many frames (frame_index multiple of it) the whole frame is searched as well, for
  // what the prior does not expect (a landmark it puts out of view, a prior wrong beyond its
  // sigma); 0: never.
  std::uint64_t full_sweep_interval_frames = 150;
  // Landmarks predicted smaller than this share of ObserveOptions::min_side_px, or seen more
  // obliquely than max_view_angle_rad from their face normal, are not looked for.
  double min_side_share = 0.8;
  double max_view_angle_rad = 1.3;
  // A window whose smallest predicted tag is n times this side (px; its shortest side) is
  // searched shrunk n times (up to max_decimation): libapriltag's cost goes with the pixels, and
  // it finds a tag of this size reliably, an oblique one too (at 24 px a tag seen at 70 degrees,
  // 50 x 140 px, was lost at half size). The tag is then refined at full resolution from the
  // scaled corners.
  double decimated_side_px = 32.0;
  int max_decimation = 4;
  // Every landmark the prior puts in view is read first on the tag detector's predicted path:
  // edge lines fitted around the predicted square (within TagDetectParams::predicted_search_px)
  // and the cells decoded against its id alone, within the bits the search path corrects; a
  // window is searched by libapriltag only when a landmark in it was not read so. Tried whatever
  // the prior's sigma: a near tag's corner sigma is a few px even for a localized vehicle, and its
  // corners are mostly within the search anyway (a failed read costs a fraction of the window).
  // false: libapriltag in every window.
  bool predicted_first = true;
};

// One landmark the prior puts in view: its corners at the prior pose (distorted pixels, page
// order), the largest projected sigma of a corner coordinate and the window searched.
struct PredictedLandmark {
  std::uint32_t id = 0;
  std::array<Vec2, 4> corners_px{};
  double corner_sigma_px = 0.0;
  double side_px = 0.0;  // shortest side at the prior pose
  cv::Rect window;
  bool predicted_path = false;  // tried on the predicted path first (predicted_first)
  int decimation = 1;           // a window searched for it alone is shrunk this many times
};

struct SearchWindow {
  cv::Rect rect;
  int decimation = 1;  // searched shrunk this many times
};

struct WindowPlan {
  bool full_sweep = true;
  SweepReason reason = SweepReason::kNoPrior;
  std::vector<PredictedLandmark> predicted;
  std::vector<SearchWindow> windows;  // the predicted windows, overlapping ones merged
  std::size_t hidden = 0;  // landmarks in view but behind an obstacle (set_obstacles): not searched
  // The whole frame is searched as well for tags the windows did not read (the interval's search,
  // ObserveOptions::interval_sweep_decimate).
  bool discovery = false;
};

// A range and bearing from the camera itself, in the terms of the EKF's range-bearing aid: the
// landmark (site frame), the camera's optical centre and yaw in the vehicle frame, the horizontal
// distance camera -> landmark, the bearing counter-clockwise from the camera's forward axis (its
// yaw), and the covariance R of (range, bearing).
struct SensorRangeBearing {
  Eigen::Vector2d landmark_xy_mm = Eigen::Vector2d::Zero();
  Eigen::Vector2d sensor_xy_mm = Eigen::Vector2d::Zero();
  double sensor_yaw_rad = 0.0;
  double range_mm = 0.0;
  double bearing_rad = 0.0;
  Eigen::Matrix2d R = Eigen::Matrix2d::Identity();
  // The mount's (roll, pitch, offsets) and the calibration's share of R: the same in every frame
  // of this landmark seen from about here (fusion::RangeBearingObs::R_systematic).
  Eigen::Matrix2d R_systematic = Eigen::Matrix2d::Zero();
};

class LandmarkObserver {
 public:
  // Checks the landmark table and the intrinsics; status() says why it will see nothing.
  // The agvloc-family landmarks of the site are skipped (this observer reads tag36h11 only).
  LandmarkObserver(const CameraIntrinsics& intrinsics, const RangingMount& mount,
                   std::span<const site::WallLandmark> landmarks,
                   const ObserveOptions& options = {});
  ~LandmarkObserver();
  LandmarkObserver(const LandmarkObserver&) = delete;
  LandmarkObserver& operator=(const LandmarkObserver&) = delete;

  // The site's obstacles (opaque, extruded to their height): a landmark the prior puts in view
  // but behind one (every corner's sight line crossing it) gets no window. A full sweep and the
  // interval's search still read it if it is in sight after all. None by default.
  void set_obstacles(std::span<const site::Obstacle> obstacles) {
    obstacles_.assign(obstacles.begin(), obstacles.end());
  }

  TableStatus status() const { return status_; }
  const std::string& status_detail() const { return status_detail_; }

  // Every tag36h11 landmark in an 8-bit gray frame of this camera. Empty when status() is not
  // kOk or the frame's size or type differs from the intrinsics.
  ObserveResult observe(const cv::Mat& gray) const;

  // The windows to search given a pose prior (nullptr: none) at frame frame_index, or a full
  // sweep and why.
  WindowPlan plan_windows(const PosePrior* prior, std::uint64_t frame_index,
                          const WindowOptions& wopt = {}) const;
  // A frame read as planned: in the plan's windows only, or a full sweep. Detections in a window
  // are the full sweep's (same detector, same refinement) where the window holds the tag.
  ObserveResult observe(const cv::Mat& gray, const WindowPlan& plan) const;
  // plan_windows then observe.
  ObserveResult observe(const cv::Mat& gray, const PosePrior* prior, std::uint64_t frame_index,
                        const WindowOptions& wopt = {}) const;

  // Measures one detected quad (corners in page order, distorted pixels); false with the reason.
  bool measure(std::uint32_t id, const std::array<Vec2, 4>& corners_px, double edge_sigma_px,
               LandmarkObservation* out, RefusalReason* reason) const;

  const RangingMount& mount() const { return mount_; }

 private:
  struct Impl;
  bool usable_frame(const cv::Mat& gray) const;
  ObserveResult full_sweep(const cv::Mat& gray, SweepReason reason) const;
  bool predict_landmark(const site::WallLandmark& w, const PosePrior& prior,
                        const WindowOptions& wopt, PredictedLandmark* out) const;
  std::vector<overhead::TagObservation> detect_in(const cv::Mat& gray, const SearchWindow& w) const;
  // The predicted landmarks read on the predicted path (appended to *dets); per landmark of
  // plan.predicted, whether it was.
  std::vector<bool> read_predicted(const cv::Mat& gray, const WindowPlan& plan,
                                   std::vector<overhead::TagObservation>* dets) const;
  // Detections of a windowed frame, each with whether the prior expected it there.
  struct WindowReads {
    std::vector<overhead::TagObservation> dets;
    std::vector<bool> confirmed;
  };
  // libapriltag in the plan's windows that the predicted path did not finish.
  void search_windows(const cv::Mat& gray, const WindowPlan& plan, const std::vector<bool>& read,
                      WindowReads* out, ObserveResult* res) const;
  // The whole frame at the interval's decimation: tags not read yet.
  void search_discovery(const cv::Mat& gray, const WindowPlan& plan, WindowReads* out) const;
  // The decimation window w is searched at: that of its smallest landmark not read on the
  // predicted path (a small tag read there does not make the search of a near one finer).
  static int unread_decimation(const WindowPlan& plan, const std::vector<bool>& read,
                               const SearchWindow& w);
  // Every predicted landmark in window w was read on the predicted path.
  static bool window_done(const WindowPlan& plan, const std::vector<bool>& read,
                          const SearchWindow& w);
  // Measures the detections not flagged mirrored into res.
  void measure_detections(const std::vector<overhead::TagObservation>& dets,
                          const std::vector<bool>& mirrored, ObserveResult* res) const;
  CameraIntrinsics k_;
  RangingMount mount_;
  ObserveOptions opt_;
  std::vector<site::WallLandmark> table_;  // sorted by id, tag36h11 only
  std::vector<std::size_t> site_index_;  // table_[i] is the constructor's landmarks[site_index_[i]]
  std::vector<site::Obstacle> obstacles_;
  TableStatus status_ = TableStatus::kOk;
  std::string status_detail_;
  std::unique_ptr<Impl> impl_;
};

// The fix's per-landmark input from an observation (range and bearing from the vehicle's
// reference point): from the tag pose, or from the apparent size. From the tag pose with a yaw
// (not ambiguous), also the face yaw with its covariance and the landmark's surveyed facing.
Observation fix_observation(const LandmarkObservation& obs, bool from_pose = true);
std::vector<Observation> fix_observations(std::span<const LandmarkObservation> obs,
                                          bool from_pose = true);

// The observation from the camera's own optical centre, for the EKF's range-bearing aid; R
// holds the corner noise and the mount's roll, pitch and height uncertainty (1 sigma; the yaw and
// the horizontal offset are the sensor's stated pose, whose errors the aid sees alike in every
// landmark).
SensorRangeBearing sensor_range_bearing(const RangingMount& mount, const LandmarkObservation& obs,
                                        double mount_sigma_rad = 0.0, double mount_sigma_mm = 0.0);

}  // namespace agv::ranging
