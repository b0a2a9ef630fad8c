// Ekf configuration, inputs (odometry, fixes held until odometry covers them, gating and kidnap
// policy) and output. The filter steps and the event history: ekf_steps.cpp.
#include "agv/fusion/ekf.hpp"

#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>
#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <utility>

#include "agv/fusion/chi2.hpp"

namespace agv::fusion {

namespace {

bool finite_nonneg(double v) { return std::isfinite(v) && v >= 0.0; }
bool finite_pos(double v) { return std::isfinite(v) && v > 0.0; }

}  // namespace

std::string validate(const EkfConfig& c) {
  if (!finite_nonneg(c.accel_sigma_mps2) || !finite_nonneg(c.yaw_accel_sigma_radps2))
    return "accel_sigma_mps2 and yaw_accel_sigma_radps2 must be finite and >= 0";
  if (!finite_nonneg(c.along_track_sigma_mm_per_sqrt_m) ||
      !finite_nonneg(c.cross_track_sigma_mm_per_sqrt_m) ||
      !finite_nonneg(c.heading_sigma_rad_per_sqrt_m) ||
      !finite_nonneg(c.heading_drift_sigma_rad_per_sqrt_s) ||
      !finite_nonneg(c.turn_heading_sigma_rad_per_sqrt_rad))
    return "process noise densities must be finite and >= 0";
  if (!finite_pos(c.odom_v_sigma_mps) || !finite_pos(c.odom_omega_sigma_radps))
    return "odom_v_sigma_mps and odom_omega_sigma_radps must be finite and > 0";
  if (!finite_pos(c.max_abs_v_mps) || !finite_pos(c.max_abs_omega_radps))
    return "max_abs_v_mps and max_abs_omega_radps must be finite and > 0";
  if (!finite_pos(c.fix_cov_scale)) return "fix_cov_scale must be finite and > 0";
  if (!finite_nonneg(c.fix_floor_sigma_mm) || !finite_nonneg(c.fix_floor_sigma_rad))
    return "fix floor sigmas must be finite and >= 0";
  if (!(c.gate_probability > 0.0 && c.gate_probability < 1.0))
    return "gate_probability must be in (0, 1)";
  if (c.kidnap_fixes < 2) return "kidnap_fixes must be >= 2";
  if (!finite_nonneg(c.kidnap_min_separation_mm) || c.kidnap_min_duration_ns < 0)
    return "kidnap_min_separation_mm and kidnap_min_duration_ns must be finite and >= 0";
  if (!finite_nonneg(c.init_v_scale_sigma) || !finite_nonneg(c.init_omega_scale_sigma) ||
      !finite_nonneg(c.init_omega_bias_sigma_radps) || !finite_nonneg(c.v_scale_sigma_per_sqrt_s) ||
      !finite_nonneg(c.omega_scale_sigma_per_sqrt_s) ||
      !finite_nonneg(c.omega_bias_sigma_radps_per_sqrt_s) ||
      !finite_nonneg(c.init_omega_per_v_sigma_radpm) ||
      !finite_nonneg(c.omega_per_v_sigma_radpm_per_sqrt_s))
    return "odometry calibration sigmas must be finite and >= 0";
  if (!finite_pos(c.init_v_sigma_mps) || !finite_pos(c.init_omega_sigma_radps))
    return "init sigmas must be finite and > 0";
  if (c.history_capacity < 8) return "history_capacity must be >= 8";
  if (c.held_fix_capacity < 1) return "held_fix_capacity must be >= 1";
  if (c.odom_period_ns <= 0 || c.odom_gap_ns < c.odom_period_ns)
    return "odom_period_ns must be > 0 and odom_gap_ns >= odom_period_ns";
  if (!finite_nonneg(c.gap_accel_sigma_mps2) || !finite_nonneg(c.gap_yaw_accel_sigma_radps2) ||
      !finite_nonneg(c.gap_yaw_rate_change_sigma_radps))
    return "gap sigmas must be finite and >= 0";
  if (!finite_pos(c.relocalize_max_fix_sigma_mm) || !finite_pos(c.relocalize_max_fix_sigma_rad))
    return "relocalize_max_fix sigmas must be finite and > 0";
  if (c.max_fix_delay_ns <= 0 || c.max_fix_lead_ns < 0)
    return "max_fix_delay_ns must be > 0 and max_fix_lead_ns >= 0";
  if (c.localized_timeout_ns <= 0 || c.odom_timeout_ns <= 0)
    return "localized_timeout_ns and odom_timeout_ns must be > 0";
  if (!finite_pos(c.lost_position_sigma_mm) || !finite_pos(c.lost_heading_sigma_rad))
    return "lost sigma limits must be finite and > 0";
  if (!finite_pos(c.gyro_noise_density_radps_per_sqrt_hz) ||
      !finite_nonneg(c.init_gyro_bias_sigma_radps) ||
      !finite_nonneg(c.gyro_bias_sigma_radps_per_sqrt_s) ||
      !finite_nonneg(c.init_gyro_scale_sigma) || !finite_nonneg(c.gyro_scale_sigma_per_sqrt_s))
    return "gyro noise density must be finite and > 0, gyro calibration sigmas finite and >= 0";
  if (!finite_pos(c.gyro_saturation_radps)) return "gyro_saturation_radps must be finite and > 0";
  if (c.gyro_gap_ns <= 0 || c.gyro_capacity < 8)
    return "gyro_gap_ns must be > 0 and gyro_capacity >= 8";
  if (!finite_nonneg(c.slip_yaw_rate_radps) || !finite_nonneg(c.slip_yaw_rate_fraction) ||
      !finite_pos(c.wheel_track_mm) || c.slip_max_duration_ns < 0 ||
      !finite_pos(c.slip_noise_sigmas) || !finite_nonneg(c.max_accel_mps2) ||
      !finite_pos(c.wheel_step_min_mps) || !finite_nonneg(c.slip_hold_sigma_fraction))
    return "slip limits and max_accel_mps2 must be finite and >= 0, wheel_track_mm, "
           "slip_noise_sigmas and wheel_step_min_mps > 0";
  if (!finite_nonneg(c.standstill_v_mps) || !finite_nonneg(c.standstill_omega_radps) ||
      !finite_pos(c.standstill_omega_sigma_radps))
    return "standstill limits must be finite and >= 0, standstill_omega_sigma_radps > 0";
  return {};
}

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

Ekf::Ekf(const EkfConfig& config)
    : config_(config), last_fix_d2_(std::numeric_limits<double>::quiet_NaN()) {
  const std::string err = validate(config_);
  if (!err.empty()) throw std::invalid_argument("EkfConfig: " + err);
  gate_threshold_ = chi2_3dof_quantile(config_.gate_probability);
  gate_threshold_2d_ = -2.0 * std::log1p(-config_.gate_probability);  // chi-square, 2 dof
  history_.resize(config_.history_capacity);  // the only allocations; never resized later
  held_.resize(config_.held_fix_capacity);
  gyro_.resize(config_.gyro_capacity);
}

std::uint16_t Ekf::take_flags() { return std::exchange(pending_flags_, std::uint16_t{0}); }

// ---------------------------------------------------------------------------------------------
// Inputs

bool Ekf::add_odometry(std::int64_t t_ns, double v_mps, double omega_radps) {
  if (!std::isfinite(v_mps) || !std::isfinite(omega_radps) ||
      std::abs(v_mps) > config_.max_abs_v_mps ||
      std::abs(omega_radps) > config_.max_abs_omega_radps) {
    ++counters_.odom_rejected_invalid;
    pending_flags_ |= flags::kInvalidInput;
    return false;
  }
  if (have_odom_ && t_ns <= last_odom_t_ns_) {
    ++counters_.odom_rejected_time;
    pending_flags_ |= flags::kInvalidInput;
    return false;
  }
  release_held_before(t_ns);
  if (have_odom_ && is_gap(last_odom_t_ns_, t_ns)) {
    ++counters_.odom_gaps;
    pending_flags_ |= flags::kOdomGap;
  }
  Event ev;
  ev.t_ns = t_ns;
  ev.kind = EventKind::kOdom;
  ev.v_mps = v_mps;
  ev.omega_radps = omega_radps;
  const std::size_t i = insert_event(ev);
  replay_from(i);
  counters_.events_replayed += size_ - i - 1;
  have_odom_ = true;
  last_odom_t_ns_ = t_ns;
  if (at(i).valid) {
    ++counters_.odom_fused;
    pending_flags_ |= flags::kFusedOdom;
    if (at(i).slip) pending_flags_ |= flags::kWheelSlip;
  } else {
    ++counters_.odom_stored_uninitialised;
  }
  track_odometry();
  settle_held_after(t_ns);
  return true;
}

bool Ekf::add_gyro(std::int64_t t_ns, double gyro_z_radps) {
  if (!std::isfinite(gyro_z_radps)) {
    ++counters_.gyro_rejected_invalid;
    pending_flags_ |= flags::kGyroInvalid;
    return false;
  }
  const bool have_prev = gyro_size_ > 0;
  const std::int64_t prev_t = have_prev ? gyro_at(gyro_size_ - 1).t_ns : INT64_MIN;
  if (have_prev && t_ns <= prev_t) {
    ++counters_.gyro_rejected_time;
    pending_flags_ |= flags::kGyroInvalid;
    return false;
  }
  const bool saturated = std::abs(gyro_z_radps) >= config_.gyro_saturation_radps;
  if (gyro_size_ == gyro_.size()) {  // drop the oldest
    gyro_head_ = (gyro_head_ + 1) % gyro_.size();
    --gyro_size_;
  }
  gyro_[(gyro_head_ + gyro_size_) % gyro_.size()] =
      GyroSample{t_ns, saturated ? std::numeric_limits<double>::quiet_NaN() : gyro_z_radps};
  ++gyro_size_;
  // Odometry periods ending after the previous sample were processed without this one (or with
  // the wheels): re-propagate them now that the gyro covers more.
  if (size_ > 0) {
    const long k = have_prev ? find_last_at_or_before(prev_t) : -1;
    const std::size_t from = static_cast<std::size_t>(k + 1);
    if (from < size_ && at(from).t_ns <= t_ns) {
      replay_from(from);
      counters_.events_replayed += size_ - from;
    }
  }
  if (saturated) {
    ++counters_.gyro_rejected_saturated;
    pending_flags_ |= flags::kGyroInvalid;
    return false;
  }
  ++counters_.gyro_accepted;
  return true;
}

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
  // Odometry flows again: what is still further ahead than max_fix_lead_ns comes from a camera
  // clock that runs ahead, not from late odometry.
  const std::size_t n = held_count_;
  held_count_ = 0;
  for (std::size_t i = 0; i < n; ++i) {
    const HeldFix h = held_[i];
    if (h.t_ns > t_ns + config_.max_fix_lead_ns) {
      ++counters_.fixes_rejected_invalid;
      pending_flags_ |= flags::kInvalidInput;
    } else {
      fuse_fix(h.t_ns, h.z, h.R, h.map_verified, h.map_guided, /*from_hold=*/false);
    }
  }
}

void Ekf::initialise_at(std::int64_t t_ns, const FilterVec& x, const FilterCov& P) {
  Event ev;
  ev.t_ns = t_ns;
  ev.kind = EventKind::kInit;
  ev.valid = true;
  ev.x = x;
  ev.x(kItheta) = wrap_angle_rad(ev.x(kItheta));
  ev.P = P;
  const std::size_t i = insert_event(ev);
  at(i).odom_t_ns = odom_time_before(i);
  replay_from(i + 1);
  counters_.events_replayed += size_ - i - 1;
  initialised_ = true;
  track_restart(i);
  t_init_ns_ = t_ns;
  have_fix_ = true;
  last_fix_t_ns_ = t_ns;
  hyp_.count = 0;
}

bool Ekf::kidnap_candidate(std::int64_t t_ns, const Eigen::Vector3d& z, const Eigen::Matrix3d& R,
                           const FilterVec& prior_x, const FilterCov& prior_P,
                           bool prior_worthless) {
  bool extended = false;
  if (hyp_.count > 0 && t_ns >= hyp_.t_ns && size_ > 0 && hyp_.t_ns >= at(0).t_ns) {
    // Carry the candidate track forward with the same odometry the filter used, then test the
    // new fix against it with the same gate.
    FilterVec x = hyp_.x;
    FilterCov P = hyp_.P;
    std::int64_t tc = hyp_.t_ns;
    const long k0 = find_last_at_or_before(hyp_.t_ns);
    std::int64_t odom_t = k0 < 0 ? kNoOdom : odom_time_after(at(static_cast<std::size_t>(k0)));
    for (std::size_t i = static_cast<std::size_t>(k0 + 1); i < size_ && at(i).t_ns <= t_ns; ++i) {
      const Event& ev = at(i);
      if (ev.kind != EventKind::kOdom) continue;
      apply_odometry(&x, &P, tc, odom_t, ev.t_ns, ev.v_mps, ev.omega_radps);
      tc = ev.t_ns;
      odom_t = ev.t_ns;
    }
    predict_span(&x, &P, tc, t_ns, odom_t);
    if (mahalanobis_sq(x, P, z, R) <= gate_threshold_) {
      update_fix(&x, &P, z, R);
      hyp_.x = x;
      hyp_.P = P;
      // Fixes of one landmark (consecutive frames, or standing on it) count once, so one
      // misprinted landmark cannot hijack the pose: only fixes kidnap_min_separation_mm apart.
      if (std::hypot(z(0) - hyp_.x_count_mm, z(1) - hyp_.y_count_mm) >=
          config_.kidnap_min_separation_mm) {
        ++hyp_.count;
        hyp_.x_count_mm = z(0);
        hyp_.y_count_mm = z(1);
      }
      hyp_.t_ns = t_ns;
      extended = true;
    }
  }
  if (!extended) {
    hyp_.count = 1;
    hyp_.t_first_ns = t_ns;
    hyp_.t_ns = t_ns;
    hyp_.x_count_mm = z(0);
    hyp_.y_count_mm = z(1);
    hyp_.x = prior_x;
    hyp_.x.head<3>() = z;
    hyp_.P = FilterCov::Zero();
    hyp_.P.topLeftCorner<3, 3>() = R;
    // v, omega and the odometry calibration carry over (they do not change when the vehicle
    // is carried); their correlation with the old pose does not.
    hyp_.P.bottomRightCorner<kFilterDim - 3, kFilterDim - 3>() =
        prior_P.bottomRightCorner<kFilterDim - 3, kFilterDim - 3>();
    // ... but not the filter's confidence in them: a filter that rejects fixes may be wrong
    // because its calibration is (a gyro bias that stepped by 1 deg/s drifted the heading 1 deg
    // per second with sigma 0.03 deg; every later fix was rejected, and a track inheriting that
    // bias drifted away from each next fix too, so it never reached kidnap_fixes and the pose
    // ran metres off: fault row gyro_bias_step). The track starts from the initial calibration
    // sigmas and learns the calibration from its own fixes.
    widen_calibration(&hyp_.P);
  }
  // A filter whose position is unknown has no pose worth protecting: two consistent fixes of
  // separate landmarks (what makes a tag, which carries no position, trustworthy) re-initialise
  // it at once.
  const bool enough = prior_worthless
                          ? hyp_.count >= 2
                          : hyp_.count >= config_.kidnap_fixes &&
                                hyp_.t_ns - hyp_.t_first_ns >= config_.kidnap_min_duration_ns;
  if (enough) {
    const FilterVec x = hyp_.x;
    const FilterCov P = hyp_.P;
    initialise_at(t_ns, x, P);
    ++counters_.reinitialisations;
    pending_flags_ |= flags::kReinitialised;
    return true;
  }
  return false;
}

void Ekf::widen_calibration(FilterCov* P) const {
  auto at_least = [P](int i, double sigma) {
    const double var = sigma * sigma;
    if ((*P)(i, i) < var) (*P)(i, i) = var;  // adding to the diagonal keeps P positive
  };
  at_least(kIbg, config_.init_gyro_bias_sigma_radps);
  at_least(kIsg, config_.init_gyro_scale_sigma);
  if (config_.estimate_odometry_calibration) {
    at_least(kIsv, config_.init_v_scale_sigma);
    at_least(kIsomega, config_.init_omega_scale_sigma);
    at_least(kIbomega, config_.init_omega_bias_sigma_radps);
    at_least(kIcomegav, config_.init_omega_per_v_sigma_radpm);
  }
}

void Ekf::relocalize(std::int64_t t_ns, const Eigen::Vector3d& z, const Eigen::Matrix3d& R,
                     const FilterVec& prior_x, const FilterCov& prior_P) {
  FilterVec x = prior_x;
  x.head<3>() = z;
  FilterCov P = FilterCov::Zero();
  P.topLeftCorner<3, 3>() = R;
  // Speed and calibration do not change with the pose error; their correlation with the old,
  // lost pose is meaningless now.
  P.bottomRightCorner<kFilterDim - 3, kFilterDim - 3>() =
      prior_P.bottomRightCorner<kFilterDim - 3, kFilterDim - 3>();
  initialise_at(t_ns, x, P);
  ++counters_.reinitialisations;
  ++counters_.relocalisations;
  pending_flags_ |= flags::kReinitialised;
}

bool Ekf::set_pose(std::int64_t t_ns, const Pose2& z_world, const Eigen::Matrix3d& R) {
  if (!std::isfinite(z_world.x_mm) || !std::isfinite(z_world.y_mm) ||
      !std::isfinite(z_world.theta_rad) || !R.allFinite() || !R.isApprox(R.transpose())) {
    return false;
  }
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig(R, Eigen::EigenvaluesOnly);
  if (eig.info() != Eigen::Success || !(eig.eigenvalues()(0) > 0.0)) return false;
  if (!initialised_ || size_ == 0 || !at(size_ - 1).valid) {
    const FixOutcome o = add_fix(t_ns, z_world, R, /*map_verified=*/true);
    return o == FixOutcome::kInitialised || o == FixOutcome::kHeld;
  }
  const Event& newest = at(size_ - 1);
  relocalize(t_ns, Eigen::Vector3d(z_world.x_mm, z_world.y_mm, z_world.theta_rad), R, newest.x,
             newest.P);
  return true;
}

FixOutcome Ekf::add_fix(std::int64_t t_ns, const Pose2& z_world, const Eigen::Matrix3d& R_in,
                        bool map_verified, bool map_guided) {
  return fuse_fix(t_ns, z_world, R_in, map_verified, map_guided, /*from_hold=*/false);
}

FixOutcome Ekf::fuse_fix(std::int64_t t_ns, const Pose2& z_world, const Eigen::Matrix3d& R_in,
                         bool map_verified, bool map_guided, bool from_hold) {
  auto reject_invalid = [this]() {
    ++counters_.fixes_rejected_invalid;
    pending_flags_ |= flags::kInvalidInput;
    return FixOutcome::kRejectedInvalid;
  };
  auto reject_old = [this]() {
    ++counters_.fixes_rejected_too_old;
    pending_flags_ |= flags::kRejectedTooOld;
    return FixOutcome::kRejectedTooOld;
  };

  // ---- Input validation: never let a bad fix touch the state ----
  if (!std::isfinite(z_world.x_mm) || !std::isfinite(z_world.y_mm) ||
      !std::isfinite(z_world.theta_rad) || !R_in.allFinite())
    return reject_invalid();
  const double scale = R_in.cwiseAbs().maxCoeff();
  if (!((R_in - R_in.transpose()).cwiseAbs().maxCoeff() <= 1e-9 * scale)) return reject_invalid();
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig(R_in, Eigen::EigenvaluesOnly);
  if (eig.info() != Eigen::Success || !(eig.eigenvalues()(0) > 0.0)) return reject_invalid();

  std::int64_t newest_t = 0;
  bool have_newest = false;
  if (size_ > 0) {
    newest_t = at(size_ - 1).t_ns;
    have_newest = true;
  }
  if (have_odom_ && (!have_newest || last_odom_t_ns_ > newest_t)) {
    newest_t = last_odom_t_ns_;
    have_newest = true;
  }
  if (!from_hold && have_odom_ && t_ns > last_odom_t_ns_ + config_.max_fix_lead_ns) {
    hold_fix(t_ns, z_world, R_in, map_verified, map_guided);
    return FixOutcome::kHeld;
  }

  Eigen::Matrix3d R = config_.fix_cov_scale * R_in;
  R(0, 0) += config_.fix_floor_sigma_mm * config_.fix_floor_sigma_mm;
  R(1, 1) += config_.fix_floor_sigma_mm * config_.fix_floor_sigma_mm;
  R(2, 2) += config_.fix_floor_sigma_rad * config_.fix_floor_sigma_rad;
  const Eigen::Vector3d z(z_world.x_mm, z_world.y_mm, wrap_angle_rad(z_world.theta_rad));

  // ---- Too old? ----
  if (have_newest && newest_t - t_ns > config_.max_fix_delay_ns) return reject_old();
  if (initialised_ && t_ns < t_init_ns_) return reject_old();
  const long k = find_last_at_or_before(t_ns);

  auto reject_not_tracking = [this]() {
    ++counters_.fixes_rejected_not_tracking;
    return FixOutcome::kRejectedNotTracking;
  };
  if (map_guided && !initialised_) return reject_not_tracking();

  // ---- Initialisation from the first valid fix ----
  if (!initialised_) {
    if (k < 0 && size_ == history_.size()) return reject_old();  // older than all kept inputs
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
    FilterCov P = FilterCov::Zero();
    P.topLeftCorner<3, 3>() = R;
    P(kIv, kIv) = config_.init_v_sigma_mps * config_.init_v_sigma_mps;
    if (config_.estimate_odometry_calibration) {
      P(kIsv, kIsv) = config_.init_v_scale_sigma * config_.init_v_scale_sigma;
      P(kIsomega, kIsomega) = config_.init_omega_scale_sigma * config_.init_omega_scale_sigma;
      P(kIbomega, kIbomega) =
          config_.init_omega_bias_sigma_radps * config_.init_omega_bias_sigma_radps;
      P(kIcomegav, kIcomegav) =
          config_.init_omega_per_v_sigma_radpm * config_.init_omega_per_v_sigma_radpm;
    }
    P(kIomega, kIomega) = config_.init_omega_sigma_radps * config_.init_omega_sigma_radps;
    P(kIbg, kIbg) = config_.init_gyro_bias_sigma_radps * config_.init_gyro_bias_sigma_radps;
    P(kIsg, kIsg) = config_.init_gyro_scale_sigma * config_.init_gyro_scale_sigma;
    initialise_at(t_ns, x, P);
    ++counters_.fixes_initialised;
    pending_flags_ |= flags::kInitialised;
    return FixOutcome::kInitialised;
  }

  if (k < 0 || !at(static_cast<std::size_t>(k)).valid) return reject_old();

  // ---- Prior at the exposure time, gate ----
  const Event& base = at(static_cast<std::size_t>(k));
  FilterVec x = base.x;
  FilterCov P = base.P;
  predict_span(&x, &P, base.t_ns, t_ns, odom_time_after(base));
  const double d2 = mahalanobis_sq(x, P, z, R);
  last_fix_d2_ = d2;
  double pos_sigma_mm = 0.0;
  const bool lost = prior_lost(P, &pos_sigma_mm);
  auto reject_gate = [&](bool worthless_prior) {
    ++counters_.fixes_rejected_gate;
    pending_flags_ |= flags::kRejectedGate;
    if (!map_guided && kidnap_candidate(t_ns, z, R, x, P, worthless_prior))
      return FixOutcome::kReinitialised;
    return FixOutcome::kRejectedGate;
  };
  // A prior whose position spans landmarks (4x the lost limit) gates nothing: any fix passes.
  // Only a fix that vouches for itself (a QR payload the map confirmed) may then be fused alone;
  // others (a tag, whose map entry is its only truth; a payload without a map) need a second,
  // agreeing fix of another landmark, and a map-guided fix cannot be chosen at all.
  const bool worthless = pos_sigma_mm > 4.0 * config_.lost_position_sigma_mm;
  if (worthless && map_guided) return reject_not_tracking();
  if (worthless && !map_verified) return reject_gate(true);
  // A fix that agrees with the prior is fused, lost or not: fusing keeps the correlations that
  // teach the odometry and gyro calibration, a re-initialisation would drop them. A map-guided
  // fix needs only that (its identity was chosen by the covariance, docs/design/map_identity.md).
  if (!(d2 <= gate_threshold_)) {
    if (map_guided && lost) return reject_not_tracking();
    const bool precise = std::sqrt(R_in.topLeftCorner<2, 2>().diagonal().maxCoeff()) <=
                             config_.relocalize_max_fix_sigma_mm &&
                         std::sqrt(R_in(2, 2)) <= config_.relocalize_max_fix_sigma_rad;
    if (config_.relocalize_from_single_fix && !map_guided && lost && precise) {
      // Re-localisation from one fix: it must still agree with what is known of the position
      // (a heading-only loss keeps a good position prior), unless the position is unknown too;
      // then only a fix that vouches for itself (a QR payload the map confirmed) may do it.
      const bool position_agrees = position_mahalanobis_sq(x, P, z, R) <= gate_threshold_2d_;
      const bool position_unknown = pos_sigma_mm > config_.lost_position_sigma_mm;
      if (position_agrees || (position_unknown && map_verified)) {
        relocalize(t_ns, z, R, x, P);
        return FixOutcome::kReinitialised;
      }
    }
    // A slip the wheels did not show explains the whole innovation: fused with that turn's
    // uncertainty added, so the calibration learnt so far is kept.
    FilterCov P_slip = P;
    if (!(map_verified && !map_guided && precise && explain_unseen_slip(t_ns, z, R, x, &P_slip) &&
          mahalanobis_sq(x, P_slip, z, R) <= gate_threshold_))
      return reject_gate(worthless);
    P = P_slip;
    ++counters_.unseen_slips;
    pending_flags_ |= flags::kWheelSlip;
  }

  // ---- Fuse at the exposure time and re-propagate newer events ----
  hyp_.count = 0;
  update_fix(&x, &P, z, R);
  Event ev;
  ev.t_ns = t_ns;
  ev.kind = EventKind::kFix;
  ev.z = z;
  ev.R = R;
  ev.valid = true;
  ev.x = x;
  ev.P = P;
  ev.odom_t_ns = odom_time_after(base);
  carry_over_fix(base, &ev);
  const std::size_t i = insert_event(ev);
  const bool delayed = i + 1 < size_;
  replay_from(i + 1);
  counters_.events_replayed += size_ - i - 1;
  track_restart(i);
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
// Output

PoseEstimate Ekf::estimate_at(std::int64_t t_ns) const {
  PoseEstimate e;
  e.t_ns = t_ns;
  e.flags = pending_flags_;
  const bool odom_timeout = !have_odom_ || t_ns - last_odom_t_ns_ > config_.odom_timeout_ns;
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
  } else if (have_fix_ && e.time_since_fix_ns <= config_.localized_timeout_ns) {
    e.health = HealthState::kLocalized;
  } else {
    e.health = HealthState::kDeadReckoning;
  }
  return e;
}

}  // namespace agv::fusion
