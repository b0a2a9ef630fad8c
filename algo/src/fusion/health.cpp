// Ekf output and health: the estimate at a requested time, its status flags and health state
// (HealthConfig), the lost limits.
#include <Eigen/Eigenvalues>
#include <algorithm>
#include <cmath>
#include <utility>

#include "agv/fusion/ekf.hpp"

namespace agv::fusion {

const char* to_string(HealthState h) {
  switch (h) {
    case HealthState::kUninitialized:
      return "uninitialized";
    case HealthState::kLocalized:
      return "localized";
    case HealthState::kDeadReckoning:
      return "dead_reckoning";
    case HealthState::kLost:
      return "lost";
  }
  return "?";
}

std::uint16_t Ekf::take_flags() { return std::exchange(pending_flags_, std::uint16_t{0}); }

bool Ekf::prior_lost(const FilterCov& P, double* position_sigma_mm,
                     double* heading_sigma_rad) const {
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix2d> eig(P.topLeftCorner<2, 2>(),
                                                           Eigen::EigenvaluesOnly);
  const double ps = std::sqrt(std::max(0.0, eig.eigenvalues()(1)));
  const double hs = std::sqrt(std::max(0.0, P(kItheta, kItheta)));
  if (position_sigma_mm) *position_sigma_mm = ps;
  if (heading_sigma_rad) *heading_sigma_rad = hs;
  return !(ps <= config_.health.lost_position_sigma_mm) ||
         !(hs <= config_.health.lost_heading_sigma_rad);
}

PoseEstimate Ekf::estimate_at(std::int64_t t_ns) const {
  PoseEstimate e;
  e.t_ns = t_ns;
  e.flags = pending_flags_;
  const bool odom_timeout = !have_odom_ || t_ns - last_odom_t_ns_ > config_.health.odom_timeout_ns;
  if (odom_timeout) e.flags |= flags::kOdomTimeout;
  if (!initialised_) {
    e.health = HealthState::kUninitialized;
    return e;
  }
  const long k = find_last_at_or_before(t_ns);
  if (k < 0 || !at(static_cast<std::size_t>(k)).valid) {
    // Older than the kept history (or than the initialisation): no estimate.
    e.health = HealthState::kLost;
    return e;
  }
  const Event& base = at(static_cast<std::size_t>(k));
  FilterVec x = base.x;
  FilterCov P = base.P;
  predict_span(&x, &P, base.t_ns, t_ns, odom_time_after(base));
  P.topLeftCorner<2, 2>() += repeated_share_excess(P.topLeftCorner<2, 2>());
  e.valid = true;
  e.pose = {x(kIx), x(kIy), wrap_angle_rad(x(kItheta))};
  e.v_mps = x(kIv);
  e.omega_radps = x(kIomega);
  e.cov = P.topLeftCorner<5, 5>();
  e.odom_v_scale_error = x(kIsv);
  e.odom_omega_scale_error = x(kIsomega);
  e.odom_omega_bias_radps = x(kIbomega);
  e.odom_omega_per_v_radpm = x(kIcomegav);
  e.gyro_bias_radps = x(kIbg);
  e.gyro_scale_error = x(kIsg);
  e.gyro_heading = base.kind == EventKind::kOdom ? base.gyro : false;
  e.time_since_fix_ns = have_fix_ ? std::max<std::int64_t>(0, t_ns - last_fix_t_ns_) : -1;
  const bool cov_limit = prior_lost(P, &e.position_sigma_mm, &e.heading_sigma_rad);
  if (cov_limit) e.flags |= flags::kCovarianceLimit;
  if (odom_timeout || cov_limit) {
    e.health = HealthState::kLost;
  } else if (have_fix_ && e.time_since_fix_ns <= config_.health.localized_timeout_ns) {
    e.health = HealthState::kLocalized;
  } else {
    e.health = HealthState::kDeadReckoning;
  }
  // Reported only: health, gates and the state stay with the filter's own P (and the repeated
  // share's excess above).
  e.cov.topLeftCorner<3, 3>() += unconfirmed_slip_cov(t_ns, Eigen::Vector2d(x(kIx), x(kIy)));
  return e;
}

}  // namespace agv::fusion
