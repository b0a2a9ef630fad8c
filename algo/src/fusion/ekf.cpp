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

constexpr double kNsToS = 1e-9;

bool finite_nonneg(double v) { return std::isfinite(v) && v >= 0.0; }
bool finite_pos(double v) { return std::isfinite(v) && v > 0.0; }

void symmetrize(FilterCov* P) { *P = 0.5 * (*P + P->transpose()); }

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
  }
  return "?";
}

Ekf::Ekf(const EkfConfig& config)
    : config_(config), last_fix_d2_(std::numeric_limits<double>::quiet_NaN()) {
  const std::string err = validate(config_);
  if (!err.empty()) throw std::invalid_argument("EkfConfig: " + err);
  gate_threshold_ = chi2_3dof_quantile(config_.gate_probability);
  history_.resize(config_.history_capacity);  // the only allocations; never resized later
  held_.resize(config_.held_fix_capacity);
}

std::uint16_t Ekf::take_flags() { return std::exchange(pending_flags_, std::uint16_t{0}); }

// ---------------------------------------------------------------------------------------------
// Filter steps

void Ekf::add_velocity_noise(FilterCov* P, double dt_s) const {
  const double adt = std::abs(dt_s);
  (*P)(kIv, kIv) += config_.accel_sigma_mps2 * config_.accel_sigma_mps2 * adt;
  (*P)(kIomega, kIomega) += config_.yaw_accel_sigma_radps2 * config_.yaw_accel_sigma_radps2 * adt;
}

void Ekf::predict(FilterVec* x, FilterCov* P, double dt_s, bool velocity_noise) const {
  if (dt_s == 0.0) return;
  if (velocity_noise) add_velocity_noise(P, dt_s);
  // Motion (eq. 14) acts on the first five states; the calibration is constant.
  FilterCov F = FilterCov::Identity();
  F.topLeftCorner<5, 5>() = motion_jacobian(x->head<5>(), dt_s);
  const double th = (*x)(kItheta), v = (*x)(kIv), w = (*x)(kIomega);
  const double dist_m = std::abs(v * dt_s);
  const double turn_rad = std::abs(w * dt_s);
  const double adt = std::abs(dt_s);

  // Position noise is defined along/across the direction of travel (mid-step heading).
  const double th_mid = th + 0.5 * w * dt_s;
  const double c = std::cos(th_mid), s = std::sin(th_mid);
  const double qa =
      config_.along_track_sigma_mm_per_sqrt_m * config_.along_track_sigma_mm_per_sqrt_m * dist_m;
  const double qc =
      config_.cross_track_sigma_mm_per_sqrt_m * config_.cross_track_sigma_mm_per_sqrt_m * dist_m;
  FilterCov Q = FilterCov::Zero();
  Q(kIx, kIx) = c * c * qa + s * s * qc;
  Q(kIy, kIy) = s * s * qa + c * c * qc;
  Q(kIx, kIy) = Q(kIy, kIx) = c * s * (qa - qc);
  const double hd = config_.heading_sigma_rad_per_sqrt_m;
  const double hdr = config_.heading_drift_sigma_rad_per_sqrt_s;
  const double ht = config_.turn_heading_sigma_rad_per_sqrt_rad;
  Q(kItheta, kItheta) = hd * hd * dist_m + hdr * hdr * adt + ht * ht * turn_rad;
  if (config_.estimate_odometry_calibration) {
    Q(kIsv, kIsv) = config_.v_scale_sigma_per_sqrt_s * config_.v_scale_sigma_per_sqrt_s * adt;
    Q(kIsomega, kIsomega) =
        config_.omega_scale_sigma_per_sqrt_s * config_.omega_scale_sigma_per_sqrt_s * adt;
    Q(kIbomega, kIbomega) =
        config_.omega_bias_sigma_radps_per_sqrt_s * config_.omega_bias_sigma_radps_per_sqrt_s * adt;
    Q(kIcomegav, kIcomegav) = config_.omega_per_v_sigma_radpm_per_sqrt_s *
                              config_.omega_per_v_sigma_radpm_per_sqrt_s * adt;
  }

  x->head<5>() = motion_predict(x->head<5>(), dt_s);
  *P = F * (*P) * F.transpose() + Q;
  symmetrize(P);
}

void Ekf::update_odometry(FilterVec* x, FilterCov* P, double v_mps, double omega_radps) const {
  // Odometry drives the motion (an input, not a measurement of a random-walk state): the sample
  // and the calibration give the true speeds,
  //   v = v_odo / (1 + s_v),  omega = (omega_odo - b_omega - c_omega_v v) / (1 + s_omega),
  // replacing the previous v and omega. Only fixes teach the calibration, through the
  // correlation this builds. Fusing the sample as a measurement of (v, omega) instead splits
  // every yaw-rate step between omega and the bias states by their prior variances: a 1.25
  // rad/s step before the calibration settled moved b_omega by 0.1 rad/s and the heading by
  // 5 deg over the next second (tests/fusion/test_ekf_faults.cpp).
  const double sv = (*x)(kIsv), sw = (*x)(kIsomega), bw = (*x)(kIbomega);
  const double cwv = (*x)(kIcomegav);
  const double v = v_mps / (1.0 + sv);
  const double w = (omega_radps - bw - cwv * v) / (1.0 + sw);
  // New (v, omega) as functions of the old state (J) and of the sample (Jz).
  Eigen::Matrix<double, 2, kFilterDim> Jvw = Eigen::Matrix<double, 2, kFilterDim>::Zero();
  const double dv_dsv = -v / (1.0 + sv);
  Jvw(0, kIsv) = dv_dsv;
  Jvw(1, kIsv) = -cwv * dv_dsv / (1.0 + sw);
  Jvw(1, kIsomega) = -w / (1.0 + sw);
  Jvw(1, kIbomega) = -1.0 / (1.0 + sw);
  Jvw(1, kIcomegav) = -v / (1.0 + sw);
  Eigen::Matrix2d Jz;
  Jz << 1.0 / (1.0 + sv), 0.0, -cwv / ((1.0 + sv) * (1.0 + sw)), 1.0 / (1.0 + sw);
  const Eigen::Vector2d r(config_.odom_v_sigma_mps * config_.odom_v_sigma_mps,
                          config_.odom_omega_sigma_radps * config_.odom_omega_sigma_radps);
  FilterCov J = FilterCov::Identity();
  J.block<2, kFilterDim>(kIv, 0) = Jvw;
  FilterCov Pn = J * (*P) * J.transpose();
  Pn.block<2, 2>(kIv, kIv) += Jz * r.asDiagonal() * Jz.transpose();
  *P = Pn;
  symmetrize(P);
  (*x)(kIv) = v;
  (*x)(kIomega) = w;
}

void Ekf::propagate_odometry(FilterVec* x, FilterCov* P, double dt_s, double v_mps,
                             double omega_radps) const {
  // A period-mean sample is the speed over the period ending at its time stamp (encoder ticks
  // per period): it replaces v and omega first and then drives the motion over that period.
  // Predicting with the previous sample instead would lag by one period: 0.05 mm per 10 ms step
  // at 1 m/s^2, 5 mm over a 1 s acceleration ramp. (No speed random walk before it: the sample
  // replaces v and omega together with their covariance.)
  update_odometry(x, P, v_mps, omega_radps);
  predict(x, P, dt_s, /*velocity_noise=*/false);
}

void Ekf::predict_span(FilterVec* x, FilterCov* P, std::int64_t t0_ns, std::int64_t t1_ns,
                       std::int64_t odom_t_ns) const {
  if (t1_ns <= t0_ns) {
    predict(x, P, static_cast<double>(t1_ns - t0_ns) * kNsToS);
    return;
  }
  const std::int64_t known_end =
      odom_t_ns == kNoOdom ? t0_ns : std::max(t0_ns, odom_t_ns + config_.odom_gap_ns);
  if (t1_ns <= known_end) {
    predict(x, P, static_cast<double>(t1_ns - t0_ns) * kNsToS);
    return;
  }
  if (known_end > t0_ns) predict(x, P, static_cast<double>(known_end - t0_ns) * kNsToS);
  // Unknown motion: the vehicle may have turned into or out of an arc at once (the yaw rate
  // jumps; added once, where the span enters the unknown part) and accelerated within its
  // limits. The mean stays the last known speed: the best guess, with a covariance that says so.
  const bool enters_unknown =
      odom_t_ns == kNoOdom ? false : t0_ns <= odom_t_ns + config_.odom_gap_ns;
  if (enters_unknown) {
    const double j = config_.gap_yaw_rate_change_sigma_radps;
    (*P)(kIomega, kIomega) += j * j;
  }
  // Substeps, so the position variance grows as the integral of the speed's random walk
  // (sigma^2 T^3 / 3), not as one step's sigma^2 T^3.
  constexpr std::int64_t kSubstepNs = 100'000'000;
  const double qa = config_.gap_accel_sigma_mps2 * config_.gap_accel_sigma_mps2;
  const double qw = config_.gap_yaw_accel_sigma_radps2 * config_.gap_yaw_accel_sigma_radps2;
  const double v0_mps = std::abs((*x)(kIv));
  for (std::int64_t t = known_end; t < t1_ns;) {
    const std::int64_t step = std::min(kSubstepNs, t1_ns - t);
    const double dt_s = static_cast<double>(step) * kNsToS;
    (*P)(kIv, kIv) += qa * dt_s;
    (*P)(kIomega, kIomega) += qw * dt_s;
    predict(x, P, dt_s, /*velocity_noise=*/false);
    t += step;
  }
  // The linearised covariance puts the travel along the predicted heading; once the heading is
  // uncertain by a radian or more, the vehicle may have gone any way. Add the expected squared
  // chord of a heading error (1 - exp(-sigma^2 / 2) of the reachable distance squared) on both
  // axes: nothing for a small heading sigma, the reachable disk for an unknown heading (a 5 s
  // gap that starts in a turn and ends on a straight is metres off a linearised 3 sigma).
  const double tu_s = static_cast<double>(t1_ns - known_end) * kNsToS;
  const double reach_mm = kMmPerM * (v0_mps * tu_s + config_.gap_accel_sigma_mps2 * tu_s * tu_s);
  const double chord = 1.0 - std::exp(-0.5 * (*P)(kItheta, kItheta));
  (*P)(kIx, kIx) += reach_mm * reach_mm * chord;
  (*P)(kIy, kIy) += reach_mm * reach_mm * chord;
}

void Ekf::apply_odometry(FilterVec* x, FilterCov* P, std::int64_t t_prev_ns, std::int64_t odom_t_ns,
                         std::int64_t t_ns, double v_mps, double omega_radps) const {
  const bool instant = config_.odom_sample_timing == EkfConfig::OdomSampleTiming::kInstant;
  if (is_gap(odom_t_ns, t_ns)) {
    // After a gap the sample says how fast the vehicle goes now (over its own period), not how
    // it moved during the gap: the gap is predicted as unknown motion up to the sample's period.
    const std::int64_t span_start =
        std::max(t_prev_ns, t_ns - (instant ? std::int64_t{0} : config_.odom_period_ns));
    predict_span(x, P, t_prev_ns, span_start, odom_t_ns);
    if (instant) {
      update_odometry(x, P, v_mps, omega_radps);
    } else {
      propagate_odometry(x, P, static_cast<double>(t_ns - span_start) * kNsToS, v_mps, omega_radps);
    }
    return;
  }
  const double dt_s = static_cast<double>(t_ns - t_prev_ns) * kNsToS;
  if (instant) {
    // Speeds at both ends of the period: the motion over it is their mean (trapezoid), so a
    // step in the yaw rate turns the heading by half the step times the period, as it did.
    add_velocity_noise(P, dt_s);
    predict(x, P, 0.5 * dt_s, /*velocity_noise=*/false);
    update_odometry(x, P, v_mps, omega_radps);
    predict(x, P, 0.5 * dt_s, /*velocity_noise=*/false);
  } else {
    propagate_odometry(x, P, dt_s, v_mps, omega_radps);
  }
}

void Ekf::update_fix(FilterVec* x, FilterCov* P, const Eigen::Vector3d& z,
                     const Eigen::Matrix3d& R) const {
  // h(x) = (x, y, theta): H = [I3 0] (eq. 17-19); innovation angle wrapped.
  const Eigen::Matrix3d S = P->topLeftCorner<3, 3>() + R;
  const Eigen::Matrix<double, kFilterDim, 3> PHt = P->leftCols<3>();
  const Eigen::Matrix<double, kFilterDim, 3> K = S.llt().solve(PHt.transpose()).transpose();
  Eigen::Vector3d nu = z - x->head<3>();
  nu(2) = wrap_angle_rad(nu(2));
  *x += K * nu;
  (*x)(kItheta) = wrap_angle_rad((*x)(kItheta));
  FilterCov IKH = FilterCov::Identity();
  IKH.leftCols<3>() -= K;
  *P = IKH * (*P) * IKH.transpose() + K * R * K.transpose();
  symmetrize(P);
}

double Ekf::mahalanobis_sq(const FilterVec& x, const FilterCov& P, const Eigen::Vector3d& z,
                           const Eigen::Matrix3d& R) const {
  const Eigen::Matrix3d S = P.topLeftCorner<3, 3>() + R;
  Eigen::Vector3d nu = z - x.head<3>();
  nu(2) = wrap_angle_rad(nu(2));
  const Eigen::LLT<Eigen::Matrix3d> llt(S);
  if (llt.info() != Eigen::Success) return std::numeric_limits<double>::infinity();
  return nu.dot(llt.solve(nu));
}

bool Ekf::prior_lost(const FilterCov& P, double* position_sigma_mm,
                     double* heading_sigma_rad) const {
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix2d> eig(P.topLeftCorner<2, 2>(),
                                                           Eigen::EigenvaluesOnly);
  const double ps = std::sqrt(std::max(0.0, eig.eigenvalues()(1)));
  const double hs = std::sqrt(std::max(0.0, P(kItheta, kItheta)));
  if (position_sigma_mm) *position_sigma_mm = ps;
  if (heading_sigma_rad) *heading_sigma_rad = hs;
  return !(ps <= config_.lost_position_sigma_mm) || !(hs <= config_.lost_heading_sigma_rad);
}

// ---------------------------------------------------------------------------------------------
// History

long Ekf::find_last_at_or_before(std::int64_t t_ns) const {
  // Binary search over the time-ordered ring.
  long lo = 0, hi = static_cast<long>(size_);  // first index with t > t_ns lies in [lo, hi]
  while (lo < hi) {
    const long mid = (lo + hi) / 2;
    if (at(static_cast<std::size_t>(mid)).t_ns <= t_ns) {
      lo = mid + 1;
    } else {
      hi = mid;
    }
  }
  return lo - 1;
}

std::size_t Ekf::insert_event(const Event& ev) {
  const std::size_t cap = history_.size();
  if (size_ == cap) {  // drop the oldest
    head_ = (head_ + 1) % cap;
    --size_;
    ++counters_.history_overwrites;
  }
  std::size_t i = size_;
  at(i) = ev;
  ++size_;
  // Bubble back to time order; equal times keep arrival order. Delays are short, so few swaps.
  while (i > 0 && at(i - 1).t_ns > at(i).t_ns) {
    std::swap(at(i - 1), at(i));
    --i;
  }
  return i;
}

void Ekf::process_event(const Event& prev, Event* ev) const {
  if (ev->kind == EventKind::kInit) return;  // fixed state, independent of the past
  if (!prev.valid) {
    ev->valid = false;
    return;
  }
  FilterVec x = prev.x;
  FilterCov P = prev.P;
  const std::int64_t odom_t = odom_time_after(prev);
  if (ev->kind == EventKind::kOdom) {
    apply_odometry(&x, &P, prev.t_ns, odom_t, ev->t_ns, ev->v_mps, ev->omega_radps);
  } else {
    predict_span(&x, &P, prev.t_ns, ev->t_ns, odom_t);
    update_fix(&x, &P, ev->z, ev->R);
  }
  ev->odom_t_ns = odom_t;
  ev->x = x;
  ev->P = P;
  ev->valid = true;
}

void Ekf::replay_from(std::size_t from) {
  for (std::size_t i = from; i < size_; ++i) {
    if (i == 0) {
      // No predecessor kept: only an initialisation carries its own state.
      if (at(0).kind != EventKind::kInit) at(0).valid = false;
      continue;
    }
    process_event(at(i - 1), &at(i));
  }
}

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
  } else {
    ++counters_.odom_stored_uninitialised;
  }
  settle_held_after(t_ns);
  return true;
}

void Ekf::hold_fix(std::int64_t t_ns, const Pose2& z_world, const Eigen::Matrix3d& R_in,
                   bool map_verified) {
  if (held_count_ == held_.size()) {  // the newest fixes are worth more: drop the oldest
    std::move(held_.begin() + 1, held_.begin() + static_cast<long>(held_count_), held_.begin());
    --held_count_;
    ++counters_.fixes_held_dropped;
  }
  std::size_t i = held_count_++;
  held_[i] = HeldFix{t_ns, z_world, R_in, map_verified};
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
    fuse_fix(h.t_ns, h.z, h.R, h.map_verified, /*from_hold=*/true);
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
      fuse_fix(h.t_ns, h.z, h.R, h.map_verified, /*from_hold=*/false);
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
  t_init_ns_ = t_ns;
  have_fix_ = true;
  last_fix_t_ns_ = t_ns;
  hyp_.count = 0;
}

bool Ekf::kidnap_candidate(std::int64_t t_ns, const Eigen::Vector3d& z, const Eigen::Matrix3d& R,
                           const FilterVec& prior_x, const FilterCov& prior_P) {
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
  }
  if (hyp_.count >= config_.kidnap_fixes &&
      hyp_.t_ns - hyp_.t_first_ns >= config_.kidnap_min_duration_ns) {
    const FilterVec x = hyp_.x;
    const FilterCov P = hyp_.P;
    initialise_at(t_ns, x, P);
    ++counters_.reinitialisations;
    pending_flags_ |= flags::kReinitialised;
    return true;
  }
  return false;
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

FixOutcome Ekf::add_fix(std::int64_t t_ns, const Pose2& z_world, const Eigen::Matrix3d& R_in,
                        bool map_verified) {
  return fuse_fix(t_ns, z_world, R_in, map_verified, /*from_hold=*/false);
}

FixOutcome Ekf::fuse_fix(std::int64_t t_ns, const Pose2& z_world, const Eigen::Matrix3d& R_in,
                         bool map_verified, bool from_hold) {
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
    hold_fix(t_ns, z_world, R_in, map_verified);
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
  if (config_.relocalize_from_single_fix && map_verified && prior_lost(P) &&
      std::sqrt(R_in.topLeftCorner<2, 2>().diagonal().maxCoeff()) <=
          config_.relocalize_max_fix_sigma_mm &&
      std::sqrt(R_in(2, 2)) <= config_.relocalize_max_fix_sigma_rad) {
    relocalize(t_ns, z, R, x, P);
    return FixOutcome::kReinitialised;
  }
  if (!(d2 <= gate_threshold_)) {
    ++counters_.fixes_rejected_gate;
    pending_flags_ |= flags::kRejectedGate;
    if (kidnap_candidate(t_ns, z, R, x, P)) return FixOutcome::kReinitialised;
    return FixOutcome::kRejectedGate;
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
  const std::size_t i = insert_event(ev);
  const bool delayed = i + 1 < size_;
  replay_from(i + 1);
  counters_.events_replayed += size_ - i - 1;
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
