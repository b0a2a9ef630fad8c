// Search windows from the prediction (docs/design/tracking.md): the trust rule, the projection of
// each mapped landmark's outer square grown by its position uncertainty, and the extrapolation of a
// fused estimate to a frame's exposure.
#include "agv/vision/tracking.hpp"

#include <algorithm>
#include <array>
#include <cmath>

namespace agv::vision {

namespace {

// The grown corner circle is bounded by a polygon of this many vertices, scaled to circumscribe it
// (radius / cos(pi / n)): its image contains the circle's image wherever the projection is locally
// affine, at 8 % extra width.
constexpr int kCirclePolygon = 8;
// The outside ring of the ring check runs 0.9 border widths beyond the outer edge and the corner
// template reaches 1 border width beyond it (detect.cpp); 1.5 covers both with a pixel to spare.
constexpr double kDetectReachBorderWidths = 1.5;
// Coarse pixels added beyond the binarization block: the block's odd rounding and the coarse
// grid's alignment (landmark_localizer.cpp aligns windows to it) each move it by up to one.
constexpr double kAlignmentCoarsePx = 2.0;
// Image angle probe along the landmark's x axis (mm on the floor): long enough for pixel
// rounding not to matter, short enough for the local distortion.
constexpr double kAngleProbeMm = 5.0;

double largest_eigen2(double a, double b, double c) {
  const double h = 0.5 * (a - c);
  return 0.5 * (a + c) + std::sqrt(h * h + b * b);
}

// Image angle reduced to (-45, 45] degrees: a square's border normals repeat every 90 degrees.
double reduce_90(double a) {
  const double q = kPi / 2.0;
  a = std::fmod(a, q);
  if (a > q / 2.0) a -= q;
  if (a <= -q / 2.0) a += q;
  return a;
}

int coarse_factor_of(const VisionConfig& v, const LandmarkGeometry& g, double mm_per_px) {
  // As VisionSetup's constructor: the largest power of two keeping coarse_border_px.
  const double border_px = g.border_width_mm() / mm_per_px;
  int f = 1;
  while (border_px / (f * 2) >= v.coarse_border_px) f *= 2;
  return f;
}

}  // namespace

bool prediction_trusted(const Prediction& pred, const TrackingConfig& cfg) {
  if (!cfg.enabled || !pred.valid) return false;
  if (!pred.cov.allFinite() || !std::isfinite(pred.vehicle_in_world.x_mm) ||
      !std::isfinite(pred.vehicle_in_world.y_mm) ||
      !std::isfinite(pred.vehicle_in_world.theta_rad)) {
    return false;
  }
  const double pos_var = largest_eigen2(pred.cov(0, 0), pred.cov(0, 1), pred.cov(1, 1));
  const double max_pos = cfg.max_position_sigma_mm;
  const double max_head = deg_to_rad(cfg.max_heading_sigma_deg);
  return pos_var >= 0.0 && pred.cov(2, 2) >= 0.0 && pos_var <= max_pos * max_pos &&
         pred.cov(2, 2) <= max_head * max_head;
}

double detection_margin_mm(const VisionConfig& vision, const LandmarkGeometry& geom,
                           const CameraModel& cam) {
  double mm_per_px = cam.mm_per_px();
  if (!(mm_per_px > 0.0) || !std::isfinite(mm_per_px)) mm_per_px = 0.26;
  const double coarse_mm = coarse_factor_of(vision, geom, mm_per_px) * mm_per_px;
  return kDetectReachBorderWidths * geom.border_width_mm() + 0.5 * vision.adaptive_block_mm +
         (1.0 + kAlignmentCoarsePx) * coarse_mm;
}

double WindowPlanner::point_sigma_mm(Vec2 p, const Eigen::Matrix3d& cov) {
  // p_V = R(theta)^T (p_W - t). With cov in vehicle axes: d p_V / d t_V = -I and
  // d p_V / d theta = (p_V.y, -p_V.x).
  Eigen::Matrix<double, 2, 3> j;
  j << -1.0, 0.0, p.y, 0.0, -1.0, -p.x;
  const Eigen::Matrix2d s = j * cov * j.transpose();
  return std::sqrt(std::max(0.0, largest_eigen2(s(0, 0), s(0, 1), s(1, 1))));
}

WindowPlanner::WindowPlanner(const VisionConfig& vision, const CameraModel& cam,
                             const LandmarkGeometry& geom, const LandmarkMap* map)
    : cfg_(vision.tracking),
      cam_(cam),
      floor_(cam),
      geom_(geom),
      map_(map),
      index_(map ? std::make_shared<const LandmarkIndex>(*map) : nullptr),
      margin_mm_(detection_margin_mm(vision, geom, cam)) {
  const double w = cam.intrinsics.width_px, h = cam.intrinsics.height_px;
  const std::array<Vec2, 8> border = {Vec2{0, 0}, Vec2{w / 2, 0}, Vec2{w, 0}, Vec2{w, h / 2},
                                      Vec2{w, h}, Vec2{w / 2, h}, Vec2{0, h}, Vec2{0, h / 2}};
  for (const Vec2& px : border) {
    Vec2 p;
    if (!cam.pixel_to_vehicle(px, &p)) {
      // A border pixel that does not reach the floor: no footprint bound, every landmark is a
      // candidate (the projection still decides).
      footprint_radius_mm_ = HUGE_VAL;
      return;
    }
    footprint_radius_mm_ = std::max(footprint_radius_mm_, std::hypot(p.x, p.y));
  }
}

void WindowPlanner::plan(const Prediction& pred, std::vector<SearchWindow>* out) const {
  out->clear();
  if (!map_ || !prediction_trusted(pred, cfg_)) return;
  const Pose2& v = pred.vehicle_in_world;
  // Covariance in vehicle axes: position block rotated by R^T, heading unchanged.
  const double c = std::cos(v.theta_rad), s = std::sin(v.theta_rad);
  Eigen::Matrix3d rt = Eigen::Matrix3d::Identity();
  rt(0, 0) = c;
  rt(0, 1) = s;
  rt(1, 0) = -s;
  rt(1, 1) = c;
  const Eigen::Matrix3d cov_v = rt * pred.cov * rt.transpose();
  const double pos_sigma =
      std::sqrt(std::max(0.0, largest_eigen2(cov_v(0, 0), cov_v(0, 1), cov_v(1, 1))));
  const double head_sigma = std::sqrt(std::max(0.0, cov_v(2, 2)));
  const double diag_mm = std::sqrt(2.0) * geom_.outer_half_mm();
  const Pose2 world_to_vehicle = inverse(v);
  const auto consider = [&](const LandmarkMapEntry& e) {
    const Vec2 q = transform(world_to_vehicle, {e.pose.x_mm, e.pose.y_mm});
    const double d = std::hypot(q.x, q.y);
    const double reach = footprint_radius_mm_ + diag_mm + margin_mm_ +
                         cfg_.window_sigmas * (pos_sigma + head_sigma * (d + diag_mm));
    if (d > reach) return;
    SearchWindow w;
    if (window_for(v, cov_v, e, &w)) out->push_back(w);
  };
  // The reach test above, solved for d: d <= fixed / (1 - window_sigmas * head_sigma). Only the
  // landmarks within that distance of the vehicle can pass it, so the index's disc holds every
  // window (in the map's order, as the scan below gives them).
  const double growth = cfg_.window_sigmas * head_sigma;
  const double fixed = footprint_radius_mm_ + diag_mm + margin_mm_ +
                       cfg_.window_sigmas * (pos_sigma + head_sigma * diag_mm);
  if (index_ && growth < 1.0 && std::isfinite(fixed)) {
    // The slack covers the two distance formulas' rounding at the disc's edge.
    const double radius_mm = fixed / (1.0 - growth) * (1.0 + 1e-9) + 1e-6;
    index_->within({v.x_mm, v.y_mm}, radius_mm, &near_);
    for (const LandmarkMapEntry* e : near_) consider(*e);
    return;
  }
  for (const auto& [id, e] : map_->entries) consider(e);
}

bool WindowPlanner::window_for(const Pose2& v, const Eigen::Matrix3d& cov_v,
                               const LandmarkMapEntry& e, SearchWindow* w) const {
  const Pose2 landmark_in_vehicle = compose(inverse(v), e.pose);
  const int width = cam_.intrinsics.width_px, height = cam_.intrinsics.height_px;
  double min_x = HUGE_VAL, min_y = HUGE_VAL, max_x = -HUGE_VAL, max_y = -HUGE_VAL;
  const double poly = 1.0 / std::cos(kPi / kCirclePolygon);
  // The polygon's vertex directions, the same values as computed per vertex.
  static const std::array<Vec2, kCirclePolygon> kUnitPolygon = [] {
    std::array<Vec2, kCirclePolygon> u;
    for (int k = 0; k < kCirclePolygon; ++k) {
      const double a = 2.0 * kPi * k / kCirclePolygon;
      u[static_cast<size_t>(k)] = {std::cos(a), std::sin(a)};
    }
    return u;
  }();
  bool all_projected = true;
  double corner_sigma_mm = 0.0;
  for (const Vec2& corner_l : geom_.outer_corners_landmark_mm()) {
    const Vec2 p = transform(landmark_in_vehicle, corner_l);
    const double sigma_mm = point_sigma_mm(p, cov_v);
    corner_sigma_mm = std::max(corner_sigma_mm, sigma_mm);
    const double r = (cfg_.window_sigmas * sigma_mm + margin_mm_) * poly;
    for (const Vec2& u : kUnitPolygon) {
      Vec2 px;
      if (!floor_.vehicle_to_pixel({p.x + r * u.x, p.y + r * u.y}, &px)) {
        all_projected = false;
        continue;
      }
      min_x = std::min(min_x, px.x);
      max_x = std::max(max_x, px.x);
      min_y = std::min(min_y, px.y);
      max_y = std::max(max_y, px.y);
    }
  }
  if (!all_projected) {
    // Part of the grown square cannot be imaged (behind a tilted camera): no bound, whole image.
    min_x = min_y = -HUGE_VAL;
    max_x = max_y = HUGE_VAL;
  }
  // Pixel i covers [i - 0.5, i + 0.5).
  w->x0 = static_cast<int>(std::clamp(std::floor(min_x + 0.5), 0.0, static_cast<double>(width)));
  w->y0 = static_cast<int>(std::clamp(std::floor(min_y + 0.5), 0.0, static_cast<double>(height)));
  w->x1 =
      static_cast<int>(std::clamp(std::floor(max_x + 0.5) + 1.0, 0.0, static_cast<double>(width)));
  w->y1 =
      static_cast<int>(std::clamp(std::floor(max_y + 0.5) + 1.0, 0.0, static_cast<double>(height)));
  if (w->x0 >= w->x1 || w->y0 >= w->y1) return false;
  w->landmark_id = e.id;
  const Vec2 centre{landmark_in_vehicle.x_mm, landmark_in_vehicle.y_mm};
  const Vec2 probe = transform(landmark_in_vehicle, {kAngleProbeMm, 0.0});
  Vec2 c_px, p_px;
  if (floor_.vehicle_to_pixel(centre, &c_px) && floor_.vehicle_to_pixel(probe, &p_px)) {
    w->centre_px = c_px;
    w->up_angle_rad = reduce_90(std::atan2(p_px.y - c_px.y, p_px.x - c_px.x));
  }
  w->up_angle_sigma_rad = std::sqrt(std::max(0.0, cov_v(2, 2)));
  w->corner_sigma_px = corner_sigma_mm / cam_.mm_per_px();
  return true;
}

Prediction extrapolate(const MotionSnapshot& s, std::int64_t t_ns, double pos_growth_mm_per_s,
                       double heading_growth_rad_per_s) {
  Prediction p;
  if (!s.valid) return p;
  const double dt = static_cast<double>(t_ns - s.t_ns) * 1e-9;
  const double mid = s.vehicle_in_world.theta_rad + 0.5 * s.omega_rad_per_s * dt;
  const double ds = s.v_mm_per_s * dt;
  p.valid = true;
  p.vehicle_in_world.x_mm = s.vehicle_in_world.x_mm + ds * std::cos(mid);
  p.vehicle_in_world.y_mm = s.vehicle_in_world.y_mm + ds * std::sin(mid);
  p.vehicle_in_world.theta_rad =
      wrap_angle_rad(s.vehicle_in_world.theta_rad + s.omega_rad_per_s * dt);
  Eigen::Matrix3d f = Eigen::Matrix3d::Identity();
  f(0, 2) = -ds * std::sin(mid);
  f(1, 2) = ds * std::cos(mid);
  const double qp = pos_growth_mm_per_s * std::abs(dt),
               qh = heading_growth_rad_per_s * std::abs(dt);
  p.cov = f * s.cov * f.transpose();
  p.cov(0, 0) += qp * qp;
  p.cov(1, 1) += qp * qp;
  p.cov(2, 2) += qh * qh;
  return p;
}

}  // namespace agv::vision
