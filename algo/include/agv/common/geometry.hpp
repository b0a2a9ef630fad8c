// Planar geometry shared by every component. Conventions: docs/design/frames.md.
#pragma once

#include <cmath>

namespace agv {

inline constexpr double kPi = 3.14159265358979323846;

inline constexpr double deg_to_rad(double deg) { return deg * (kPi / 180.0); }
inline constexpr double rad_to_deg(double rad) { return rad * (180.0 / kPi); }

// Wraps to (-pi, pi]. Finite input only; NaN stays NaN.
inline double wrap_angle_rad(double a_rad) {
  if (a_rad > -kPi && a_rad <= kPi) return a_rad;
  double w = std::remainder(a_rad, 2.0 * kPi);  // [-pi, pi]
  if (w <= -kPi) w += 2.0 * kPi;
  return w;
}

// Wraps to (-180, 180].
inline double wrap_angle_deg(double a_deg) { return rad_to_deg(wrap_angle_rad(deg_to_rad(a_deg))); }

struct Vec2 {
  double x = 0.0;
  double y = 0.0;
};

// Pose of frame B expressed in frame A: B's origin at (x_mm, y_mm) in A, B's x axis rotated
// theta_rad counter-clockwise from A's x axis (seen from above).
struct Pose2 {
  double x_mm = 0.0;
  double y_mm = 0.0;
  double theta_rad = 0.0;
};

// A<-C = (A<-B) (+) (B<-C).
inline Pose2 compose(const Pose2& a_b, const Pose2& b_c) {
  const double c = std::cos(a_b.theta_rad), s = std::sin(a_b.theta_rad);
  return {a_b.x_mm + c * b_c.x_mm - s * b_c.y_mm, a_b.y_mm + s * b_c.x_mm + c * b_c.y_mm,
          wrap_angle_rad(a_b.theta_rad + b_c.theta_rad)};
}

// B<-A from A<-B.
inline Pose2 inverse(const Pose2& a_b) {
  const double c = std::cos(a_b.theta_rad), s = std::sin(a_b.theta_rad);
  return {-c * a_b.x_mm - s * a_b.y_mm, s * a_b.x_mm - c * a_b.y_mm,
          wrap_angle_rad(-a_b.theta_rad)};
}

// Point p given in frame B, expressed in frame A.
inline Vec2 transform(const Pose2& a_b, Vec2 p_b) {
  const double c = std::cos(a_b.theta_rad), s = std::sin(a_b.theta_rad);
  return {a_b.x_mm + c * p_b.x - s * p_b.y, a_b.y_mm + s * p_b.x + c * p_b.y};
}

}  // namespace agv
