// Motion model of the fusion EKF: state (x_mm, y_mm, theta_rad, v_mps, omega_radps), Yang et al.
// eq. 14 generalised to the exact constant-turn-rate arc. Conventions: docs/design/frames.md,
// docs/design/fusion.md.
#pragma once

#include <Eigen/Core>

namespace agv::fusion {

// State indices.
inline constexpr int kIx = 0;      // x_mm, world
inline constexpr int kIy = 1;      // y_mm, world
inline constexpr int kItheta = 2;  // theta_rad, wrapped to (-pi, pi]
inline constexpr int kIv = 3;      // v_mps, forward speed of the reference point
inline constexpr int kIomega = 4;  // omega_radps, yaw rate, counter-clockwise positive

using StateVec = Eigen::Matrix<double, 5, 1>;
using StateCov = Eigen::Matrix<double, 5, 5>;

// Millimetres per metre: v is in m/s (CAN and odom.csv units), positions in mm.
inline constexpr double kMmPerM = 1000.0;

// Arc coefficients for a heading change a = omega * dt:
//   s = sin(a)/a, c = (1 - cos(a))/a and their derivatives ds/da, dc/da.
// Below |a| = 1e-2 a Taylor series is used (error < 1e-17), so the model and its Jacobian are
// smooth through omega = 0 instead of dividing by zero or losing digits to cancellation.
struct ArcCoefficients {
  double s = 1.0;
  double c = 0.0;
  double ds = 0.0;
  double dc = 0.5;
};
ArcCoefficients arc_coefficients(double a);

// f(x, dt): exact motion along a circular arc at constant v and omega over dt_s (which may be
// 0). With d = 1000 v dt (mm) and a = omega dt:
//   x' = x + d (cos th s(a) - sin th c(a)),  y' = y + d (sin th s(a) + cos th c(a)),
//   th' = wrap(th + a),  v' = v,  omega' = omega.
// For a -> 0 this is eq. 14 of Yang et al. (x + v dt cos th, ...), which it reduces to.
StateVec motion_predict(const StateVec& x, double dt_s);

// F = df/dx at x (analytic, eq. 16).
StateCov motion_jacobian(const StateVec& x, double dt_s);

}  // namespace agv::fusion
