// Ekf aid: wheel slip. Two detectors, one state (SlipState, kept with every history event):
//  - with a gyro, the wheels' yaw rate against the gyro's: beyond the flag threshold a slip whose
//    speed error is corrected; under it, within the noise, a measurement of the wheel calibration;
//    between, a sub-threshold slip whose sign the speed reading's steps tell;
//  - wheels only, one wheel's reading stepping beyond what the vehicle can do: that wheel is held
//    at its reading less the step until it steps back (docs/design/fusion.md "Wheel slip without
//    a gyro").
// A slip neither showed (a heading change found by the next landmark) is recovery.cpp's.
#include <algorithm>
#include <cmath>

#include "agv/fusion/ekf.hpp"
#include "ekf_internal.hpp"

namespace agv::fusion {

using detail::kNsToS;
using detail::symmetrize;

// ---------------------------------------------------------------------------------------------
// With a gyro

Ekf::GyroSlip Ekf::wheels_against_gyro(FilterVec* x, FilterCov* P, double dt_s, double v_mps,
                                       double omega_radps, bool still, double v_read_prev_mps,
                                       SlipRun* run) const {
  const double w_gyro = (*x)(kIomega);
  // The wheels' yaw rate after their calibration, against the gyro's.
  const double sv = (*x)(kIsv), sw = (*x)(kIsomega), bw = (*x)(kIbomega), cwv = (*x)(kIcomegav);
  const double v_true = v_mps / (1.0 + sv);
  const double w_wheels = (omega_radps - bw - cwv * v_true) / (1.0 + sw);
  GyroSlip out;
  out.d_radps = w_wheels - w_gyro;
  const double d = out.d_radps;
  out.slip =
      std::abs(d) > config_.slip.yaw_rate_radps + config_.slip.yaw_rate_fraction * std::abs(w_gyro);
  // One wheel off by e turns the yaw rate by e / track and the speed by e / 2, whichever wheel
  // it is. A wheel that loses grip while it drives spins (reads high); one that loses it while
  // braking locks (reads low): the speed is corrected by that half and keeps half the correction
  // as its sigma (the other case lands 4 sigma off, not unnoticed).
  const double v_prev = (*x)(kIv) * (1.0 + sv);  // the previous period, as the wheels read
  const bool braking = std::abs(v_mps) < std::abs(v_prev);
  const double away = v_mps >= 0.0 ? 1.0 : -1.0;  // towards a larger |v|
  const double spin_sign = braking ? away : -away;
  const double half_track_m = 0.5 * config_.slip.wheel_track_mm / kMmPerM;
  out.v_mps = v_mps;
  out.v_var = 0.0;
  if (out.slip) {
    const double half_mps = std::abs(d) * half_track_m;
    out.v_mps = v_mps + spin_sign * half_mps;
    out.v_var = 0.25 * half_mps * half_mps;
  } else {
    small_slip(x, P, dt_s, v_mps, omega_radps, still, v_read_prev_mps, away, run, &out);
  }
  return out;
}

void Ekf::small_slip(FilterVec* x, FilterCov* P, double dt_s, double v_mps, double omega_radps,
                     bool still, double v_read_prev_mps, double away, SlipRun* run,
                     GyroSlip* out) const {
  const double half_track_m = 0.5 * config_.slip.wheel_track_mm / kMmPerM;
  double d_sigma = 0.0;
  const double diff = learn_wheel_yaw(x, P, v_mps, omega_radps, /*learn=*/!still, &d_sigma);
  if (!(std::abs(diff) > config_.slip.noise_sigmas * d_sigma && dt_s > 0.0)) {
    *run = SlipRun{};
    return;
  }
  // More difference than the sample noise and the calibration explain: a wheel slips. Given
  // that, its speed error is the whole difference's speed equivalent u (up to the noise
  // part, d_sigma), either +u (the wheel spins: reads high) or -u (it locks: reads low).
  // Which one the speed reading says: its step between periods is the vehicle's own
  // acceleration plus the change of +-u, so each period adds 2 du step / s^2 to the run's
  // log likelihood ratio spin : lock (a 5 % slip of an arc's outer wheel steps 37 mm/s
  // against s = 12 mm/s: 19, certain; a slip whose step hides in s stays near even). The
  // speed then takes the mixture's mean and variance, (2p - 1) u and 4 p (1 - p) u^2, plus
  // the noise part. Guessing the sign from the braking test and keeping u in full as sigma
  // made the position sigma ~10x the error after each such slip, and a step-less difference
  // was "corrected" by the whole of u.
  const double u_mps = std::abs(diff) * half_track_m;
  if (std::isfinite(v_read_prev_mps)) {
    const double sn = config_.odometry.v_sigma_mps, sa = config_.slip.max_accel_mps2 * dt_s;
    const double step_mps = away * (v_mps - v_read_prev_mps);
    run->llr += 2.0 * (u_mps - run->u_mps) * step_mps / (2.0 * sn * sn + sa * sa);
    run->llr = std::clamp(run->llr, -30.0, 30.0);
  }
  run->u_mps = u_mps;
  const double p_spin = 1.0 / (1.0 + std::exp(-run->llr));
  const double noise_mps = d_sigma * half_track_m;
  const double sd_mps =
      std::sqrt(4.0 * p_spin * (1.0 - p_spin) * u_mps * u_mps + noise_mps * noise_mps);
  out->v_mps = v_mps - away * (2.0 * p_spin - 1.0) * u_mps;
  // A slip's speed error is the same over its periods, so over a run they add up: the run's
  // variance is (sum sd dt)^2, i.e. sd^2 + 2 A sd / dt per period after A of the run (as
  // white noise per period, a 0.3 s slip had 2 mm of sigma for its 11 mm).
  out->v_var = sd_mps * sd_mps + 2.0 * run->sigma_m * sd_mps / dt_s;
  run->sigma_m += sd_mps * dt_s;
}

double Ekf::learn_wheel_yaw(FilterVec* x, FilterCov* P, double v_mps, double omega_radps,
                            bool learn, double* sigma_radps) const {
  // z = omega_odo = (1 + s_omega) omega + b_omega + c_omega_v v with omega from the gyro. Only
  // the wheel calibration takes the gain (the gyro keeps the heading; Joseph form, so the
  // restricted gain stays consistent). Without it the calibration kept its prior with a gyro
  // (sigma 2-4 deg/s in arcs) and no sub-threshold slip could be told from it.
  const double sv = (*x)(kIsv), sw = (*x)(kIsomega), bw = (*x)(kIbomega), cwv = (*x)(kIcomegav);
  const double w = (*x)(kIomega);
  const double v = v_mps / (1.0 + sv);
  Eigen::Matrix<double, 1, kFilterDim> H = Eigen::Matrix<double, 1, kFilterDim>::Zero();
  H(kIomega) = 1.0 + sw;
  H(kIsomega) = w;
  H(kIbomega) = 1.0;
  H(kIcomegav) = v;
  H(kIsv) = -cwv * v / (1.0 + sv);
  const double r = config_.odometry.omega_sigma_radps * config_.odometry.omega_sigma_radps;
  const FilterVec PHt = (*P) * H.transpose();
  const double S = H.dot(PHt) + r;
  *sigma_radps = 0.0;
  if (!(S > 0.0)) return 0.0;
  const double nu = omega_radps - ((1.0 + sw) * w + bw + cwv * v);
  const double k = config_.slip.noise_sigmas;
  *sigma_radps = std::sqrt(S) / (1.0 + sw);
  if (learn && config_.odometry.estimate_calibration) {
    // A difference beyond k sigma is fused as one of k sigma (its R grows to nu^2 / k^2): a
    // sub-threshold slip hardly moves the calibration, and a real change (tyre, load) is still
    // followed, which a hard gate would lock out once it exceeds k sigma.
    // The scale's regressor is the gyro's rate, whose noise is also in nu: where that noise is
    // of the rate's size (straights, standing) the product biases s_omega (errors in
    // variables: -P_ss sigma_w^2 / S every period, -0.1 over 6 s of straight in eval_fusion
    // --honesty). Below 10 sigma of the rate the gain leaves s_omega out and takes its term as
    // noise; the covariance keeps the full H (Joseph form holds for any gain).
    const bool scale_seen = w * w > 100.0 * (*P)(kIomega, kIomega);
    Eigen::Matrix<double, 1, kFilterDim> Hk = H;
    double Sk = S;
    if (!scale_seen) {
      Hk(kIsomega) = 0.0;
      Sk = Hk.dot((*P) * Hk.transpose()) + r + w * w * (*P)(kIsomega, kIsomega);
    }
    const FilterVec PHk = (*P) * Hk.transpose();
    const double Sr = std::max(Sk, nu * nu / (k * k));
    const double r_eff = r + std::max(0.0, nu * nu / (k * k) - Sk);
    FilterVec K = FilterVec::Zero();
    for (const int i : {kIsomega, kIbomega, kIcomegav}) K(i) = PHk(i) / Sr;
    if (!scale_seen) K(kIsomega) = 0.0;
    *x += K * nu;
    FilterCov IKH = FilterCov::Identity() - K * H;
    *P = IKH * (*P) * IKH.transpose() + K * r_eff * K.transpose();
    symmetrize(P);
  }
  return nu / (1.0 + sw);
}

void Ekf::count_slip(const Event& prev, bool was_slip, bool was_start, const Event& ev) const {
  // Counted once per period however often it is replayed (a later gyro sample or a delayed
  // fix re-propagates it).
  const bool is_start = ev.slip.slipping && !prev.slip.slipping;
  if (ev.slip.slipping != was_slip) {
    if (ev.slip.slipping)
      ++counters_.slip_periods;
    else
      --counters_.slip_periods;
  }
  if (is_start != was_start) {
    if (is_start)
      ++counters_.slip_events;
    else
      --counters_.slip_events;
  }
}

// ---------------------------------------------------------------------------------------------
// Wheels only: the held wheel

WheelHold Ekf::hold_wheel(const Event& prev, std::int64_t t_ns, double dt_s, double v_mps,
                          double omega_radps, double* v_use_mps, double* omega_use_radps,
                          double* add_theta_var) const {
  *add_theta_var = 0.0;
  const SlipState& ps = prev.slip;
  if (std::isnan(ps.v_read_mps) || std::isnan(ps.omega_read_radps)) return WheelHold{};
  const double half_m = 0.5 * config_.slip.wheel_track_mm / kMmPerM;
  WheelSteps s;
  s.now[0] = v_mps - omega_radps * half_m;
  s.now[1] = v_mps + omega_radps * half_m;
  const double before[2] = {ps.v_read_mps - ps.omega_read_radps * half_m,
                            ps.v_read_mps + ps.omega_read_radps * half_m};
  s.step[0] = s.now[0] - before[0];
  s.step[1] = s.now[1] - before[1];
  s.limit = config_.slip.max_accel_mps2 * dt_s + config_.slip.wheel_step_min_mps;
  s.track_m = 2.0 * half_m;
  WheelHold h = ps.hold;
  auto done = [&s](WheelHold r) {
    r.step_mps[0] = s.step[0];
    r.step_mps[1] = s.step[1];
    return r;
  };
  if (h.wheel >= 0) {
    if (!continue_hold(&h, s, t_ns, add_theta_var)) return done(h);
  } else if (!start_hold(prev, s, dt_s, &h, add_theta_var)) {
    return done(WheelHold{});
  }
  read_held(&h, s, dt_s, v_use_mps, omega_use_radps, add_theta_var);
  return done(h);
}

bool Ekf::continue_hold(WheelHold* h, const WheelSteps& s, std::int64_t t_ns,
                        double* add_theta_var) const {
  const int i = h->wheel, o = 1 - i;
  if (t_ns - h->since_ns > config_.slip.max_duration_ns) {
    // Held too long for a slip: the readings are taken as they are from here. The hold may
    // have been wrong all along (a real change the wheel made alone): half its yaw-rate step
    // over the hold, as sigma.
    const double amb =
        0.5 * h->offset_mps / s.track_m * static_cast<double>(t_ns - h->since_ns) * kNsToS;
    *add_theta_var = amb * amb;
    *h = WheelHold{};
    return false;
  }
  // Another step of the held wheel alone. Back by at least half the held step, or to within
  // half of what the slip had grown or shrunk to: the slip is over (one ending inside a period
  // steps back over two: the rest is not a new slip), and this reading is the wheel's own again.
  // The same way: the slip began inside the previous period, whose mean reading showed only part
  // of it; the rest is added to the step.
  if (std::abs(s.step[i]) > s.limit &&
      std::abs(s.step[o]) <= std::min(s.limit, 0.25 * std::abs(s.step[i]))) {
    // (The slip's size now, if it changed while held, is the step plus the drift below.)
    const double slip_now = h->offset_mps + h->drift_mps;
    if ((s.step[i] > 0.0) != (h->offset_mps > 0.0) &&
        (std::abs(s.step[i]) >= 0.5 * std::abs(h->offset_mps) ||
         std::abs(s.step[i] + slip_now) <= 0.5 * std::abs(slip_now))) {
      WheelHold released;
      released.released_ns = t_ns;
      released.released_wheel = i;
      released.released_step_mps = s.step[i];
      *h = released;
      return false;
    }
    h->offset_mps += s.step[i];
  }
  return true;
}

bool Ekf::start_hold(const Event& prev, const WheelSteps& s, double dt_s, WheelHold* h,
                     double* add_theta_var) const {
  const WheelHold& before = prev.slip.hold;
  const bool releasing = before.released_ns == prev.t_ns;
  for (int i = 0; i < 2; ++i) {
    // The other wheel steady: within the limit and a quarter of this step (a turn's start or
    // end inside a period steps both wheels by about as much, opposite).
    if (releasing && i == before.released_wheel &&
        (s.step[i] > 0.0) == (before.released_step_mps > 0.0))
      continue;
    if (!(std::abs(s.step[i]) > s.limit &&
          std::abs(s.step[1 - i]) <= std::min(s.limit, 0.25 * std::abs(s.step[i]))))
      continue;
    const double pre = before.step_mps[i], pre_other = before.step_mps[1 - i];
    *h = WheelHold{};
    h->wheel = i;
    h->offset_mps = s.step[i];
    h->since_ns = prev.t_ns;
    h->diff0_mps = (s.now[i] - s.step[i]) - s.now[1 - i];
    // Begun inside the previous period: that period's step of this wheel, the same way and
    // beyond what the vehicle's acceleration explains (the other wheel steady), is the
    // slip's first part. The heading already took it: its yaw rate over the period as sigma.
    if ((pre > 0.0) == (s.step[i] > 0.0) &&
        std::abs(pre) >
            config_.slip.max_accel_mps2 * dt_s + 0.5 * config_.slip.wheel_step_min_mps &&
        std::abs(pre_other) <= 0.25 * std::abs(pre)) {
      h->offset_mps += pre;
      h->diff0_mps -= pre;
      const double missed_rad = pre / s.track_m * dt_s;
      h->sigma_rad = std::abs(missed_rad);
      *add_theta_var += missed_rad * missed_rad;
    }
    return true;
  }
  return false;
}

void Ekf::read_held(WheelHold* h, const WheelSteps& s, double dt_s, double* v_use_mps,
                    double* omega_use_radps, double* add_theta_var) const {
  // Two readings of the held wheel: less the step (the slip kept its size) and the other wheel
  // plus the difference at the onset (the yaw rate kept its value). While they agree either is
  // right; where they part, the slip's size or the yaw rate changed and the wheels cannot say
  // which: the mean of the two is used, half their difference is the yaw-rate doubt, and the
  // heading sigma adds it up over the hold (a run's error adds up, it does not average out),
  // with hold_sigma_fraction of the step as a floor.
  const int i = h->wheel, o = 1 - i;
  double w[2] = {s.now[0], s.now[1]};
  w[i] -= h->offset_mps;
  h->drift_mps = (w[i] - w[o]) - h->diff0_mps;
  w[i] -= 0.5 * h->drift_mps;
  *v_use_mps = 0.5 * (w[0] + w[1]);
  *omega_use_radps = (w[1] - w[0]) / s.track_m;
  const double doubt_radps =
      (0.5 * std::abs(h->drift_mps) + config_.slip.hold_sigma_fraction * std::abs(h->offset_mps)) /
      s.track_m;
  const double sigma = h->sigma_rad + doubt_radps * dt_s;
  *add_theta_var += sigma * sigma - h->sigma_rad * h->sigma_rad;
  h->sigma_rad = sigma;
}

}  // namespace agv::fusion
