// Two-landmark fixes: the intersection of two range circles and the two rules that pick one of
// its two solutions; headings from bearings.
#include <algorithm>
#include <array>
#include <cmath>

#include "agv/ranging/fix.hpp"

namespace agv::ranging {

namespace {

double circles_cross(Vec2 a, Vec2 b) { return a.x * b.y - a.y * b.x; }
double circles_dot(Vec2 a, Vec2 b) { return a.x * b.x + a.y * b.y; }
Vec2 circles_sub(Vec2 a, Vec2 b) { return {a.x - b.x, a.y - b.y}; }

// Bearing of l1 minus bearing of l0 as seen from p (counter-clockwise positive).
double circles_subtended_rad(Vec2 p, Vec2 l0, Vec2 l1) {
  const Vec2 a = circles_sub(l0, p), b = circles_sub(l1, p);
  return std::atan2(circles_cross(a, b), circles_dot(a, b));
}

// The two-circle pose as a function of the measurements z = (r0, b0, r1, b1), with the solution
// index held fixed so that the function is smooth for the numeric Jacobian.
bool circles_pose(const Observation& o0, const Observation& o1, const double z[4], int index,
                  double tolerance_mm, Eigen::Vector3d* pose) {
  const CircleCrossing c =
      intersect_circles(o0.landmark_mm, z[0], o1.landmark_mm, z[2], tolerance_mm);
  if (c.count == 0) return false;
  const Vec2 p = c.solutions[c.count == 1 ? 0 : index];
  Observation obs[2] = {o0, o1};
  obs[0].range_mm = z[0];
  obs[0].bearing_rad = z[1];
  obs[1].range_mm = z[2];
  obs[1].bearing_rad = z[3];
  *pose = Eigen::Vector3d(p.x, p.y, heading_from_bearings_rad(p, obs, 0.0));
  return true;
}

}  // namespace

CircleCrossing intersect_circles(Vec2 c0, double r0_mm, Vec2 c1, double r1_mm,
                                 double tolerance_mm) {
  CircleCrossing out;
  const Vec2 dv = circles_sub(c1, c0);
  const double d = std::hypot(dv.x, dv.y);
  if (!(d > 0.0) || !(r0_mm >= 0.0) || !(r1_mm >= 0.0)) return out;
  // How far the circles miss each other: apart (d > r0 + r1) or one inside the other.
  const double miss = std::max(d - (r0_mm + r1_mm), std::abs(r0_mm - r1_mm) - d);
  if (miss > tolerance_mm) return out;
  const Vec2 e{dv.x / d, dv.y / d};
  const Vec2 n{-e.y, e.x};  // left of c0 -> c1
  // Foot of the common chord (the radical line) on the baseline.
  const double a = (r0_mm * r0_mm - r1_mm * r1_mm + d * d) / (2.0 * d);
  const Vec2 p2{c0.x + a * e.x, c0.y + a * e.y};
  const double h2 = r0_mm * r0_mm - a * a;
  if (miss >= 0.0 || !(h2 > 0.0)) {
    out.count = 1;
    out.touching = true;
    out.solutions[0] = out.solutions[1] = p2;
    return out;
  }
  const double h = std::sqrt(h2);
  out.count = 2;
  out.solutions[0] = {p2.x + h * n.x, p2.y + h * n.y};
  out.solutions[1] = {p2.x - h * n.x, p2.y - h * n.y};
  return out;
}

int choose_by_left_right(Vec2 l0, Vec2 l1, bool l0_left_of_l1, const CircleCrossing& crossing) {
  if (crossing.count != 2) return -1;
  const Vec2& s0 = crossing.solutions[0];
  const Vec2& s1 = crossing.solutions[1];
  if (l0.x != l1.x) {
    const bool smaller_x_is_left = (l0.x < l1.x) ? l0_left_of_l1 : !l0_left_of_l1;
    if (s0.y == s1.y) return -1;
    const int lower = s0.y < s1.y ? 0 : 1;
    return smaller_x_is_left ? lower : 1 - lower;
  }
  if (l0.y == l1.y || s0.x == s1.x) return -1;
  const bool larger_y_is_left = (l0.y > l1.y) ? l0_left_of_l1 : !l0_left_of_l1;
  const int left = s0.x < s1.x ? 0 : 1;
  return larger_y_is_left ? left : 1 - left;
}

int choose_by_bearing_difference(Vec2 l0, Vec2 l1, double bearing_difference_rad,
                                 double sigma_difference_rad, const CircleCrossing& crossing,
                                 double gate_sigma) {
  if (crossing.count == 1) return 0;
  if (crossing.count != 2) return -1;
  std::array<double, 2> err{};
  for (int i = 0; i < 2; ++i) {
    const double predicted = circles_subtended_rad(crossing.solutions[i], l0, l1);
    err[static_cast<std::size_t>(i)] = std::abs(wrap_angle_rad(bearing_difference_rad - predicted));
  }
  const int best = err[0] <= err[1] ? 0 : 1;
  const double other = err[static_cast<std::size_t>(1 - best)];
  return other > gate_sigma * sigma_difference_rad ? best : -1;
}

double heading_from_bearing_rad(Vec2 position_mm, Vec2 landmark_mm, double bearing_rad) {
  const double direction = std::atan2(landmark_mm.y - position_mm.y, landmark_mm.x - position_mm.x);
  return wrap_angle_rad(direction - bearing_rad);
}

double heading_from_bearings_rad(Vec2 position_mm, std::span<const Observation> obs,
                                 double position_sigma_mm) {
  double sx = 0.0, sy = 0.0;
  for (const Observation& o : obs) {
    const double h = heading_from_bearing_rad(position_mm, o.landmark_mm, o.bearing_rad);
    const double rho = std::hypot(o.landmark_mm.x - position_mm.x, o.landmark_mm.y - position_mm.y);
    const double across = rho > 0.0 ? position_sigma_mm / rho : 0.0;
    const double var = o.cov(1, 1) + across * across;
    const double w = var > 0.0 ? 1.0 / var : 1.0;
    sx += w * std::cos(h);
    sy += w * std::sin(h);
  }
  return std::atan2(sy, sx);
}

FixResult fix_two_circles(const Observation& o0, const Observation& o1, TwoLandmarkRule rule,
                          bool l0_left_of_l1, const FixOptions& opt) {
  FixResult out;
  out.dof = 1 + static_cast<int>(o0.has_face_yaw) + static_cast<int>(o1.has_face_yaw);
  const double sigma_sum = std::sqrt(std::max(0.0, o0.cov(0, 0) + o1.cov(0, 0)));
  const double tolerance = opt.intersection_gate_sigma * sigma_sum;
  const CircleCrossing c =
      intersect_circles(o0.landmark_mm, o0.range_mm, o1.landmark_mm, o1.range_mm, tolerance);
  if (c.count == 0) {
    out.status = FixStatus::kNoIntersection;
    return out;
  }
  out.touching = c.touching;
  int index = 0;
  if (rule == TwoLandmarkRule::kLeftRight) {
    index =
        c.count == 1 ? 0 : choose_by_left_right(o0.landmark_mm, o1.landmark_mm, l0_left_of_l1, c);
  } else {
    const double diff = wrap_angle_rad(o1.bearing_rad - o0.bearing_rad);
    const double sigma = std::sqrt(std::max(0.0, o0.cov(1, 1) + o1.cov(1, 1)));
    index = choose_by_bearing_difference(o0.landmark_mm, o1.landmark_mm, diff, sigma, c,
                                         opt.ambiguity_gate_sigma);
  }
  if (index < 0) {
    out.status = FixStatus::kAmbiguous;
    return out;
  }
  const double z[4] = {o0.range_mm, o0.bearing_rad, o1.range_mm, o1.bearing_rad};
  Eigen::Vector3d pose;
  circles_pose(o0, o1, z, index, tolerance, &pose);
  out.pose = {pose.x(), pose.y(), pose.z()};
  const Observation both[2] = {o0, o1};
  out.chi2 = fix_chi2(both, out.pose);
  const double crossing =
      std::abs(circles_subtended_rad({pose.x(), pose.y()}, o0.landmark_mm, o1.landmark_mm));
  if (c.touching || std::sin(crossing) < std::sin(opt.min_crossing_angle_rad)) {
    out.status = FixStatus::kShallowGeometry;
    return out;
  }
  // First-order covariance by central differences of the whole computation.
  Eigen::Matrix<double, 3, 4> J;
  Eigen::Matrix4d R = Eigen::Matrix4d::Zero();
  R.topLeftCorner<2, 2>() = o0.cov;
  R.bottomRightCorner<2, 2>() = o1.cov;
  for (int k = 0; k < 4; ++k) {
    const double step = (k % 2 == 0) ? 1e-6 * std::max(1.0, z[k]) : 1e-7;
    double zp[4] = {z[0], z[1], z[2], z[3]}, zm[4] = {z[0], z[1], z[2], z[3]};
    zp[k] += step;
    zm[k] -= step;
    Eigen::Vector3d fp, fm;
    if (!circles_pose(o0, o1, zp, index, tolerance, &fp) ||
        !circles_pose(o0, o1, zm, index, tolerance, &fm)) {
      out.status = FixStatus::kShallowGeometry;
      return out;
    }
    Eigen::Vector3d d = fp - fm;
    d.z() = wrap_angle_rad(d.z());
    J.col(k) = d / (2.0 * step);
  }
  out.cov = J * R * J.transpose();
  out.status = FixStatus::kOk;
  return out;
}

}  // namespace agv::ranging
