// Ekf filter steps (prediction over an odometry gap, odometry and fix updates, gating) and the
// time-ordered event history they are replayed over. Inputs, fix policy and output: ekf.cpp.
#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>
#include <algorithm>
#include <cmath>
#include <limits>

#include "agv/fusion/ekf.hpp"

namespace agv::fusion {

namespace {

constexpr double kNsToS = 1e-9;

void symmetrize(FilterCov* P) { *P = 0.5 * (*P + P->transpose()); }

}  // namespace

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

}  // namespace agv::fusion
