// An OK fix's first-order response to errors its least squares cannot see in one frame: those
// every frame repeats (the mount, the survey), a bearing offset common to all landmarks, and the
// lens's focal lengths common to all of them.
#include <Eigen/Dense>

#include "agv/ranging/fix.hpp"
#include "fix_internal.hpp"

namespace agv::ranging {

namespace fix_detail {

// The fix's gains: calls f(o, G) for each observation o that can be predicted at the fix, G the
// pose's first-order response to an error of o's own (range, bearing, face yaw); returns the
// pose's response to the common lens error (1 sigma per column), zero where the fix did not
// estimate it. A fix that did (FixResult::lens_estimated) takes its gains from the full state's
// normal equations, so a cov grown since (add_mount_yaw_uncertainty) does not enter them.
template <class F>
Eigen::Matrix<double, 3, 2> for_each_gain(std::span<const Observation> obs, const FixResult& fix,
                                          F f) {
  State x;
  x << fix.pose.x_mm, fix.pose.y_mm, fix.pose.theta_rad, fix.lens_error_sigma;
  Eigen::Matrix<double, 3, 5> P = Eigen::Matrix<double, 3, 5>::Zero();
  P.leftCols<3>() = fix.cov;
  Eigen::Matrix<double, 3, 2> lens_gain = Eigen::Matrix<double, 3, 2>::Zero();
  if (fix.lens_estimated) {
    Matrix5d H;
    State g;
    if (!normal_equations(obs, x, true, &H, &g)) return lens_gain;
    P = H.inverse().topRows<3>();
    lens_gain = -P.rightCols<2>();
  }
  for (const Observation& o : obs) {
    Linearised l;
    if (linearise(o, x, fix.lens_estimated, &l)) f(o, P * l.A.transpose() * l.W);
  }
  return lens_gain;
}

}  // namespace fix_detail

void add_mount_yaw_uncertainty(std::span<const Observation> obs, double sigma_common_rad,
                               FixResult* fix) {
  if (!(sigma_common_rad > 0.0)) return;
  // The response to an offset b on every bearing and face yaw: d(pose) = sum G 1_b.
  Eigen::Vector3d d = Eigen::Vector3d::Zero();
  fix_detail::for_each_gain(obs, *fix, [&](const Observation&, const Eigen::Matrix3d& G) {
    d += G * Eigen::Vector3d(0.0, 1.0, 1.0);
  });
  fix->cov += sigma_common_rad * sigma_common_rad * d * d.transpose();
}

Eigen::Matrix3d fix_systematic_cov(std::span<const Observation> obs, const FixResult& fix) {
  Eigen::Matrix3d out = Eigen::Matrix3d::Zero();
  if (fix.status != FixStatus::kOk) return out;
  const Eigen::Matrix<double, 3, 2> lens_gain =
      fix_detail::for_each_gain(obs, fix, [&](const Observation& o, const Eigen::Matrix3d& G) {
        Eigen::Matrix3d S = o.systematic_cov;
        // A fix that estimated the lens error holds it once, below, not per landmark.
        if (fix.lens_estimated) {
          Eigen::Matrix3d R;
          Eigen::Matrix<double, 3, 2> L;
          fix_detail::padded_cov_and_lens(o, &R, &L);
          S -= L * L.transpose();
        }
        out += G * S * G.transpose();
      });
  out += lens_gain * lens_gain.transpose();
  return 0.5 * (out + out.transpose());
}

Eigen::Matrix3d lens_cov_change(std::span<const Observation> obs, const FixResult& fix) {
  Eigen::Matrix3d out = Eigen::Matrix3d::Zero();
  if (fix.status != FixStatus::kOk || fix.lens_estimated) return out;
  Eigen::Matrix<double, 3, 2> common = Eigen::Matrix<double, 3, 2>::Zero();
  fix_detail::for_each_gain(obs, fix, [&](const Observation& o, const Eigen::Matrix3d& G) {
    // The fix's response to this landmark's share of the common error, per column.
    const Eigen::Matrix<double, 3, 2> g = G * o.lens_response;
    common += g;
    out -= g * g.transpose();
  });
  out += common * common.transpose();
  return 0.5 * (out + out.transpose());
}

}  // namespace agv::ranging
