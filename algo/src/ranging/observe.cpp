#include "agv/ranging/observe.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <opencv2/calib3d.hpp>
#include <opencv2/core.hpp>

#include "agv/overhead/tag_detect.hpp"
#include "agv/ranging/square_pose.hpp"
#include "observe_internal.hpp"

namespace agv::ranging {

namespace {

bool observe_finite_landmark(const site::WallLandmark& w) {
  return std::isfinite(w.x_mm) && std::isfinite(w.y_mm) && std::isfinite(w.z_mm) &&
         std::isfinite(w.facing_rad) && std::isfinite(w.size_mm) && w.size_mm > 0.0;
}

Vec2 observe_centre(const std::array<Vec2, 4>& c) {
  return {(c[0].x + c[1].x + c[2].x + c[3].x) / 4.0, (c[0].y + c[1].y + c[2].y + c[3].y) / 4.0};
}

double observe_dist(Vec2 a, Vec2 b) { return std::hypot(a.x - b.x, a.y - b.y); }

Eigen::Vector3d observe_rb_vector(const RangeBearing& rb) {
  return {rb.range_mm, rb.bearing_rad, rb.relative_yaw_rad};
}

// Covariance of (range, bearing, yaw) from the mount's roll, pitch and offsets (x and y only with
// with_xy), by central differences of measure_at(mount).
template <class F>
Eigen::Matrix3d observe_mount_cov(const RangingMount& m, double sigma_rad, double sigma_mm,
                                  bool with_xy, F measure_at) {
  double RangingMount::*const fields[] = {&RangingMount::roll_rad, &RangingMount::pitch_rad,
                                          &RangingMount::z_mm, &RangingMount::x_mm,
                                          &RangingMount::y_mm};
  Eigen::Matrix3d C = Eigen::Matrix3d::Zero();
  for (std::size_t k = 0; k < (with_xy ? 5u : 3u); ++k) {
    const bool angle = k < 2;
    const double sigma = angle ? sigma_rad : sigma_mm, h = angle ? 1e-5 : 1e-2;
    if (!(sigma > 0.0)) continue;
    RangingMount a = m, b = m;
    a.*fields[k] += h;
    b.*fields[k] -= h;
    Eigen::Vector3d d = observe_rb_vector(measure_at(a)) - observe_rb_vector(measure_at(b));
    d[1] = wrap_angle_rad(d[1]);
    d[2] = wrap_angle_rad(d[2]);
    d /= 2.0 * h;
    C += sigma * sigma * d * d.transpose();
  }
  return C;
}

// Whether every corner keeps `margin_px` from the image border.
bool inside_margin(const std::array<Vec2, 4>& corners_px, const CameraIntrinsics& k,
                   double margin_px) {
  for (const Vec2& c : corners_px) {
    if (!(c.x >= margin_px && c.y >= margin_px && c.x <= k.width_px - 1 - margin_px &&
          c.y <= k.height_px - 1 - margin_px)) {
      return false;
    }
  }
  return true;
}

// The tag pose's change for each focal length (fx, fy apart) believed longer by sigma_rel than
// the lens's. Seen near face-on, a tag's yaw rests on the ratio of its width to its height: 0.2 %
// on one axis turns it by about 0.65 deg at 10 deg off face-on; both axes scale the range and,
// off the image centre, the bearing. A lens whose focal length is longer than believed by
// sigma_rel moves the projected corners by sigma_rel (u - cx) (or (v - cy)); the pose that puts
// them back is one Gauss-Newton step on the corners' Jacobian, and a belief too long moves the
// pose the other way. False when the projection or its normal equations fail.
bool focal_pose_step(const CameraIntrinsics& k, double side_mm, const LandmarkObservation& o,
                     double sigma_rel, Eigen::Matrix<double, 6, 2>* step) {
  SquareCorners8 uv;
  SquareJacobian J;
  if (!project_square(k.fx, k.fy, k.cx, k.cy, side_mm, o.R_CT, o.t_C_mm, &uv, &J)) return false;
  const Eigen::LDLT<Eigen::Matrix<double, 6, 6>> normal(J.transpose() * J);
  if (normal.info() != Eigen::Success) return false;
  for (int axis = 0; axis < 2; ++axis) {
    SquareCorners8 moved = SquareCorners8::Zero();
    const double centre = axis == 0 ? k.cx : k.cy;
    for (int i = 0; i < 4; ++i) moved(2 * i + axis) = sigma_rel * (uv(2 * i + axis) - centre);
    step->col(axis) = -normal.solve(J.transpose() * moved);
  }
  return step->allFinite();
}

// IPPE's (up to two) poses of the square, each refined by Levenberg-Marquardt on the undistorted
// corners (refine_square_pose); returns the index of the one with the smaller squared reprojection
// error (-1 when none), that error and the other solution's (-1 when there is none).
int best_square_pose(const CameraIntrinsics& k, double side_mm, const cv::Matx33d& K,
                     const std::array<Vec2, 4>& image, std::array<SquarePose, 2>* poses,
                     double* best_err, double* other_err) {
  const double h = side_mm / 2.0;
  std::array<cv::Point3d, 4> object = {{{-h, h, 0.0}, {h, h, 0.0}, {h, -h, 0.0}, {-h, -h, 0.0}}};
  std::array<cv::Point2d, 4> image_cv;
  for (std::size_t i = 0; i < 4; ++i) image_cv[i] = {image[i].x, image[i].y};
  std::vector<cv::Mat> rvecs, tvecs;
  int n = 0;
  try {
    n = cv::solvePnPGeneric(cv::Mat(4, 1, CV_64FC3, object.data()),
                            cv::Mat(4, 1, CV_64FC2, image_cv.data()), K, cv::noArray(), rvecs,
                            tvecs, false, cv::SOLVEPNP_IPPE_SQUARE);
  } catch (const cv::Exception&) {
    n = 0;
  }
  *best_err = 0.0;
  *other_err = -1.0;
  int best = -1;
  for (int s = 0; s < std::min(n, 2); ++s) {
    const cv::Mat& r = rvecs[static_cast<std::size_t>(s)];
    const cv::Mat& t = tvecs[static_cast<std::size_t>(s)];
    const Eigen::Vector3d w(r.at<double>(0), r.at<double>(1), r.at<double>(2));
    const double a = w.norm();
    const Eigen::Matrix3d R0 =
        a > 0.0 ? Eigen::AngleAxisd(a, w / a).toRotationMatrix() : Eigen::Matrix3d::Identity();
    const Eigen::Vector3d t0(t.at<double>(0), t.at<double>(1), t.at<double>(2));
    SquarePose& p = (*poses)[static_cast<std::size_t>(s)];
    p = refine_square_pose(k.fx, k.fy, k.cx, k.cy, side_mm, image, R0, t0);
    if (!p.ok) continue;
    const double e = p.squared_error_px2;
    if (best < 0 || e < *best_err) {
      if (best >= 0) *other_err = *best_err;
      *best_err = e;
      best = s;
    } else {
      *other_err = e;
    }
  }
  return best;
}

// The papers' measure on the same corners: range from the height of the two vertical edges,
// bearing from the centre's column (o->size, o->paper).
void add_size_measure(const CameraIntrinsics& k, const RangingMount& mount,
                      const ObserveOptions& opt, double side, LandmarkObservation* o) {
  const auto& u = o->corners_undistorted_px;
  const double height_px = (observe_dist(u[0], u[3]) + observe_dist(u[1], u[2])) / 2.0;
  CameraIntrinsics pin = k;
  pin.k1 = pin.k2 = pin.p1 = pin.p2 = pin.k3 = 0.0;
  const SizeRange depth = size_range(k.fy, side, height_px, o->corner_sigma_px);
  const Vec2 centre = observe_centre(u);
  const CameraPoint point = size_camera_point(pin, centre, o->corner_sigma_px / 2.0, depth);
  o->size = range_bearing_from_camera_point(mount, point);
  o->size.systematic_cov.topLeftCorner<2, 2>() =
      observe_mount_cov(
          mount, opt.mount_sigma_rad, opt.mount_sigma_mm, true,
          [&](const RangingMount& m) { return range_bearing_from_camera_point(m, point); })
          .topLeftCorner<2, 2>();
  o->size.cov.topLeftCorner<2, 2>() += o->size.systematic_cov.topLeftCorner<2, 2>();
  o->paper.distance_mm = depth.depth_mm;
  o->paper.bearing_rad = mount.yaw_rad + column_bearing_rad(pin, centre.x);
}

}  // namespace

namespace observe_detail {

std::vector<overhead::TagObservation> mirrored_reads(const overhead::TagDetector& det,
                                                     const cv::Mat& gray, const cv::Rect& window) {
  const cv::Rect w = window & cv::Rect(0, 0, gray.cols, gray.rows);
  if (w.empty()) return {};
  cv::Mat flipped;
  cv::flip(gray(w), flipped, 1);
  std::vector<overhead::TagObservation> out =
      det.detect(flipped, cv::Rect(0, 0, flipped.cols, flipped.rows));
  const double right = w.x + w.width - 1.0;
  for (overhead::TagObservation& m : out) {
    for (Vec2& c : m.corners_px) {
      c.x = right - c.x;
      c.y += w.y;
    }
  }
  return out;
}

void refuse_mirrored(const std::vector<overhead::TagObservation>& mirrored,
                     const std::vector<overhead::TagObservation>& direct,
                     std::vector<bool>* flagged, ObserveResult* res) {
  for (const overhead::TagObservation& m : mirrored) {
    const Vec2 mc = observe_centre(m.corners_px);
    const double reach = overhead::shortest_side_px(m.corners_px) / 2.0;
    for (std::size_t i = 0; i < direct.size(); ++i) {
      if (observe_dist(observe_centre(direct[i].corners_px), mc) < reach) (*flagged)[i] = true;
    }
    const bool known = std::any_of(res->refused.begin(), res->refused.end(), [&](const auto& r) {
      return r.reason == RefusalReason::kMirrored && r.id == m.id &&
             observe_dist(observe_centre(r.corners_px), mc) < reach;
    });
    if (!known) res->refused.push_back({m.id, RefusalReason::kMirrored, m.corners_px});
  }
}

}  // namespace observe_detail

const char* table_status_name(TableStatus status) {
  switch (status) {
    case TableStatus::kOk:
      return "ok";
    case TableStatus::kDuplicateId:
      return "duplicate_landmark_id";
    case TableStatus::kBadLandmark:
      return "bad_landmark";
    case TableStatus::kBadIntrinsics:
      return "bad_intrinsics";
  }
  return "unknown";
}

const char* refusal_reason_name(RefusalReason reason) {
  switch (reason) {
    case RefusalReason::kUnknownId:
      return "unknown_id";
    case RefusalReason::kMirrored:
      return "mirrored";
    case RefusalReason::kTooSmall:
      return "too_small";
    case RefusalReason::kTouchesEdge:
      return "touches_edge";
    case RefusalReason::kNoPose:
      return "no_pose";
  }
  return "unknown";
}

const char* sweep_reason_name(SweepReason reason) {
  switch (reason) {
    case SweepReason::kWindows:
      return "windows";
    case SweepReason::kNoPrior:
      return "no_prior";
    case SweepReason::kUncertainPrior:
      return "uncertain_prior";
    case SweepReason::kInterval:
      return "interval";
    case SweepReason::kWindowsTooLarge:
      return "windows_too_large";
  }
  return "unknown";
}

LandmarkObserver::LandmarkObserver(const CameraIntrinsics& intrinsics, const RangingMount& mount,
                                   std::span<const site::WallLandmark> landmarks,
                                   const ObserveOptions& options)
    : k_(intrinsics), mount_(mount), opt_(options) {
  overhead::TagDetectParams p;
  p.quad_min_white_black_diff = options.quad_min_white_black_diff;
  impl_ = std::make_unique<Impl>(p);
  if (options.full_sweep_decimate > 1.0) {
    p.quad_decimate = options.full_sweep_decimate;
    impl_->decimated = std::make_unique<overhead::TagDetector>(p);
  }
  if (options.interval_sweep_decimate > 1.0) {
    p.quad_decimate = options.interval_sweep_decimate;
    impl_->interval = std::make_unique<overhead::TagDetector>(p);
  }
  impl_->K = cv::Matx33d(k_.fx, 0.0, k_.cx, 0.0, k_.fy, k_.cy, 0.0, 0.0, 1.0);
  impl_->dist = {k_.k1, k_.k2, k_.p1, k_.p2, k_.k3};
  if (!(k_.fx > 0.0) || !(k_.fy > 0.0) || k_.width_px <= 0 || k_.height_px <= 0) {
    status_ = TableStatus::kBadIntrinsics;
    status_detail_ = "camera intrinsics need positive focal lengths and image size";
    return;
  }
  std::vector<std::size_t> order;
  for (std::size_t i = 0; i < landmarks.size(); ++i) {
    const site::WallLandmark& w = landmarks[i];
    if (w.family != site::LandmarkFamily::kTag36h11) continue;
    if (!observe_finite_landmark(w)) {
      status_ = TableStatus::kBadLandmark;
      status_detail_ = "wall landmark " + std::to_string(w.id) + " has a bad size or position";
      return;
    }
    order.push_back(i);
  }
  std::stable_sort(order.begin(), order.end(),
                   [&](std::size_t a, std::size_t b) { return landmarks[a].id < landmarks[b].id; });
  for (std::size_t i : order) table_.push_back(landmarks[i]);
  site_index_ = std::move(order);
  for (std::size_t i = 1; i < table_.size(); ++i) {
    if (table_[i].id == table_[i - 1].id) {
      status_ = TableStatus::kDuplicateId;
      status_detail_ = "tag36h11 wall landmark id " + std::to_string(table_[i].id) +
                       " appears more than once in the site";
      table_.clear();
      site_index_.clear();
      return;
    }
  }
}

LandmarkObserver::~LandmarkObserver() = default;

bool LandmarkObserver::measure(std::uint32_t id, const std::array<Vec2, 4>& corners_px,
                               double edge_sigma_px, LandmarkObservation* out,
                               RefusalReason* reason) const {
  const auto it =
      std::lower_bound(table_.begin(), table_.end(), id,
                       [](const site::WallLandmark& w, std::uint32_t v) { return w.id < v; });
  if (it == table_.end() || it->id != id) {
    *reason = RefusalReason::kUnknownId;
    return false;
  }
  if (!inside_margin(corners_px, k_, opt_.edge_margin_px)) {
    *reason = RefusalReason::kTouchesEdge;
    return false;
  }
  // Fixed buffers: no allocation for the four points.
  std::array<cv::Point2d, 4> distorted, undistorted;
  for (std::size_t i = 0; i < 4; ++i) distorted[i] = {corners_px[i].x, corners_px[i].y};
  cv::Mat undistorted_mat(4, 1, CV_64FC2, undistorted.data());
  cv::undistortPoints(cv::Mat(4, 1, CV_64FC2, distorted.data()), undistorted_mat, impl_->K,
                      impl_->dist, cv::noArray(), impl_->K);
  LandmarkObservation o;
  o.id = id;
  o.landmark_index = site_index_[static_cast<std::size_t>(it - table_.begin())];
  o.landmark_xy_mm = {it->x_mm, it->y_mm};
  o.landmark_facing_rad = it->facing_rad;
  o.corners_px = corners_px;
  for (std::size_t i = 0; i < 4; ++i)
    o.corners_undistorted_px[i] = {undistorted[i].x, undistorted[i].y};
  if (overhead::shortest_side_px(o.corners_undistorted_px) < opt_.min_side_px) {
    *reason = RefusalReason::kTooSmall;
    return false;
  }
  o.corner_sigma_px = std::max(opt_.corner_sigma_floor_px, opt_.corner_sigma_scale * edge_sigma_px);
  const double side = it->size_mm;
  const double focal = std::sqrt(k_.fx * k_.fy);

  // Pose: IPPE wants the square's corners in the order (-h, h), (h, h), (h, -h), (-h, -h) of its
  // own frame; with y along the page's down that is bottom-left, bottom-right, top-right, top-left.
  const auto& u = o.corners_undistorted_px;
  std::array<SquarePose, 2> poses;
  double best_err = 0.0, other_err = -1.0;
  const int best =
      best_square_pose(k_, side, impl_->K, {u[3], u[2], u[1], u[0]}, &poses, &best_err, &other_err);
  if (best < 0) {
    *reason = RefusalReason::kNoPose;
    return false;
  }
  o.t_C_mm = poses[static_cast<std::size_t>(best)].t_C_mm;
  o.R_CT = poses[static_cast<std::size_t>(best)].R_CT;
  if (!(o.t_C_mm.z() > 0.0) || !o.t_C_mm.allFinite()) {
    *reason = RefusalReason::kNoPose;
    return false;
  }
  o.reprojection_rms_px = std::sqrt(best_err / 8.0);
  o.cov6 = tag_pose_covariance(focal, side, o.t_C_mm, o.R_CT, o.corner_sigma_px);
  o.pose = range_bearing_from_tag_pose(mount_, o.t_C_mm, o.R_CT, o.cov6);
  o.pose.systematic_cov = observe_mount_cov(
      mount_, opt_.mount_sigma_rad, opt_.mount_sigma_mm, true, [&](const RangingMount& m) {
        return range_bearing_from_tag_pose(m, o.t_C_mm, o.R_CT, o.cov6);
      });
  o.pose.cov += o.pose.systematic_cov;
  // A second solution nearly as good: the tag's turn is not resolved by its corners.
  const double floor_err = 8.0 * o.corner_sigma_px * o.corner_sigma_px;
  const bool lens_ok = !(opt_.focal_sigma_rel > 0.0) ||
                       focal_pose_step(k_, side, o, opt_.focal_sigma_rel, &o.focal_pose_step);
  if (!lens_ok) o.focal_pose_step.setZero();
  // The focal lengths' share, the same in every frame: the systematic share too.
  const Eigen::Matrix<double, 3, 2> lens = lens_response(mount_, o);
  o.pose.cov += lens * lens.transpose();
  o.pose.systematic_cov += lens * lens.transpose();
  const bool yaw_ambiguous =
      other_err >= 0.0 && other_err < opt_.yaw_ambiguity_ratio * std::max(best_err, floor_err);
  if (yaw_ambiguous || !lens_ok) {
    o.pose.has_yaw = false;
    o.pose.relative_yaw_rad = 0.0;
    for (Eigen::Matrix3d* m : {&o.pose.cov, &o.pose.systematic_cov}) {
      m->row(2).setZero();
      m->col(2).setZero();
    }
  }
  o.pose_lens_response = lens;
  if (!o.pose.has_yaw) o.pose_lens_response.row(2).setZero();

  add_size_measure(k_, mount_, opt_, side, &o);
  o.calibration_bearing_var_rad2 = std::pow(opt_.calibration_sigma_px / k_.fx, 2);
  o.calibration_range_var_rel2 = opt_.focal_sigma_rel * opt_.focal_sigma_rel;
  for (Eigen::Matrix3d* m : {&o.size.cov, &o.size.systematic_cov})
    (*m)(0, 0) += o.calibration_range_var_rel2 * o.size.range_mm * o.size.range_mm;
  if (!lens_ok) {  // no step: the pose's range takes the size model's scale share instead
    for (Eigen::Matrix3d* m : {&o.pose.cov, &o.pose.systematic_cov})
      (*m)(0, 0) += o.calibration_range_var_rel2 * o.pose.range_mm * o.pose.range_mm;
  }
  for (RangeBearing* rb : {&o.pose, &o.size}) {
    for (Eigen::Matrix3d* m : {&rb->cov, &rb->systematic_cov})
      (*m)(1, 1) += o.calibration_bearing_var_rad2;
  }
  *out = o;
  return true;
}

bool LandmarkObserver::usable_frame(const cv::Mat& gray) const {
  return status_ == TableStatus::kOk && gray.type() == CV_8UC1 && gray.cols == k_.width_px &&
         gray.rows == k_.height_px;
}

ObserveResult LandmarkObserver::observe(const cv::Mat& gray) const {
  return full_sweep(gray, SweepReason::kNoPrior);
}

ObserveResult LandmarkObserver::full_sweep(const cv::Mat& gray, SweepReason reason) const {
  ObserveResult res;
  res.reason = reason;
  if (!usable_frame(gray)) return res;
  const cv::Rect all(0, 0, gray.cols, gray.rows);
  const std::vector<overhead::TagObservation> dets = impl_->sweep_detector().detect(gray, all);
  std::vector<bool> mirrored(dets.size(), false);
  if (opt_.mirror_check == MirrorCheck::kFullFrame) {
    observe_detail::refuse_mirrored(
        observe_detail::mirrored_reads(impl_->sweep_detector(), gray, all), dets, &mirrored, &res);
  } else if (opt_.mirror_check == MirrorCheck::kOwnWindow) {
    for (const overhead::TagObservation& d : dets) {
      const cv::Rect own = overhead::own_window(d.corners_px, gray.size());
      observe_detail::refuse_mirrored(observe_detail::mirrored_reads(impl_->detector, gray, own),
                                      dets, &mirrored, &res);
    }
  }
  measure_detections(dets, mirrored, &res);
  return res;
}

void LandmarkObserver::measure_detections(const std::vector<overhead::TagObservation>& dets,
                                          const std::vector<bool>& mirrored,
                                          ObserveResult* res) const {
  for (std::size_t i = 0; i < dets.size(); ++i) {
    if (mirrored[i]) continue;
    LandmarkObservation o;
    RefusalReason why = RefusalReason::kNoPose;
    if (measure(dets[i].id, dets[i].corners_px, dets[i].corner_sigma_px, &o, &why)) {
      res->seen.push_back(o);
    } else {
      res->refused.push_back({dets[i].id, why, dets[i].corners_px});
    }
  }
}

Observation fix_observation(const LandmarkObservation& obs, bool from_pose) {
  const RangeBearing& rb = from_pose ? obs.pose : obs.size;
  Observation o;
  o.landmark_mm = obs.landmark_xy_mm;
  o.range_mm = rb.range_mm;
  o.bearing_rad = rb.bearing_rad;
  o.cov = rb.cov.topLeftCorner<2, 2>();
  o.systematic_cov.topLeftCorner<2, 2>() = rb.systematic_cov.topLeftCorner<2, 2>();
  if (from_pose && !obs.focal_pose_step.isZero(0.0)) {
    o.lens_response = obs.pose_lens_response;
  } else {  // the size model's range, or no step: one common scale of the range
    o.lens_response.col(0) << std::sqrt(obs.calibration_range_var_rel2) * rb.range_mm, 0.0, 0.0;
  }
  if (from_pose && rb.has_yaw) {
    o.systematic_cov.row(2) = rb.systematic_cov.row(2);
    o.systematic_cov.col(2) = rb.systematic_cov.col(2);
    o.has_face_yaw = true;
    o.face_yaw_rad = rb.relative_yaw_rad;
    o.face_yaw_var_rad2 = rb.cov(2, 2);
    o.face_yaw_cov = rb.cov.topRightCorner<2, 1>();
    o.landmark_facing_rad = obs.landmark_facing_rad;
  }
  return o;
}

std::vector<Observation> fix_observations(std::span<const LandmarkObservation> obs,
                                          bool from_pose) {
  std::vector<Observation> out;
  out.reserve(obs.size());
  for (const LandmarkObservation& o : obs) out.push_back(fix_observation(o, from_pose));
  return out;
}

Eigen::Matrix<double, 3, 2> lens_response(const RangingMount& mount,
                                          const LandmarkObservation& obs) {
  return tag_pose_jacobian(mount, obs.t_C_mm, obs.R_CT) * obs.focal_pose_step;
}

SensorRangeBearing sensor_range_bearing(const RangingMount& mount, const LandmarkObservation& obs,
                                        double mount_sigma_rad, double mount_sigma_mm) {
  // The same pose seen from a mount at the vehicle's origin without yaw: range and bearing from
  // the optical centre, the bearing relative to the camera's own yaw.
  RangingMount at_sensor = mount;
  at_sensor.x_mm = 0.0;
  at_sensor.y_mm = 0.0;
  at_sensor.yaw_rad = 0.0;
  const RangeBearing rb = range_bearing_from_tag_pose(at_sensor, obs.t_C_mm, obs.R_CT, obs.cov6);
  SensorRangeBearing s;
  s.landmark_xy_mm = Eigen::Vector2d(obs.landmark_xy_mm.x, obs.landmark_xy_mm.y);
  s.sensor_xy_mm = Eigen::Vector2d(mount.x_mm, mount.y_mm);
  s.sensor_yaw_rad = mount.yaw_rad;
  s.range_mm = rb.range_mm;
  s.bearing_rad = rb.bearing_rad;
  s.R_systematic =
      observe_mount_cov(at_sensor, mount_sigma_rad, mount_sigma_mm, false,
                        [&](const RangingMount& m) {
                          return range_bearing_from_tag_pose(m, obs.t_C_mm, obs.R_CT, obs.cov6);
                        })
          .topLeftCorner<2, 2>();
  if (obs.focal_pose_step.isZero(0.0)) {
    s.R_systematic(0, 0) += obs.calibration_range_var_rel2 * s.range_mm * s.range_mm;
  } else {
    const Eigen::Matrix<double, 2, 2> lens = lens_response(at_sensor, obs).topRows<2>();
    s.R_systematic += lens * lens.transpose();
  }
  s.R_systematic(1, 1) += obs.calibration_bearing_var_rad2;
  s.R = rb.cov.topLeftCorner<2, 2>() + s.R_systematic;
  return s;
}

}  // namespace agv::ranging
