// Ekf aid: wheel odometry. The samples drive the motion (an input, not a measurement of a
// random-walk state); their gaps are predicted as unknown motion (docs/design/fusion.md, "Model",
// "Odometry gaps"). Where the gyro covers a period it carries the heading (aid_gyro.cpp); wheel
// slip: aid_wheel_slip.cpp.
#include <algorithm>
#include <cmath>

#include "agv/fusion/ekf.hpp"
#include "ekf_internal.hpp"

namespace agv::fusion {

using detail::kNsToS;
using detail::symmetrize;

bool Ekf::add_odometry(std::int64_t t_ns, double v_mps, double omega_radps) {
  if (!std::isfinite(v_mps) || !std::isfinite(omega_radps) ||
      std::abs(v_mps) > config_.odometry.max_abs_v_mps ||
      std::abs(omega_radps) > config_.odometry.max_abs_omega_radps) {
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
    if (at(i).slip.slipping) pending_flags_ |= flags::kWheelSlip;
  } else {
    ++counters_.odom_stored_uninitialised;
  }
  track_odometry();
  settle_held_after(t_ns);
  return true;
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
  const Eigen::Vector2d r(config_.odometry.v_sigma_mps * config_.odometry.v_sigma_mps,
                          config_.odometry.omega_sigma_radps * config_.odometry.omega_sigma_radps);
  FilterCov J = FilterCov::Identity();
  J.block<2, kFilterDim>(kIv, 0) = Jvw;
  FilterCov Pn = J * (*P) * J.transpose();
  Pn.block<2, 2>(kIv, kIv) += Jz * r.asDiagonal() * Jz.transpose();
  *P = Pn;
  symmetrize(P);
  (*x)(kIv) = v;
  (*x)(kIomega) = w;
}

void Ekf::update_speed(FilterVec* x, FilterCov* P, double v_mps, double extra_v_var) const {
  // v = v_odo / (1 + s_v) replaces the speed (as update_odometry, without the yaw rate).
  const double sv = (*x)(kIsv);
  const double v = v_mps / (1.0 + sv);
  FilterCov J = FilterCov::Identity();
  J(kIv, kIv) = 0.0;
  J(kIv, kIsv) = -v / (1.0 + sv);
  FilterCov Pn = J * (*P) * J.transpose();
  const double jz = 1.0 / (1.0 + sv);
  Pn(kIv, kIv) +=
      jz * jz * (config_.odometry.v_sigma_mps * config_.odometry.v_sigma_mps + extra_v_var);
  *P = Pn;
  symmetrize(P);
  (*x)(kIv) = v;
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

void Ekf::predict_known(FilterVec* x, FilterCov* P, std::int64_t t0_ns, std::int64_t t1_ns) const {
  // Part of an odometry period (a fix's exposure, an output tick): the period's yaw rate is its
  // mean, which is wrong by the rate's change where a turn starts or ends inside the period
  // (0.3 deg at 115 deg/s in 10 ms). The gyro's samples over the part itself, where they cover
  // it, say how much of the turn falls before the split: without them a fix just after a turn
  // ended pulled the heading 0.3 deg off at sigma 0.04 deg (eval_fusion --honesty).
  double g = 0.0;
  const double dt_s = static_cast<double>(t1_ns - t0_ns) * kNsToS;
  if (gyro_mean(t0_ns, t1_ns, &g)) {
    set_gyro_rate(x, P, g, dt_s);
    predict(x, P, dt_s, /*velocity_noise=*/false, /*gyro_heading=*/true);
  } else {
    predict(x, P, dt_s);
  }
}

void Ekf::predict_span(FilterVec* x, FilterCov* P, std::int64_t t0_ns, std::int64_t t1_ns,
                       std::int64_t odom_t_ns) const {
  if (t1_ns <= t0_ns) {
    predict(x, P, static_cast<double>(t1_ns - t0_ns) * kNsToS);
    return;
  }
  const std::int64_t known_end =
      odom_t_ns == kNoOdom ? t0_ns : std::max(t0_ns, odom_t_ns + config_.odometry.gap_ns);
  if (t1_ns <= known_end) {
    predict_known(x, P, t0_ns, t1_ns);
    return;
  }
  if (known_end > t0_ns) predict_known(x, P, t0_ns, known_end);
  predict_unknown(x, P, t0_ns, known_end, t1_ns, odom_t_ns);
}

void Ekf::predict_unknown(FilterVec* x, FilterCov* P, std::int64_t t0_ns, std::int64_t known_end_ns,
                          std::int64_t t1_ns, std::int64_t odom_t_ns) const {
  const OdometryConfig& o = config_.odometry;
  const std::int64_t known_end = known_end_ns;
  // Unknown motion: the vehicle may have turned into or out of an arc at once (the yaw rate
  // jumps; added once, where the span enters the unknown part) and accelerated within its
  // limits. The mean stays the last known speed: the best guess, with a covariance that says so.
  const bool enters_unknown = odom_t_ns == kNoOdom ? false : t0_ns <= odom_t_ns + o.gap_ns;
  // A working gyro still knows the turn: only the speed is unknown then.
  double g = 0.0;
  const bool gyro_all = gyro_mean_hold(known_end, t1_ns, &g);
  if (enters_unknown && !gyro_all) {
    // The change may have come right after the newest sample, not only once gap_ns had
    // passed: the heading then already turned by it for that long (gs). Added as one jump of
    // (heading, yaw rate) = j (gs, 1), so the prediction carries the pair forward together
    // (without the heading part an arc exit at the start of a gap stayed outside 3 sigma for
    // 0.25 s: fault row odom_gap_5s_straight).
    const double j = o.gap_yaw_rate_change_sigma_radps;
    const double gs =
        odom_t_ns == kNoOdom ? 0.0 : static_cast<double>(known_end - odom_t_ns) * kNsToS;
    (*P)(kIomega, kIomega) += j * j;
    (*P)(kItheta, kItheta) += j * j * gs * gs;
    (*P)(kItheta, kIomega) += j * j * gs;
    (*P)(kIomega, kItheta) += j * j * gs;
  }
  // Substeps, so the position variance grows as the integral of the speed's random walk
  // (sigma^2 T^3 / 3), not as one step's sigma^2 T^3.
  constexpr std::int64_t kSubstepNs = 100'000'000;
  const double qa = o.gap_accel_sigma_mps2 * o.gap_accel_sigma_mps2;
  const double qw = o.gap_yaw_accel_sigma_radps2 * o.gap_yaw_accel_sigma_radps2;
  const double v0_mps = std::abs((*x)(kIv));
  for (std::int64_t t = known_end; t < t1_ns;) {
    const std::int64_t step = std::min(kSubstepNs, t1_ns - t);
    const double dt_s = static_cast<double>(step) * kNsToS;
    (*P)(kIv, kIv) += qa * dt_s;
    if (gyro_all && gyro_mean_hold(t, t + step, &g)) {
      set_gyro_rate(x, P, g, dt_s);
      predict(x, P, dt_s, /*velocity_noise=*/false, /*gyro_heading=*/true);
    } else {
      (*P)(kIomega, kIomega) += qw * dt_s;
      predict(x, P, dt_s, /*velocity_noise=*/false);
    }
    t += step;
  }
  // The linearised covariance puts the travel along the predicted heading; once the heading is
  // uncertain by a radian or more, the vehicle may have gone any way. Add the expected squared
  // chord of a heading error (1 - exp(-sigma^2 / 2) of the reachable distance squared) on both
  // axes: nothing for a small heading sigma, the reachable disk for an unknown heading (a 5 s
  // gap that starts in a turn and ends on a straight is metres off a linearised 3 sigma).
  const double tu_s = static_cast<double>(t1_ns - known_end) * kNsToS;
  const double reach_mm = kMmPerM * (v0_mps * tu_s + o.gap_accel_sigma_mps2 * tu_s * tu_s);
  const double chord = 1.0 - std::exp(-0.5 * (*P)(kItheta, kItheta));
  (*P)(kIx, kIx) += reach_mm * reach_mm * chord;
  (*P)(kIy, kIy) += reach_mm * reach_mm * chord;
}

void Ekf::apply_odometry(FilterVec* x, FilterCov* P, std::int64_t t_prev_ns, std::int64_t odom_t_ns,
                         std::int64_t t_ns, double v_mps, double omega_radps, const Event* prev,
                         Event* out) const {
  if (out) {
    out->gyro = false;
    out->slip = SlipState{};
    out->slip.v_read_mps = v_mps;
    out->slip.omega_read_radps = omega_radps;
  }
  double g = 0.0;
  if (!is_gap(odom_t_ns, t_ns) && t_ns > t_prev_ns && gyro_mean(t_prev_ns, t_ns, &g)) {
    apply_gyro_period(x, P, t_prev_ns, t_ns, v_mps, omega_radps, g, prev, out);
    return;
  }
  const bool instant = config_.odometry.sample_timing == OdometryConfig::SampleTiming::kInstant;
  if (is_gap(odom_t_ns, t_ns)) {
    // After a gap the sample says how fast the vehicle goes now (over its own period), not how
    // it moved during the gap: the gap is predicted as unknown motion up to the sample's period.
    const std::int64_t span_start =
        std::max(t_prev_ns, t_ns - (instant ? std::int64_t{0} : config_.odometry.period_ns));
    predict_span(x, P, t_prev_ns, span_start, odom_t_ns);
    if (instant) {
      update_odometry(x, P, v_mps, omega_radps);
    } else {
      propagate_odometry(x, P, static_cast<double>(t_ns - span_start) * kNsToS, v_mps, omega_radps);
    }
    return;
  }
  apply_wheel_period(x, P, t_prev_ns, t_ns, v_mps, omega_radps, prev, out);
}

void Ekf::apply_wheel_period(FilterVec* x, FilterCov* P, std::int64_t t_prev_ns, std::int64_t t_ns,
                             double v_mps, double omega_radps, const Event* prev,
                             Event* out) const {
  const double dt_s = static_cast<double>(t_ns - t_prev_ns) * kNsToS;
  if (prev) {
    double add_theta_var = 0.0;
    const WheelHold h =
        hold_wheel(*prev, t_ns, dt_s, v_mps, omega_radps, &v_mps, &omega_radps, &add_theta_var);
    (*P)(kItheta, kItheta) += add_theta_var;
    if (out) {
      out->slip.hold = h;
      out->slip.slipping = h.wheel >= 0;
      out->slip.since_ns = h.wheel >= 0 ? h.since_ns : kNoOdom;
    }
  }
  if (config_.odometry.sample_timing == OdometryConfig::SampleTiming::kInstant) {
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

}  // namespace agv::fusion
