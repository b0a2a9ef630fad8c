// Ekf aid: landmark fixes (the world pose of the vehicle at a frame's exposure). A fix is checked,
// held while it is ahead of the odometry, gated (chi-square, 3 dof) against the prior at its
// exposure and fused there, the newer events re-propagated. A gate-rejected fix goes to the
// recovery rules (recovery.cpp); the first valid fix initialises the filter.
#include <Eigen/Eigenvalues>
#include <algorithm>
#include <cmath>
#include <utility>

#include "agv/fusion/ekf.hpp"
#include "ekf_internal.hpp"

namespace agv::fusion {

const char* to_string(FixOutcome o) {
  switch (o) {
    case FixOutcome::kFused:
      return "fused";
    case FixOutcome::kInitialised:
      return "initialised";
    case FixOutcome::kRejectedGate:
      return "rejected_gate";
    case FixOutcome::kRejectedTooOld:
      return "rejected_too_old";
    case FixOutcome::kRejectedInvalid:
      return "rejected_invalid";
    case FixOutcome::kReinitialised:
      return "reinitialised";
    case FixOutcome::kHeld:
      return "held";
    case FixOutcome::kRejectedNotTracking:
      return "rejected_not_tracking";
  }
  return "?";
}

FixOutcome Ekf::add_fix(std::int64_t t_ns, const Pose2& z_world, const Eigen::Matrix3d& R_in,
                        bool map_verified, bool map_guided) {
  return fuse_fix(t_ns, z_world, R_in, map_verified, map_guided, /*from_hold=*/false);
}

FixOutcome Ekf::reject_fix_invalid() {
  ++counters_.fixes_rejected_invalid;
  pending_flags_ |= flags::kInvalidInput;
  return FixOutcome::kRejectedInvalid;
}

FixOutcome Ekf::reject_fix_too_old() {
  ++counters_.fixes_rejected_too_old;
  pending_flags_ |= flags::kRejectedTooOld;
  return FixOutcome::kRejectedTooOld;
}

FixOutcome Ekf::reject_fix_not_tracking() {
  ++counters_.fixes_rejected_not_tracking;
  return FixOutcome::kRejectedNotTracking;
}

Eigen::Matrix3d Ekf::effective_fix_cov(const Eigen::Matrix3d& R_in) const {
  const FixConfig& c = config_.fix;
  Eigen::Matrix3d R = c.cov_scale * R_in;
  R(0, 0) += c.floor_sigma_mm * c.floor_sigma_mm;
  R(1, 1) += c.floor_sigma_mm * c.floor_sigma_mm;
  R(2, 2) += c.floor_sigma_rad * c.floor_sigma_rad;
  return R;
}

FixOutcome Ekf::fuse_fix(std::int64_t t_ns, const Pose2& z_world, const Eigen::Matrix3d& R_in,
                         bool map_verified, bool map_guided, bool from_hold) {
  // ---- Input validation: never let a bad fix touch the state ----
  if (!std::isfinite(z_world.x_mm) || !std::isfinite(z_world.y_mm) ||
      !std::isfinite(z_world.theta_rad) || !R_in.allFinite())
    return reject_fix_invalid();
  const double scale = R_in.cwiseAbs().maxCoeff();
  if (!((R_in - R_in.transpose()).cwiseAbs().maxCoeff() <= 1e-9 * scale))
    return reject_fix_invalid();
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig(R_in, Eigen::EigenvaluesOnly);
  if (eig.info() != Eigen::Success || !(eig.eigenvalues()(0) > 0.0)) return reject_fix_invalid();

  std::int64_t newest_t = 0;
  const bool have_newest = newest_time(&newest_t);
  if (!from_hold && have_odom_ && t_ns > last_odom_t_ns_ + config_.fix.max_lead_ns) {
    hold_fix(t_ns, z_world, R_in, map_verified, map_guided);
    return FixOutcome::kHeld;
  }
  const Eigen::Matrix3d R = effective_fix_cov(R_in);
  const Eigen::Vector3d z(z_world.x_mm, z_world.y_mm, wrap_angle_rad(z_world.theta_rad));

  // ---- Too old? ----
  if (have_newest && newest_t - t_ns > config_.fix.max_delay_ns) return reject_fix_too_old();
  if (initialised_ && t_ns < t_init_ns_) return reject_fix_too_old();
  const long k = find_last_at_or_before(t_ns);
  if (map_guided && !initialised_) return reject_fix_not_tracking();
  if (!initialised_) return initialise_from_fix(k, t_ns, z, R);
  if (k < 0 || !at(static_cast<std::size_t>(k)).valid) return reject_fix_too_old();

  // ---- Prior at the exposure time, gate ----
  FixPrior prior;
  prior.base = static_cast<std::size_t>(k);
  const Event& base = at(prior.base);
  prior.x = base.x;
  prior.P = base.P;
  predict_span(&prior.x, &prior.P, base.t_ns, t_ns, odom_time_after(base));
  // What the rack landmarks' repeated errors may have moved the state by: a floor fix is
  // independent of them, weighed and gated against it, and clears it once fused.
  prior.P.topLeftCorner<2, 2>() += repeated_share_excess(prior.P.topLeftCorner<2, 2>());
  const FixOutcome gated = gate_fix(t_ns, z, R, R_in, map_verified, map_guided, &prior);
  if (gated != FixOutcome::kFused) return gated;
  return fuse_gated_fix(t_ns, z, R, &prior);
}

FixOutcome Ekf::initialise_from_fix(long k, std::int64_t t_ns, const Eigen::Vector3d& z,
                                    const Eigen::Matrix3d& R) {
  if (k < 0 && size_ == history_.size()) return reject_fix_too_old();  // older than all inputs
  FilterVec x = FilterVec::Zero();
  x.head<3>() = z;
  // Speed from the newest odometry at or before the fix, if any.
  for (long i = k; i >= 0; --i) {
    const Event& ev = at(static_cast<std::size_t>(i));
    if (ev.kind == EventKind::kOdom) {
      x(kIv) = ev.v_mps;
      x(kIomega) = ev.omega_radps;
      break;
    }
  }
  const OdometryConfig& o = config_.odometry;
  FilterCov P = FilterCov::Zero();
  P.topLeftCorner<3, 3>() = R;
  P(kIv, kIv) = config_.fix.init_v_sigma_mps * config_.fix.init_v_sigma_mps;
  if (o.estimate_calibration) {
    P(kIsv, kIsv) = o.init_v_scale_sigma * o.init_v_scale_sigma;
    P(kIsomega, kIsomega) = o.init_omega_scale_sigma * o.init_omega_scale_sigma;
    P(kIbomega, kIbomega) = o.init_omega_bias_sigma_radps * o.init_omega_bias_sigma_radps;
    P(kIcomegav, kIcomegav) = o.init_omega_per_v_sigma_radpm * o.init_omega_per_v_sigma_radpm;
  }
  P(kIomega, kIomega) = config_.fix.init_omega_sigma_radps * config_.fix.init_omega_sigma_radps;
  P(kIbg, kIbg) = config_.gyro.init_bias_sigma_radps * config_.gyro.init_bias_sigma_radps;
  P(kIsg, kIsg) = config_.gyro.init_scale_sigma * config_.gyro.init_scale_sigma;
  initialise_at(t_ns, x, P);
  ++counters_.fixes_initialised;
  pending_flags_ |= flags::kInitialised;
  return FixOutcome::kInitialised;
}

FixOutcome Ekf::reject_fix_gate(std::int64_t t_ns, const Eigen::Vector3d& z,
                                const Eigen::Matrix3d& R, const FixPrior& prior, bool map_guided,
                                bool worthless_prior) {
  ++counters_.fixes_rejected_gate;
  pending_flags_ |= flags::kRejectedGate;
  if (!map_guided && kidnap_candidate(t_ns, z, R, prior.x, prior.P, worthless_prior))
    return FixOutcome::kReinitialised;
  return FixOutcome::kRejectedGate;
}

FixOutcome Ekf::gate_fix(std::int64_t t_ns, const Eigen::Vector3d& z, const Eigen::Matrix3d& R,
                         const Eigen::Matrix3d& R_in, bool map_verified, bool map_guided,
                         FixPrior* prior) {
  const double d2 = mahalanobis_sq(prior->x, prior->P, z, R);
  last_fix_d2_ = d2;
  prior->lost = prior_lost(prior->P, &prior->position_sigma_mm);
  // A prior whose position spans landmarks (4x the lost limit) gates nothing: any fix passes.
  // Only a fix that vouches for itself (a QR payload the map confirmed) may then be fused alone;
  // others (a tag, whose map entry is its only truth; a payload without a map) need a second,
  // agreeing fix of another landmark, and a map-guided fix cannot be chosen at all.
  const bool worthless = prior->position_sigma_mm > 4.0 * config_.health.lost_position_sigma_mm;
  if (worthless && map_guided) return reject_fix_not_tracking();
  if (worthless && !map_verified) return reject_fix_gate(t_ns, z, R, *prior, map_guided, true);
  // A fix that agrees with the prior is fused, lost or not: fusing keeps the correlations that
  // teach the odometry and gyro calibration, a re-initialisation would drop them. A map-guided
  // fix needs only that (its identity was chosen by the covariance, docs/design/map_identity.md).
  if (d2 <= gate_threshold_) return FixOutcome::kFused;
  if (map_guided && prior->lost) return reject_fix_not_tracking();
  const RecoveryConfig& rc = config_.recovery;
  const bool precise = std::sqrt(R_in.topLeftCorner<2, 2>().diagonal().maxCoeff()) <=
                           rc.relocalize_max_fix_sigma_mm &&
                       std::sqrt(R_in(2, 2)) <= rc.relocalize_max_fix_sigma_rad;
  if (rc.relocalize_from_single_fix && !map_guided && prior->lost && precise) {
    // Re-localisation from one fix: it must still agree with what is known of the position
    // (a heading-only loss keeps a good position prior), unless the position is unknown too;
    // then only a fix that vouches for itself (a QR payload the map confirmed) may do it.
    const bool position_agrees =
        position_mahalanobis_sq(prior->x, prior->P, z, R) <= gate_threshold_2d_;
    const bool position_unknown = prior->position_sigma_mm > config_.health.lost_position_sigma_mm;
    if (position_agrees || (position_unknown && map_verified)) {
      relocalize(t_ns, z, R, prior->x, prior->P);
      return FixOutcome::kReinitialised;
    }
  }
  // A slip the wheels did not show explains the whole innovation: fused with that turn's
  // uncertainty added, so the calibration learnt so far is kept.
  FilterCov P_slip = prior->P;
  if (!(map_verified && !map_guided && precise &&
        explain_unseen_slip(t_ns, z, R, prior->x, &P_slip) &&
        mahalanobis_sq(prior->x, P_slip, z, R) <= gate_threshold_))
    return reject_fix_gate(t_ns, z, R, *prior, map_guided, worthless);
  prior->P = P_slip;
  ++counters_.unseen_slips;
  pending_flags_ |= flags::kWheelSlip;
  return FixOutcome::kFused;
}

FixOutcome Ekf::fuse_gated_fix(std::int64_t t_ns, const Eigen::Vector3d& z,
                               const Eigen::Matrix3d& R, FixPrior* prior) {
  hyp_.count = 0;
  update_fix(&prior->x, &prior->P, z, R);
  const Event& base = at(prior->base);
  Event ev;
  ev.t_ns = t_ns;
  ev.kind = EventKind::kFix;
  ev.z = z;
  ev.R = R;
  ev.valid = true;
  ev.x = prior->x;
  ev.P = prior->P;
  ev.odom_t_ns = odom_time_after(base);
  ev.slip = SlipState::after_measurement(base.slip);
  bool delayed = false;
  const std::size_t i = insert_measurement(ev, &delayed);
  track_restart(i);
  rb_repeated_floor_.setZero();
  ++counters_.fixes_fused;
  pending_flags_ |= flags::kFusedFix;
  if (delayed) {
    ++counters_.fixes_delayed;
    pending_flags_ |= flags::kDelayedFix;
  }
  have_fix_ = true;
  last_fix_t_ns_ = std::max(last_fix_t_ns_, t_ns);
  return FixOutcome::kFused;
}

// ---------------------------------------------------------------------------------------------
// Fixes ahead of the odometry

void Ekf::hold_fix(std::int64_t t_ns, const Pose2& z_world, const Eigen::Matrix3d& R_in,
                   bool map_verified, bool map_guided) {
  if (held_count_ == held_.size()) {  // the newest fixes are worth more: drop the oldest
    std::move(held_.begin() + 1, held_.begin() + static_cast<long>(held_count_), held_.begin());
    --held_count_;
    ++counters_.fixes_held_dropped;
  }
  std::size_t i = held_count_++;
  held_[i] = HeldFix{t_ns, z_world, R_in, map_verified, map_guided};
  while (i > 0 && held_[i - 1].t_ns > held_[i].t_ns) {
    std::swap(held_[i - 1], held_[i]);
    --i;
  }
  ++counters_.fixes_held;
}

void Ekf::release_held_before(std::int64_t t_ns) {
  std::size_t n = 0;
  while (n < held_count_ && held_[n].t_ns < t_ns) {
    const HeldFix h = held_[n++];
    fuse_fix(h.t_ns, h.z, h.R, h.map_verified, h.map_guided, /*from_hold=*/true);
  }
  std::move(held_.begin() + static_cast<long>(n), held_.begin() + static_cast<long>(held_count_),
            held_.begin());
  held_count_ -= n;
}

void Ekf::settle_held_after(std::int64_t t_ns) {
  // Odometry flows again: what is still further ahead than max_lead_ns comes from a camera
  // clock that runs ahead, not from late odometry.
  const std::size_t n = held_count_;
  held_count_ = 0;
  for (std::size_t i = 0; i < n; ++i) {
    const HeldFix h = held_[i];
    if (h.t_ns > t_ns + config_.fix.max_lead_ns) {
      ++counters_.fixes_rejected_invalid;
      pending_flags_ |= flags::kInvalidInput;
    } else {
      fuse_fix(h.t_ns, h.z, h.R, h.map_verified, h.map_guided, /*from_hold=*/false);
    }
  }
}

// ---------------------------------------------------------------------------------------------
// Measurement model: h(x) = (x, y, theta), H = [I3 0] (eq. 17-19); innovation angle wrapped.

namespace {

detail::MeasRow<3> fix_jacobian() {
  detail::MeasRow<3> H = detail::MeasRow<3>::Zero();
  H.leftCols<3>() = Eigen::Matrix3d::Identity();
  return H;
}

Eigen::Vector3d fix_innovation(const FilterVec& x, const Eigen::Vector3d& z) {
  Eigen::Vector3d nu = z - x.head<3>();
  nu(2) = wrap_angle_rad(nu(2));
  return nu;
}

}  // namespace

void Ekf::update_fix(FilterVec* x, FilterCov* P, const Eigen::Vector3d& z,
                     const Eigen::Matrix3d& R) const {
  detail::joseph_update<3>(x, P, fix_jacobian(), fix_innovation(*x, z), R);
  (*x)(kItheta) = wrap_angle_rad((*x)(kItheta));
}

double Ekf::mahalanobis_sq(const FilterVec& x, const FilterCov& P, const Eigen::Vector3d& z,
                           const Eigen::Matrix3d& R) const {
  return detail::mahalanobis_sq<3>(P, fix_jacobian(), fix_innovation(x, z), R);
}

double Ekf::position_mahalanobis_sq(const FilterVec& x, const FilterCov& P,
                                    const Eigen::Vector3d& z, const Eigen::Matrix3d& R) const {
  const Eigen::Matrix2d S = P.topLeftCorner<2, 2>() + R.topLeftCorner<2, 2>();
  const Eigen::Vector2d nu = z.head<2>() - x.head<2>();
  const Eigen::LLT<Eigen::Matrix2d> llt(S);
  if (llt.info() != Eigen::Success) return std::numeric_limits<double>::infinity();
  return nu.dot(llt.solve(nu));
}

}  // namespace agv::fusion
