// LandmarkObserver's predicted windows (observe.hpp): each landmark the pose prior puts in view
// projected into the camera at the prior pose, a window around it grown by the projected
// uncertainty of the prior, the mount and the lens calibration, and libapriltag run in those
// windows only; at an interval the whole frame at a coarser quad decimation as well. A full sweep
// when there is no usable prior or when the windows would cover much of the frame.
#include <algorithm>
#include <cmath>
#include <limits>
#include <opencv2/core.hpp>

#include "agv/ranging/observe.hpp"
#include "agv/site/site_geometry.hpp"
#include "observe_internal.hpp"

namespace agv::ranging {

// Named, not anonymous: the library is built as one unity source.
namespace window_detail {

// Below this depth (mm) a corner is taken as not imageable.
constexpr double kMinDepthMm = 100.0;
// Central-difference steps for the corners' Jacobian.
constexpr double kStepMm = 1.0;
constexpr double kStepRad = 1e-4;
// libapriltag does not search windows smaller than this (TagDetector's own limit).
constexpr int kMinWindowPx = 16;
// Normalised coordinates beyond this factor of the image's own half-extent are not projected:
// the distortion polynomial folds back far outside the calibrated field.
constexpr double kFieldFactor = 1.5;

// Corners of a wall landmark in the site frame, page order TL TR BR BL: page right is the
// horizontal in the face to the right of a viewer facing it, page up is site +z.
std::array<Eigen::Vector3d, 4> landmark_corners_site(const site::WallLandmark& w) {
  const double h = w.size_mm / 2.0;
  const Eigen::Vector3d c(w.x_mm, w.y_mm, w.z_mm);
  const Eigen::Vector3d right(-std::sin(w.facing_rad), std::cos(w.facing_rad), 0.0);
  const Eigen::Vector3d up(0.0, 0.0, 1.0);
  return {c - h * right + h * up, c + h * right + h * up, c + h * right - h * up,
          c - h * right - h * up};
}

// Every corner's sight line from the camera at the vehicle pose crosses an obstacle: the
// landmark cannot be read there. One corner in sight keeps it (the prior's doubt and the
// outline's survey put the edge of the shadow in doubt too).
bool hidden(const std::array<Eigen::Vector3d, 4>& corners_site, const Pose2& pose,
            const RangingMount& mount, std::span<const site::Obstacle> obstacles) {
  if (obstacles.empty()) return false;
  const double c = std::cos(pose.theta_rad), s = std::sin(pose.theta_rad);
  const std::array<double, 3> cam{pose.x_mm + c * mount.x_mm - s * mount.y_mm,
                                  pose.y_mm + s * mount.x_mm + c * mount.y_mm, mount.z_mm};
  return std::all_of(corners_site.begin(), corners_site.end(), [&](const Eigen::Vector3d& p) {
    return site::sight_line_blocked(cam, {p.x(), p.y(), p.z()}, obstacles);
  });
}

// The corners in distorted pixels seen from vehicle pose (x, y, theta) through the mount; false
// when one is behind the camera or outside the field the lens model holds for.
bool project_corners(const std::array<Eigen::Vector3d, 4>& corners_site, const Pose2& pose,
                     const RangingMount& mount, const CameraModel& cam, std::array<Vec2, 4>* out) {
  const Eigen::Matrix3d R_CV = rotation_vehicle_from_camera(mount).transpose();
  const Eigen::Vector3d m(mount.x_mm, mount.y_mm, mount.z_mm);
  const double c = std::cos(pose.theta_rad), s = std::sin(pose.theta_rad);
  const CameraIntrinsics& k = cam.intrinsics;
  const double max_x = kFieldFactor * std::max(k.cx, k.width_px - k.cx) / k.fx;
  const double max_y = kFieldFactor * std::max(k.cy, k.height_px - k.cy) / k.fy;
  for (std::size_t i = 0; i < 4; ++i) {
    const double dx = corners_site[i].x() - pose.x_mm, dy = corners_site[i].y() - pose.y_mm;
    const Eigen::Vector3d p_V(c * dx + s * dy, -s * dx + c * dy, corners_site[i].z());
    const Eigen::Vector3d p_C = R_CV * (p_V - m);
    if (!(p_C.z() > kMinDepthMm)) return false;
    const Vec2 xn{p_C.x() / p_C.z(), p_C.y() / p_C.z()};
    if (std::abs(xn.x) > max_x || std::abs(xn.y) > max_y) return false;
    (*out)[i] = cam.distort_normalized_to_pixel(xn);
  }
  return true;
}

// Whether the landmark's printed face turns towards the camera within max_angle_rad.
bool faces_camera(const site::WallLandmark& w, const Pose2& pose, const RangingMount& mount,
                  double max_angle_rad) {
  const double c = std::cos(pose.theta_rad), s = std::sin(pose.theta_rad);
  const Eigen::Vector3d cam(pose.x_mm + c * mount.x_mm - s * mount.y_mm,
                            pose.y_mm + s * mount.x_mm + c * mount.y_mm, mount.z_mm);
  const Eigen::Vector3d to_cam = cam - Eigen::Vector3d(w.x_mm, w.y_mm, w.z_mm);
  const Eigen::Vector3d n(std::cos(w.facing_rad), std::sin(w.facing_rad), 0.0);
  return n.dot(to_cam) > std::cos(max_angle_rad) * to_cam.norm();
}

// Adds sigma^2 d d^T of each corner for one perturbed projection (d = central difference).
void add_corner_term(const std::array<Vec2, 4>& plus, const std::array<Vec2, 4>& minus, double step,
                     double sigma, std::array<Eigen::Matrix2d, 4>* cov) {
  for (std::size_t i = 0; i < 4; ++i) {
    const Eigen::Vector2d d((plus[i].x - minus[i].x) / (2.0 * step),
                            (plus[i].y - minus[i].y) / (2.0 * step));
    (*cov)[i] += sigma * sigma * d * d.transpose();
  }
}

// Largest 1-sigma of a corner coordinate (separately for u and v) from the prior's covariance,
// the mount's calibration sigmas and the lens calibration; false when a perturbed projection
// fails (the landmark is at the edge of being imageable).
bool corner_sigmas(const std::array<Eigen::Vector3d, 4>& cs, const PosePrior& prior,
                   const RangingMount& mount, const CameraModel& cam, const ObserveOptions& opt,
                   const std::array<Vec2, 4>& at_prior, double* sigma_u, double* sigma_v) {
  std::array<Eigen::Matrix2d, 4> cov;
  cov.fill(Eigen::Matrix2d::Zero());
  Eigen::Matrix<double, 2, 3> J[4];
  std::array<Vec2, 4> a{}, b{};
  const double pose_steps[3] = {kStepMm, kStepMm, kStepRad};
  for (int j = 0; j < 3; ++j) {
    Pose2 pa = prior.pose, pb = prior.pose;
    double* fa[3] = {&pa.x_mm, &pa.y_mm, &pa.theta_rad};
    double* fb[3] = {&pb.x_mm, &pb.y_mm, &pb.theta_rad};
    *fa[j] += pose_steps[j];
    *fb[j] -= pose_steps[j];
    if (!project_corners(cs, pa, mount, cam, &a) || !project_corners(cs, pb, mount, cam, &b))
      return false;
    for (std::size_t i = 0; i < 4; ++i) {
      J[i](0, j) = (a[i].x - b[i].x) / (2.0 * pose_steps[j]);
      J[i](1, j) = (a[i].y - b[i].y) / (2.0 * pose_steps[j]);
    }
  }
  for (std::size_t i = 0; i < 4; ++i) cov[i] = J[i] * prior.cov * J[i].transpose();
  double RangingMount::*const fields[] = {&RangingMount::roll_rad, &RangingMount::pitch_rad,
                                          &RangingMount::yaw_rad,  &RangingMount::x_mm,
                                          &RangingMount::y_mm,     &RangingMount::z_mm};
  for (std::size_t f = 0; f < 6; ++f) {
    const bool angle = f < 3;
    const double sigma = angle ? opt.mount_sigma_rad : opt.mount_sigma_mm;
    if (!(sigma > 0.0)) continue;
    const double step = angle ? kStepRad : kStepMm;
    RangingMount ma = mount, mb = mount;
    ma.*fields[f] += step;
    mb.*fields[f] -= step;
    if (!project_corners(cs, prior.pose, ma, cam, &a) ||
        !project_corners(cs, prior.pose, mb, cam, &b))
      return false;
    add_corner_term(a, b, step, sigma, &cov);
  }
  const CameraIntrinsics& k = cam.intrinsics;
  *sigma_u = *sigma_v = 0.0;
  for (std::size_t i = 0; i < 4; ++i) {
    const double fu = opt.focal_sigma_rel * (at_prior[i].x - k.cx);
    const double fv = opt.focal_sigma_rel * (at_prior[i].y - k.cy);
    const double cal2 = opt.calibration_sigma_px * opt.calibration_sigma_px;
    *sigma_u = std::max(*sigma_u, std::sqrt(cov[i](0, 0) + cal2 + fu * fu));
    *sigma_v = std::max(*sigma_v, std::sqrt(cov[i](1, 1) + cal2 + fv * fv));
  }
  return true;
}

bool prior_usable(const PosePrior& prior, const WindowOptions& wopt) {
  if (!prior.cov.allFinite() || !std::isfinite(prior.pose.x_mm) ||
      !std::isfinite(prior.pose.y_mm) || !std::isfinite(prior.pose.theta_rad)) {
    return false;
  }
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix2d> es(prior.cov.topLeftCorner<2, 2>());
  const double worst_mm2 = es.eigenvalues().maxCoeff();
  return es.eigenvalues().minCoeff() >= 0.0 && prior.cov(2, 2) >= 0.0 &&
         worst_mm2 <= wopt.max_position_sd_mm * wopt.max_position_sd_mm &&
         prior.cov(2, 2) <= wopt.max_heading_sd_rad * wopt.max_heading_sd_rad;
}

// Overlapping windows merged into their bounding rectangles (until none overlap), so that no
// tag is searched twice.
std::vector<SearchWindow> merge_windows(std::vector<SearchWindow> w) {
  for (bool merged = true; merged;) {
    merged = false;
    for (std::size_t i = 0; i < w.size() && !merged; ++i) {
      for (std::size_t j = i + 1; j < w.size(); ++j) {
        // Overlapping windows of one decimation are merged when their bounding box wastes
        // little. A near tag's coarse window over a far tag's fine one, or two crossing at a
        // corner, stay two: a tag read in both is kept once.
        const cv::Rect a = w[i].rect, b = w[j].rect;
        if (w[i].decimation == w[j].decimation && (a & b).area() > 0 &&
            (a | b).area() <= a.area() + b.area()) {
          w[i].rect |= b;
          w.erase(w.begin() + static_cast<std::ptrdiff_t>(j));
          merged = true;
          break;
        }
      }
    }
  }
  return w;
}

}  // namespace window_detail

bool LandmarkObserver::predict_landmark(const site::WallLandmark& w, const PosePrior& prior,
                                        const WindowOptions& wopt, PredictedLandmark* out) const {
  using namespace window_detail;
  if (!faces_camera(w, prior.pose, mount_, wopt.max_view_angle_rad)) return false;
  CameraModel cam;
  cam.intrinsics = k_;
  const std::array<Eigen::Vector3d, 4> cs = landmark_corners_site(w);
  std::array<Vec2, 4> px{};
  if (!project_corners(cs, prior.pose, mount_, cam, &px)) return false;
  const double side = overhead::shortest_side_px(px);
  if (side < wopt.min_side_share * opt_.min_side_px) return false;
  double su = 0.0, sv = 0.0;
  if (!corner_sigmas(cs, prior, mount_, cam, opt_, px, &su, &sv)) return false;
  double x0 = px[0].x, x1 = x0, y0 = px[0].y, y1 = y0;
  for (const Vec2& c : px) {
    x0 = std::min(x0, c.x);
    x1 = std::max(x1, c.x);
    y0 = std::min(y0, c.y);
    y1 = std::max(y1, c.y);
  }
  const double margin =
      std::max(wopt.margin_px, wopt.margin_side_share * std::max(x1 - x0, y1 - y0));
  const double mu = wopt.sigma_count * su + margin, mv = wopt.sigma_count * sv + margin;
  const cv::Rect r(
      cv::Point(static_cast<int>(std::floor(x0 - mu)), static_cast<int>(std::floor(y0 - mv))),
      cv::Point(static_cast<int>(std::ceil(x1 + mu)) + 1,
                static_cast<int>(std::ceil(y1 + mv)) + 1));
  const cv::Rect window = r & cv::Rect(0, 0, k_.width_px, k_.height_px);
  if (window.width < kMinWindowPx || window.height < kMinWindowPx) return false;
  out->id = w.id;
  out->corners_px = px;
  out->corner_sigma_px = std::max(su, sv);
  out->side_px = side;
  out->window = window;
  // Tried whatever the prior's sigma: a read the prior did not promise within the search still
  // saves its window, and a failed one costs a fraction of the window's search.
  out->predicted_path = wopt.predicted_first;
  out->decimation = overhead::search_decimation(side, wopt.decimated_side_px, wopt.max_decimation);
  return true;
}

WindowPlan LandmarkObserver::plan_windows(const PosePrior* prior, std::uint64_t frame_index,
                                          const WindowOptions& wopt) const {
  using namespace window_detail;
  WindowPlan plan;
  if (!prior) return plan;  // full sweep, no prior
  const bool interval =
      wopt.full_sweep_interval_frames > 0 && frame_index % wopt.full_sweep_interval_frames == 0;
  // A mirrored read of everything searched (kFullFrame) keeps the interval a full sweep.
  if (interval && (!impl_->interval || opt_.mirror_check == MirrorCheck::kFullFrame)) {
    plan.reason = SweepReason::kInterval;
    return plan;
  }
  if (!prior_usable(*prior, wopt)) {
    plan.reason = SweepReason::kUncertainPrior;
    return plan;
  }
  std::vector<SearchWindow> windows;
  for (const site::WallLandmark& w : table_) {
    PredictedLandmark p;
    if (!predict_landmark(w, *prior, wopt, &p)) continue;
    if (hidden(landmark_corners_site(w), prior->pose, mount_, obstacles_)) {
      ++plan.hidden;
      continue;
    }
    plan.predicted.push_back(p);
    windows.push_back({p.window, p.decimation});
  }
  plan.windows = merge_windows(std::move(windows));
  double searched_px = 0.0;
  for (const SearchWindow& w : plan.windows) {
    searched_px += static_cast<double>(w.rect.area()) / (w.decimation * w.decimation);
  }
  if (searched_px > wopt.max_window_share * k_.width_px * k_.height_px) {
    plan.reason = SweepReason::kWindowsTooLarge;
    return plan;
  }
  plan.full_sweep = false;
  plan.reason = interval ? SweepReason::kInterval : SweepReason::kWindows;
  plan.discovery = interval;
  return plan;
}

std::vector<overhead::TagObservation> LandmarkObserver::detect_in(const cv::Mat& gray,
                                                                  const SearchWindow& w) const {
  return impl_->detector.detect(gray, w.rect, w.decimation);
}

std::vector<bool> LandmarkObserver::read_predicted(
    const cv::Mat& gray, const WindowPlan& plan,
    std::vector<overhead::TagObservation>* dets) const {
  std::vector<bool> read(plan.predicted.size(), false);
  const int bits = impl_->detector.params().global_bits_corrected;
  for (std::size_t i = 0; i < plan.predicted.size(); ++i) {
    const PredictedLandmark& p = plan.predicted[i];
    overhead::TagObservation o;
    if (p.predicted_path && impl_->detector.detect_predicted(gray, p.corners_px, {p.id}, &o) &&
        o.id == p.id && o.hamming <= bits) {
      dets->push_back(o);
      read[i] = true;
    }
  }
  return read;
}

bool LandmarkObserver::window_done(const WindowPlan& plan, const std::vector<bool>& read,
                                   const SearchWindow& w) {
  bool any = false;
  for (std::size_t i = 0; i < plan.predicted.size(); ++i) {
    if ((plan.predicted[i].window & w.rect).area() == 0) continue;
    if (!read[i]) return false;
    any = true;
  }
  return any;
}

int LandmarkObserver::unread_decimation(const WindowPlan& plan, const std::vector<bool>& read,
                                        const SearchWindow& w) {
  int dec = std::numeric_limits<int>::max();
  for (std::size_t i = 0; i < plan.predicted.size(); ++i) {
    if (!read[i] && (plan.predicted[i].window & w.rect).area() > 0) {
      dec = std::min(dec, plan.predicted[i].decimation);
    }
  }
  return dec == std::numeric_limits<int>::max() ? w.decimation : std::max(dec, w.decimation);
}

void LandmarkObserver::search_windows(const cv::Mat& gray, const WindowPlan& plan,
                                      const std::vector<bool>& read, WindowReads* out,
                                      ObserveResult* res) const {
  for (const SearchWindow& w : plan.windows) {
    if (window_done(plan, read, w)) continue;
    for (const overhead::TagObservation& d :
         detect_in(gray, {w.rect, unread_decimation(plan, read, w)})) {
      if (std::any_of(out->dets.begin(), out->dets.end(),
                      [&](const overhead::TagObservation& o) { return o.id == d.id; }))
        continue;  // read on the predicted path or in another window (ids are unique)
      // Confirmed by the prior: a predicted id whose predicted window holds the read.
      const bool expected = std::any_of(
          plan.predicted.begin(), plan.predicted.end(),
          [&](const auto& p) { return p.id == d.id && (p.window & w.rect).area() > 0; });
      out->dets.push_back(d);
      out->confirmed.push_back(expected);
    }
    ++res->windows_searched;
  }
}

void LandmarkObserver::search_discovery(const cv::Mat& gray, const WindowPlan& plan,
                                        WindowReads* out) const {
  std::vector<std::uint32_t> known;
  for (const overhead::TagObservation& d : out->dets) known.push_back(d.id);
  const cv::Rect all(0, 0, gray.cols, gray.rows);
  for (const overhead::TagObservation& d : impl_->interval->detect(gray, all)) {
    if (std::find(known.begin(), known.end(), d.id) != known.end()) continue;
    const cv::Point centre(static_cast<int>(0.25 * (d.corners_px[0].x + d.corners_px[1].x +
                                                    d.corners_px[2].x + d.corners_px[3].x)),
                           static_cast<int>(0.25 * (d.corners_px[0].y + d.corners_px[1].y +
                                                    d.corners_px[2].y + d.corners_px[3].y)));
    const bool expected =
        std::any_of(plan.predicted.begin(), plan.predicted.end(),
                    [&](const auto& p) { return p.id == d.id && p.window.contains(centre); });
    out->dets.push_back(d);
    out->confirmed.push_back(expected);
    known.push_back(d.id);
  }
}

ObserveResult LandmarkObserver::observe(const cv::Mat& gray, const WindowPlan& plan) const {
  if (plan.full_sweep) return full_sweep(gray, plan.reason);
  ObserveResult res;
  res.full_sweep = false;
  res.reason = plan.reason;
  if (!usable_frame(gray)) return res;
  WindowReads reads;
  const std::vector<bool> read = read_predicted(gray, plan, &reads.dets);
  reads.confirmed.assign(reads.dets.size(), true);
  res.predicted_reads = reads.dets.size();
  search_windows(gray, plan, read, &reads, &res);
  if (plan.discovery && impl_->interval) search_discovery(gray, plan, &reads);
  const std::vector<overhead::TagObservation>& dets = reads.dets;
  const std::vector<bool>& confirmed = reads.confirmed;
  std::vector<bool> mirrored(dets.size(), false);
  if (opt_.mirror_check == MirrorCheck::kFullFrame) {
    for (const SearchWindow& w : plan.windows) {
      observe_detail::refuse_mirrored(observe_detail::mirrored_reads(impl_->detector, gray, w.rect),
                                      dets, &mirrored, &res);
    }
  } else if (opt_.mirror_check == MirrorCheck::kOwnWindow) {
    for (std::size_t i = 0; i < dets.size(); ++i) {
      if (confirmed[i]) continue;
      const cv::Rect own = overhead::own_window(dets[i].corners_px, gray.size());
      observe_detail::refuse_mirrored(observe_detail::mirrored_reads(impl_->detector, gray, own),
                                      dets, &mirrored, &res);
    }
  }
  measure_detections(dets, mirrored, &res);
  return res;
}

ObserveResult LandmarkObserver::observe(const cv::Mat& gray, const PosePrior* prior,
                                        std::uint64_t frame_index,
                                        const WindowOptions& wopt) const {
  return observe(gray, plan_windows(prior, frame_index, wopt));
}

}  // namespace agv::ranging
