// A route as the motion prior of a coasting track (route_prior.hpp).
#include "agv/overhead/route_prior.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

namespace agv::overhead {

// Helpers in a namespace of their own: the library may be built as a unity batch.
namespace route_detail {
namespace {

bool finite_positive(double v) { return std::isfinite(v) && v > 0.0; }

// Segments shorter than this carry no direction.
constexpr double kMinSegmentMm = 1e-6;

}  // namespace
}  // namespace route_detail

namespace rd = route_detail;

std::string validate(const RoutePriorParams& p) {
  if (!rd::finite_positive(p.max_cross_track_mm))
    return "max_cross_track_mm must be finite and > 0";
  if (!(rd::finite_positive(p.max_heading_error_rad) && p.max_heading_error_rad <= kPi)) {
    return "max_heading_error_rad must be in (0, pi]";
  }
  if (!rd::finite_positive(p.cross_track_sigma_mm)) {
    return "cross_track_sigma_mm must be finite and > 0";
  }
  if (!rd::finite_positive(p.heading_sigma_rad)) return "heading_sigma_rad must be finite and > 0";
  return {};
}

bool RoutePath::assign(const std::vector<Vec2>& waypoints_mm, std::string* error) {
  clear();
  auto fail = [&](const std::string& why) {
    if (error != nullptr) *error = why;
    clear();
    return false;
  };
  if (waypoints_mm.size() > kRouteMaxPoints) {
    return fail("more than " + std::to_string(kRouteMaxPoints) + " waypoints");
  }
  pts_.reserve(waypoints_mm.size());
  s_.reserve(waypoints_mm.size());
  for (std::size_t i = 0; i < waypoints_mm.size(); ++i) {
    const Vec2& w = waypoints_mm[i];
    if (!std::isfinite(w.x) || !std::isfinite(w.y)) {
      return fail("waypoint " + std::to_string(i) + " is not finite");
    }
    if (!pts_.empty()) {
      const double d = std::hypot(w.x - pts_.back().x, w.y - pts_.back().y);
      if (!(d > rd::kMinSegmentMm)) continue;
      s_.push_back(s_.back() + d);
    } else {
      s_.push_back(0.0);
    }
    pts_.push_back(w);
  }
  if (pts_.size() < 2) return fail("a route needs two distinct waypoints");
  return true;
}

void RoutePath::clear() {
  pts_.clear();
  s_.clear();
}

Vec2 RoutePath::point_at(double s_mm, std::size_t* segment) const {
  const double s = std::clamp(s_mm, 0.0, length_mm());
  // The last segment whose start is at or before s.
  const auto it = std::upper_bound(s_.begin(), s_.end(), s);
  std::size_t i = static_cast<std::size_t>(std::max<std::ptrdiff_t>(it - s_.begin(), 1)) - 1;
  i = std::min(i, segments() - 1);
  if (segment != nullptr) *segment = i;
  const Vec2 u = direction(i);
  const double t = s - s_[i];
  return {pts_[i].x + t * u.x, pts_[i].y + t * u.y};
}

Vec2 RoutePath::direction(std::size_t i) const {
  const double len = s_[i + 1] - s_[i];
  return {(pts_[i + 1].x - pts_[i].x) / len, (pts_[i + 1].y - pts_[i].y) / len};
}

RouteFit predict_on_route(const RoutePath& route, const RouteFixState& fix, double dt_s,
                          double accel_density, const RoutePriorParams& p, RoutePrediction* out) {
  bool finite = std::isfinite(fix.pose.x_mm) && std::isfinite(fix.pose.y_mm) &&
                std::isfinite(fix.pose.theta_rad) && std::isfinite(fix.v_mmps) &&
                std::isfinite(fix.var_theta_rad2) && std::isfinite(dt_s) &&
                std::isfinite(accel_density);
  for (double c : fix.cov_xyv) finite = finite && std::isfinite(c);
  if (route.empty() || !finite || dt_s < 0.0 || accel_density < 0.0 || out == nullptr) {
    return RouteFit::kInvalid;
  }
  // The nearest segment (within the limits) whose direction agrees with the heading: at a
  // corner both segments are near, and the heading tells which one the vehicle is on.
  std::size_t best = route.segments();
  double best_d = std::numeric_limits<double>::infinity(), best_t = 0.0, best_cross = 0.0;
  double best_heading = 0.0;
  for (std::size_t i = 0; i < route.segments(); ++i) {
    const Vec2 a = route.points()[i];
    const Vec2 u = route.direction(i);
    const double len = route.start_of(i + 1) - route.start_of(i);
    const double dx = fix.pose.x_mm - a.x, dy = fix.pose.y_mm - a.y;
    const double t = std::clamp(dx * u.x + dy * u.y, 0.0, len);
    const double ex = dx - t * u.x, ey = dy - t * u.y;
    const double d = std::hypot(ex, ey);
    const double heading = wrap_angle_rad(fix.pose.theta_rad - std::atan2(u.y, u.x));
    if (d > p.max_cross_track_mm || std::abs(heading) > p.max_heading_error_rad) continue;
    if (d < best_d) {
      best = i;
      best_d = d;
      best_t = t;
      best_cross = u.x * ey - u.y * ex;
      best_heading = heading;
    }
  }
  if (best == route.segments()) return RouteFit::kOffRoute;

  // Along-route position and speed at the fix, carried over dt with the white acceleration.
  const Vec2 u0 = route.direction(best);
  const auto& c = fix.cov_xyv;
  const double var_s0 = u0.x * u0.x * c[0] + 2.0 * u0.x * u0.y * c[1] + u0.y * u0.y * c[4];
  const double cov_sv0 = u0.x * c[2] + u0.y * c[5];
  const double var_v0 = c[8];
  const double t = dt_s;
  const double var_s =
      std::max(0.0, var_s0 + 2.0 * t * cov_sv0 + t * t * var_v0) + accel_density * t * t * t / 3.0;
  const double var_cross0 = u0.y * u0.y * c[0] - 2.0 * u0.x * u0.y * c[1] + u0.x * u0.x * c[4];
  const double var_cross =
      std::max(p.cross_track_sigma_mm * p.cross_track_sigma_mm, std::max(0.0, var_cross0));
  const double var_theta =
      std::max(p.heading_sigma_rad * p.heading_sigma_rad, std::max(0.0, fix.var_theta_rad2));

  const double s0 = route.start_of(best) + best_t;
  const double s1 = s0 + std::max(0.0, fix.v_mmps) * t;
  std::size_t seg = 0;
  const Vec2 q = route.point_at(s1, &seg);
  const Vec2 u = route.direction(seg);
  RoutePrediction r;
  r.pose = {q.x, q.y, std::atan2(u.y, u.x)};
  r.s_mm = std::min(s1, route.length_mm());
  r.at_end = s1 >= route.length_mm();
  r.cross_track_mm = best_cross;
  r.heading_error_rad = best_heading;
  // Along u, across n = (-u.y, u.x).
  r.cov[0] = var_s * u.x * u.x + var_cross * u.y * u.y;
  r.cov[1] = r.cov[3] = (var_s - var_cross) * u.x * u.y;
  r.cov[4] = var_s * u.y * u.y + var_cross * u.x * u.x;
  r.cov[8] = var_theta;
  *out = r;
  return RouteFit::kOnRoute;
}

}  // namespace agv::overhead
