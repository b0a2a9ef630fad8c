// The per-vehicle filter's mathematics: prediction, process noise, gate and Joseph update.
#include "tracker_model.hpp"

#include <Eigen/Cholesky>
#include <algorithm>
#include <cmath>

#include "agv/common/geometry.hpp"

namespace agv::overhead::tracker_detail {

namespace {

// sin(a)/a and its derivative, by series where the quotient loses its digits.
double sinc(double a) { return std::abs(a) < 1e-4 ? 1.0 - a * a / 6.0 : std::sin(a) / a; }
double sinc_derivative(double a) {
  return std::abs(a) < 1e-4 ? -a / 3.0 : (a * std::cos(a) - std::sin(a)) / (a * a);
}

// The accelerations enter the state through the linearised continuous motion: a speed change
// ramps the position along the heading, a turn-rate change ramps the heading, which bends the
// position. g_a(s) = a1 s + a0 and g_alpha(s) = b2 s^2 + b1 s + b0 after s seconds; the
// covariance is the integral of q g g^T over the step.
Mat5 process_noise(const Vec5& x, double dt_s, const ProcessNoise& q) {
  const double t = std::abs(dt_s);
  const double c = std::cos(x(2)), s = std::sin(x(2)), v = x(3);
  Vec5 a1, a0, b2, b1, b0;
  a1 << c, s, 0, 0, 0;
  a0 << 0, 0, 0, 1, 0;
  b2 << -0.5 * v * s, 0.5 * v * c, 0, 0, 0;
  b1 << 0, 0, 1, 0, 0;
  b0 << 0, 0, 0, 0, 1;
  const double t2 = t * t, t3 = t2 * t, t4 = t3 * t, t5 = t4 * t;
  const Mat5 qa = a1 * a1.transpose() * (t3 / 3.0) +
                  (a1 * a0.transpose() + a0 * a1.transpose()) * (t2 / 2.0) +
                  a0 * a0.transpose() * t;
  const Mat5 qw =
      b2 * b2.transpose() * (t5 / 5.0) + (b2 * b1.transpose() + b1 * b2.transpose()) * (t4 / 4.0) +
      (b2 * b0.transpose() + b0 * b2.transpose() + b1 * b1.transpose()) * (t3 / 3.0) +
      (b1 * b0.transpose() + b0 * b1.transpose()) * (t2 / 2.0) + b0 * b0.transpose() * t;
  return q.accel * qa + q.alpha * qw;
}

}  // namespace

Belief predict(const Belief& b, double dt_s, const ProcessNoise& q) {
  if (dt_s == 0.0) return b;
  const Vec5& x = b.x;
  const double half = 0.5 * x(4) * dt_s;
  const double phi = x(2) + half;
  const double cp = std::cos(phi), sp = std::sin(phi);
  const double sc = sinc(half), dsc = sinc_derivative(half);
  const double chord = x(3) * dt_s * sc;  // the arc's chord, along the mid-step heading
  Belief out;
  out.x << x(0) + chord * cp, x(1) + chord * sp, wrap_angle_rad(x(2) + x(4) * dt_s), x(3), x(4);
  Mat5 f = Mat5::Identity();
  f(0, 2) = -chord * sp;
  f(1, 2) = chord * cp;
  f(0, 3) = dt_s * sc * cp;
  f(1, 3) = dt_s * sc * sp;
  // d chord / d omega = v dt dsc dt/2; d phi / d omega = dt/2.
  const double dchord = x(3) * dt_s * dsc * 0.5 * dt_s;
  f(0, 4) = dchord * cp - chord * sp * 0.5 * dt_s;
  f(1, 4) = dchord * sp + chord * cp * 0.5 * dt_s;
  f(2, 4) = dt_s;
  out.p = f * b.p * f.transpose() + process_noise(x, dt_s, q);
  out.p = 0.5 * (out.p + out.p.transpose()).eval();
  return out;
}

bool make_measurement(const TagFix& fix, Measurement* out) {
  if (!std::isfinite(fix.pose.x_mm) || !std::isfinite(fix.pose.y_mm) ||
      !std::isfinite(fix.pose.theta_rad)) {
    return false;
  }
  Mat3 m;
  for (int i = 0; i < 3; ++i) {
    for (int j = 0; j < 3; ++j) {
      const double e = fix.cov[static_cast<std::size_t>(3 * i + j)];
      if (!std::isfinite(e)) return false;
      m(i, j) = e;
    }
  }
  for (int i = 0; i < 3; ++i) {
    if (!(m(i, i) > 0.0)) return false;
    for (int j = 0; j < i; ++j) {
      const double scale = std::sqrt(m(i, i) * m(j, j));
      if (std::abs(m(i, j) - m(j, i)) > 1e-6 * scale) return false;
    }
  }
  m = 0.5 * (m + m.transpose()).eval();
  const Eigen::LLT<Mat3> llt(m);
  if (llt.info() != Eigen::Success) return false;
  out->z << fix.pose.x_mm, fix.pose.y_mm, wrap_angle_rad(fix.pose.theta_rad);
  out->source = fix.source;
  out->r = m;
  out->bias.setZero();
  Mat3 c;
  for (int i = 0; i < 3; ++i) {
    for (int j = 0; j < 3; ++j) c(i, j) = fix.cov_camera[static_cast<std::size_t>(3 * i + j)];
  }
  if (!c.allFinite() || c.isZero(0.0)) return true;
  c = 0.5 * (c + c.transpose()).eval();
  const Mat3 noise = m - c;
  if (Eigen::LLT<Mat3>(noise).info() != Eigen::Success || !(c.diagonal().minCoeff() >= 0.0)) {
    return true;
  }
  out->r = noise;
  out->bias = c;
  return true;
}

namespace {

Vec3 innovation(const Belief& b, const Measurement& m) {
  return {m.z(0) - b.x(0), m.z(1) - b.x(1), wrap_angle_rad(m.z(2) - b.x(2))};
}

}  // namespace

double distance2(const Belief& b, const Mat3& track_bias, const Measurement& m) {
  const Mat3 s = b.p.topLeftCorner<3, 3>() + track_bias + m.r + m.bias;
  const Eigen::LLT<Mat3> llt(s);
  const Vec3 y = innovation(b, m);
  return y.dot(llt.solve(y));
}

double heading_distance2(const Belief& b, const Mat3& track_bias, const Measurement& m) {
  const double s = b.p(2, 2) + track_bias(2, 2) + m.r(2, 2) + m.bias(2, 2);
  const double y = wrap_angle_rad(m.z(2) - b.x(2));
  return y * y / s;
}

Belief update(const Belief& b, const Measurement& m, const Measurement& prior_fix) {
  if (m.source < 0 || prior_fix.source < 0 || m.source == prior_fix.source) return update(b, m);
  Measurement across = m;
  across.r += m.bias + prior_fix.bias;
  return update(b, across);
}

Belief update(const Belief& b, const Measurement& m) {
  const Mat3 s = b.p.topLeftCorner<3, 3>() + m.r;
  const Eigen::LLT<Mat3> llt(s);
  // K = P H^T S^-1 with H = [I 0]; P symmetric, so K^T = S^-1 (H P).
  const Eigen::Matrix<double, 5, 3> k = llt.solve(b.p.topRows<3>()).transpose();
  Belief out;
  out.x = b.x + k * innovation(b, m);
  out.x(2) = wrap_angle_rad(out.x(2));
  Mat5 ikh = Mat5::Identity();
  ikh.leftCols<3>() -= k;
  out.p = ikh * b.p * ikh.transpose() + k * m.r * k.transpose();
  out.p = 0.5 * (out.p + out.p.transpose()).eval();
  return out;
}

Belief start(const Measurement& m, double speed_sigma_mmps, double turn_sigma_radps) {
  Belief b;
  b.x << m.z(0), m.z(1), m.z(2), 0.0, 0.0;
  b.p.topLeftCorner<3, 3>() = m.r;
  b.p(3, 3) = speed_sigma_mmps * speed_sigma_mmps;
  b.p(4, 4) = turn_sigma_radps * turn_sigma_radps;
  return b;
}

double position_sigma_mm(const Mat5& p) {
  // Larger eigenvalue of a symmetric 2 x 2 matrix, in closed form.
  const double a = p(0, 0), d = p(1, 1), c = 0.5 * (p(0, 1) + p(1, 0));
  const double mean = 0.5 * (a + d);
  const double dev = std::sqrt(0.25 * (a - d) * (a - d) + c * c);
  return std::sqrt(std::max(0.0, mean + dev));
}

}  // namespace agv::overhead::tracker_detail
