#include "agv/fusion/motion_model.hpp"

#include <cmath>

#include "agv/common/geometry.hpp"

namespace agv::fusion {

ArcCoefficients arc_coefficients(double a) {
  ArcCoefficients k;
  if (std::abs(a) < 1e-2) {
    // Taylor series; the first omitted terms are O(a^8) relative, < 1e-17 here.
    const double a2 = a * a, a4 = a2 * a2, a6 = a4 * a2;
    k.s = 1.0 - a2 / 6.0 + a4 / 120.0 - a6 / 5040.0;
    k.c = a * (0.5 - a2 / 24.0 + a4 / 720.0 - a6 / 40320.0);
    k.ds = a * (-1.0 / 3.0 + a2 / 30.0 - a4 / 840.0);
    k.dc = 0.5 - a2 / 8.0 + a4 / 144.0 - a6 / 5760.0;
  } else {
    const double sa = std::sin(a), ca = std::cos(a);
    k.s = sa / a;
    k.c = (1.0 - ca) / a;
    k.ds = (a * ca - sa) / (a * a);
    k.dc = (a * sa - (1.0 - ca)) / (a * a);
  }
  return k;
}

StateVec motion_predict(const StateVec& x, double dt_s) {
  const double th = x(kItheta), v = x(kIv), w = x(kIomega);
  const double d_mm = kMmPerM * v * dt_s;
  const double a = w * dt_s;
  const ArcCoefficients k = arc_coefficients(a);
  const double ct = std::cos(th), st = std::sin(th);
  StateVec out = x;
  out(kIx) += d_mm * (ct * k.s - st * k.c);
  out(kIy) += d_mm * (st * k.s + ct * k.c);
  out(kItheta) = wrap_angle_rad(th + a);
  return out;
}

StateCov motion_jacobian(const StateVec& x, double dt_s) {
  const double th = x(kItheta), v = x(kIv), w = x(kIomega);
  const double d_mm = kMmPerM * v * dt_s;
  const double a = w * dt_s;
  const ArcCoefficients k = arc_coefficients(a);
  const double ct = std::cos(th), st = std::sin(th);
  const double ux = ct * k.s - st * k.c;  // unit-distance displacement, world x
  const double uy = st * k.s + ct * k.c;
  StateCov F = StateCov::Identity();
  F(kIx, kItheta) = -d_mm * uy;
  F(kIy, kItheta) = d_mm * ux;
  F(kIx, kIv) = kMmPerM * dt_s * ux;
  F(kIy, kIv) = kMmPerM * dt_s * uy;
  F(kIx, kIomega) = d_mm * dt_s * (ct * k.ds - st * k.dc);
  F(kIy, kIomega) = d_mm * dt_s * (st * k.ds + ct * k.dc);
  F(kItheta, kIomega) = dt_s;
  return F;
}

}  // namespace agv::fusion
