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

void Ekf::predict(FilterVec* x, FilterCov* P, double dt_s, bool velocity_noise,
                  bool gyro_heading) const {
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
  // With the gyro the heading noise is the gyro's: its rate noise (set with omega) and its
  // calibration states. The wheel terms model the wheels' heading errors.
  if (!gyro_heading) Q(kItheta, kItheta) = hd * hd * dist_m + hdr * hdr * adt + ht * ht * turn_rad;
  Q(kIbg, kIbg) =
      config_.gyro_bias_sigma_radps_per_sqrt_s * config_.gyro_bias_sigma_radps_per_sqrt_s * adt;
  Q(kIsg, kIsg) = config_.gyro_scale_sigma_per_sqrt_s * config_.gyro_scale_sigma_per_sqrt_s * adt;
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

void Ekf::set_gyro_rate(FilterVec* x, FilterCov* P, double gyro_radps, double dt_s) const {
  // omega = (gyro - b_g) / (1 + s_g) replaces the yaw rate; the mean of white rate noise over
  // dt has variance N^2 / dt, so the heading integrates to the angle random walk N^2 t.
  const double bg = (*x)(kIbg), sg = (*x)(kIsg);
  const double w = (gyro_radps - bg) / (1.0 + sg);
  Eigen::Matrix<double, 1, kFilterDim> Jw = Eigen::Matrix<double, 1, kFilterDim>::Zero();
  Jw(kIbg) = -1.0 / (1.0 + sg);
  Jw(kIsg) = -w / (1.0 + sg);
  FilterCov J = FilterCov::Identity();
  J.row(kIomega) = Jw;
  FilterCov Pn = J * (*P) * J.transpose();
  const double n = config_.gyro_noise_density_radps_per_sqrt_hz / (1.0 + sg);
  Pn(kIomega, kIomega) += n * n / std::max(dt_s, 1e-4);
  *P = Pn;
  symmetrize(P);
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
  Pn(kIv, kIv) += jz * jz * (config_.odom_v_sigma_mps * config_.odom_v_sigma_mps + extra_v_var);
  *P = Pn;
  symmetrize(P);
  (*x)(kIv) = v;
}

void Ekf::update_zero_rate(FilterVec* x, FilterCov* P) const {
  // z = 0 = omega: through omega's correlation with b_g (set_gyro_rate) this is the gyro's
  // reading of its own bias.
  const double r = config_.standstill_omega_sigma_radps * config_.standstill_omega_sigma_radps;
  const double S = (*P)(kIomega, kIomega) + r;
  if (!(S > 0.0)) return;
  const FilterVec K = P->col(kIomega) / S;
  const double nu = -(*x)(kIomega);
  *x += K * nu;
  FilterCov IKH = FilterCov::Identity();
  IKH.col(kIomega) -= K;
  *P = IKH * (*P) * IKH.transpose() + K * r * K.transpose();
  symmetrize(P);
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
  const double r = config_.odom_omega_sigma_radps * config_.odom_omega_sigma_radps;
  const FilterVec PHt = (*P) * H.transpose();
  const double S = H.dot(PHt) + r;
  *sigma_radps = 0.0;
  if (!(S > 0.0)) return 0.0;
  const double nu = omega_radps - ((1.0 + sw) * w + bw + cwv * v);
  const double k = config_.slip_noise_sigmas;
  *sigma_radps = std::sqrt(S) / (1.0 + sw);
  if (learn && config_.estimate_odometry_calibration) {
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

bool Ekf::gyro_period(FilterVec* x, FilterCov* P, double dt_s, double v_mps, double omega_radps,
                      double gyro_radps, bool distrust_gyro, double v_read_prev_mps,
                      SlipRun* run) const {
  set_gyro_rate(x, P, gyro_radps, dt_s);
  const double w_gyro = (*x)(kIomega);
  // The wheels' yaw rate after their calibration, against the gyro's.
  const double sv = (*x)(kIsv), sw = (*x)(kIsomega), bw = (*x)(kIbomega), cwv = (*x)(kIcomegav);
  const double v_true = v_mps / (1.0 + sv);
  const double w_wheels = (omega_radps - bw - cwv * v_true) / (1.0 + sw);
  const double d = w_wheels - w_gyro;
  const bool slip =
      std::abs(d) > config_.slip_yaw_rate_radps + config_.slip_yaw_rate_fraction * std::abs(w_gyro);
  const bool still = std::abs(v_mps) < config_.standstill_v_mps &&
                     std::abs(omega_radps) < config_.standstill_omega_radps;
  // One wheel off by e turns the yaw rate by e / track and the speed by e / 2, whichever wheel
  // it is. A wheel that loses grip while it drives spins (reads high); one that loses it while
  // braking locks (reads low): the speed is corrected by that half and keeps half the correction
  // as its sigma (the other case lands 4 sigma off, not unnoticed).
  const double v_prev = (*x)(kIv) * (1.0 + sv);  // the previous period, as the wheels read
  const bool braking = std::abs(v_mps) < std::abs(v_prev);
  const double away = v_mps >= 0.0 ? 1.0 : -1.0;  // towards a larger |v|
  const double spin_sign = braking ? away : -away;
  const double half_track_m = 0.5 * config_.wheel_track_mm / kMmPerM;
  double v_corr = v_mps, v_var = 0.0;
  if (slip) {
    const double half_mps = std::abs(d) * half_track_m;
    v_corr = v_mps + spin_sign * half_mps;
    v_var = 0.25 * half_mps * half_mps;
  } else {
    double d_sigma = 0.0;
    const double diff = learn_wheel_yaw(x, P, v_mps, omega_radps, /*learn=*/!still, &d_sigma);
    if (std::abs(diff) > config_.slip_noise_sigmas * d_sigma && dt_s > 0.0) {
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
        const double sn = config_.odom_v_sigma_mps, sa = config_.max_accel_mps2 * dt_s;
        const double step_mps = away * (v_mps - v_read_prev_mps);
        run->llr += 2.0 * (u_mps - run->u_mps) * step_mps / (2.0 * sn * sn + sa * sa);
        run->llr = std::clamp(run->llr, -30.0, 30.0);
      }
      run->u_mps = u_mps;
      const double p_spin = 1.0 / (1.0 + std::exp(-run->llr));
      const double noise_mps = d_sigma * half_track_m;
      const double sd_mps =
          std::sqrt(4.0 * p_spin * (1.0 - p_spin) * u_mps * u_mps + noise_mps * noise_mps);
      v_corr = v_mps - away * (2.0 * p_spin - 1.0) * u_mps;
      // A slip's speed error is the same over its periods, so over a run they add up: the run's
      // variance is (sum sd dt)^2, i.e. sd^2 + 2 A sd / dt per period after A of the run (as
      // white noise per period, a 0.3 s slip had 2 mm of sigma for its 11 mm).
      v_var = sd_mps * sd_mps + 2.0 * run->sigma_m * sd_mps / dt_s;
      run->sigma_m += sd_mps * dt_s;
    } else {
      *run = SlipRun{};
    }
  }
  update_speed(x, P, v_corr, v_var);
  if (distrust_gyro) (*P)(kIomega, kIomega) += d * d;
  if (still && !slip) {
    update_zero_rate(x, P);
    ++counters_.standstill_updates;
  }
  predict(x, P, dt_s, /*velocity_noise=*/false, /*gyro_heading=*/true);
  return slip;
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
      odom_t_ns == kNoOdom ? t0_ns : std::max(t0_ns, odom_t_ns + config_.odom_gap_ns);
  if (t1_ns <= known_end) {
    predict_known(x, P, t0_ns, t1_ns);
    return;
  }
  if (known_end > t0_ns) predict_known(x, P, t0_ns, known_end);
  // Unknown motion: the vehicle may have turned into or out of an arc at once (the yaw rate
  // jumps; added once, where the span enters the unknown part) and accelerated within its
  // limits. The mean stays the last known speed: the best guess, with a covariance that says so.
  const bool enters_unknown =
      odom_t_ns == kNoOdom ? false : t0_ns <= odom_t_ns + config_.odom_gap_ns;
  // A working gyro still knows the turn: only the speed is unknown then.
  double g = 0.0;
  const bool gyro_all = gyro_mean_hold(known_end, t1_ns, &g);
  if (enters_unknown && !gyro_all) {
    // The change may have come right after the newest sample, not only once odom_gap_ns had
    // passed: the heading then already turned by it for that long (gs). Added as one jump of
    // (heading, yaw rate) = j (gs, 1), so the prediction carries the pair forward together
    // (without the heading part an arc exit at the start of a gap stayed outside 3 sigma for
    // 0.25 s: fault row odom_gap_5s_straight).
    const double j = config_.gap_yaw_rate_change_sigma_radps;
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
  const double qa = config_.gap_accel_sigma_mps2 * config_.gap_accel_sigma_mps2;
  const double qw = config_.gap_yaw_accel_sigma_radps2 * config_.gap_yaw_accel_sigma_radps2;
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
  const double reach_mm = kMmPerM * (v0_mps * tu_s + config_.gap_accel_sigma_mps2 * tu_s * tu_s);
  const double chord = 1.0 - std::exp(-0.5 * (*P)(kItheta, kItheta));
  (*P)(kIx, kIx) += reach_mm * reach_mm * chord;
  (*P)(kIy, kIy) += reach_mm * reach_mm * chord;
}

void Ekf::apply_odometry(FilterVec* x, FilterCov* P, std::int64_t t_prev_ns, std::int64_t odom_t_ns,
                         std::int64_t t_ns, double v_mps, double omega_radps, const Event* prev,
                         Event* out) const {
  const bool instant = config_.odom_sample_timing == EkfConfig::OdomSampleTiming::kInstant;
  if (out) {
    out->gyro = false;
    out->slip = false;
    out->slip_since_ns = kNoOdom;
    out->slip_run = SlipRun{};
    out->v_read_mps = v_mps;
    out->omega_read_radps = omega_radps;
    out->hold = WheelHold{};
  }
  double g = 0.0;
  if (!is_gap(odom_t_ns, t_ns) && t_ns > t_prev_ns && gyro_mean(t_prev_ns, t_ns, &g)) {
    // The gyro carries the heading of this period, the wheels its speed. (Both timings: the
    // gyro mean is over the period itself, the speed is the period's.)
    const bool prev_slip = prev && prev->slip;
    const std::int64_t since = prev_slip ? prev->slip_since_ns : t_prev_ns;
    const bool distrust = prev_slip && t_ns - since > config_.slip_max_duration_ns;
    const double dt_s = static_cast<double>(t_ns - t_prev_ns) * kNsToS;
    SlipRun run = prev ? prev->slip_run : SlipRun{};
    const double v_read_prev = prev ? prev->v_read_mps : std::numeric_limits<double>::quiet_NaN();
    const bool slip = gyro_period(x, P, dt_s, v_mps, omega_radps, g, distrust, v_read_prev, &run);
    if (out) {
      out->gyro = true;
      out->slip = slip;
      out->slip_since_ns = slip ? since : kNoOdom;
      out->slip_run = run;
    }
    return;
  }
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
  if (prev) {
    double add_theta_var = 0.0;
    const WheelHold h =
        hold_wheel(*prev, t_ns, dt_s, v_mps, omega_radps, &v_mps, &omega_radps, &add_theta_var);
    (*P)(kItheta, kItheta) += add_theta_var;
    if (out) {
      out->hold = h;
      out->slip = h.wheel >= 0;
      out->slip_since_ns = h.wheel >= 0 ? h.since_ns : kNoOdom;
    }
  }
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

double Ekf::position_mahalanobis_sq(const FilterVec& x, const FilterCov& P,
                                    const Eigen::Vector3d& z, const Eigen::Matrix3d& R) const {
  const Eigen::Matrix2d S = P.topLeftCorner<2, 2>() + R.topLeftCorner<2, 2>();
  const Eigen::Vector2d nu = z.head<2>() - x.head<2>();
  const Eigen::LLT<Eigen::Matrix2d> llt(S);
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
// Gyro samples

std::size_t Ekf::gyro_lower_bound(std::int64_t t_ns) const {
  std::size_t lo = 0, hi = gyro_size_;
  while (lo < hi) {
    const std::size_t mid = (lo + hi) / 2;
    if (gyro_at(mid).t_ns < t_ns) {
      lo = mid + 1;
    } else {
      hi = mid;
    }
  }
  return lo;
}

bool Ekf::gyro_mean(std::int64_t t0_ns, std::int64_t t1_ns, double* mean_radps) const {
  // Sample k is the mean rate over (t_{k-1}, t_k]: the interval is covered when a sample ends at
  // or after t1, the kept sample before the first overlapping one starts at or before t0, and no
  // two consecutive samples are further apart than gyro_gap_ns.
  if (gyro_size_ < 2 || t1_ns <= t0_ns) return false;
  std::size_t k = gyro_lower_bound(t0_ns + 1);  // first sample ending after t0
  if (k == 0 || k >= gyro_size_) return false;
  double integral = 0.0;
  std::int64_t t = t0_ns;
  for (; k < gyro_size_ && t < t1_ns; ++k) {
    const GyroSample& a = gyro_at(k - 1);
    const GyroSample& b = gyro_at(k);
    // A saturated sample is kept as NaN: its interval is unknown, not the next sample's.
    if (b.t_ns - a.t_ns > config_.gyro_gap_ns || std::isnan(b.rate_radps)) return false;
    const std::int64_t end = std::min(b.t_ns, t1_ns);
    integral += b.rate_radps * static_cast<double>(end - t);
    t = end;
  }
  if (t < t1_ns) return false;
  *mean_radps = integral / static_cast<double>(t1_ns - t0_ns);
  return true;
}

bool Ekf::gyro_mean_hold(std::int64_t t0_ns, std::int64_t t1_ns, double* mean_radps) const {
  if (gyro_size_ == 0) return false;
  const GyroSample& last = gyro_at(gyro_size_ - 1);
  if (t1_ns <= last.t_ns) return gyro_mean(t0_ns, t1_ns, mean_radps);
  // A query between samples (an output tick) holds the newest rate for at most gyro_gap_ns.
  if (t1_ns - last.t_ns > config_.gyro_gap_ns || std::isnan(last.rate_radps)) return false;
  if (t0_ns >= last.t_ns) {
    *mean_radps = last.rate_radps;
    return true;
  }
  double head = 0.0;
  if (!gyro_mean(t0_ns, last.t_ns, &head)) return false;
  *mean_radps = (head * static_cast<double>(last.t_ns - t0_ns) +
                 last.rate_radps * static_cast<double>(t1_ns - last.t_ns)) /
                static_cast<double>(t1_ns - t0_ns);
  return true;
}

Ekf::WheelHold Ekf::hold_wheel(const Event& prev, std::int64_t t_ns, double dt_s, double v_mps,
                               double omega_radps, double* v_use_mps, double* omega_use_radps,
                               double* add_theta_var) const {
  *add_theta_var = 0.0;
  if (std::isnan(prev.v_read_mps) || std::isnan(prev.omega_read_radps)) return WheelHold{};
  const double half_m = 0.5 * config_.wheel_track_mm / kMmPerM;
  const double now[2] = {v_mps - omega_radps * half_m, v_mps + omega_radps * half_m};
  const double before[2] = {prev.v_read_mps - prev.omega_read_radps * half_m,
                            prev.v_read_mps + prev.omega_read_radps * half_m};
  const double step[2] = {now[0] - before[0], now[1] - before[1]};
  const double limit = config_.max_accel_mps2 * dt_s + config_.wheel_step_min_mps;
  WheelHold h = prev.hold;
  const double track_m = 2.0 * half_m;
  auto done = [&step](WheelHold r) {
    r.step_mps[0] = step[0];
    r.step_mps[1] = step[1];
    return r;
  };
  if (h.wheel >= 0) {
    const int i = h.wheel, o = 1 - i;
    if (t_ns - h.since_ns > config_.slip_max_duration_ns) {
      // Held too long for a slip: the readings are taken as they are from here. The hold may
      // have been wrong all along (a real change the wheel made alone): half its yaw-rate step
      // over the hold, as sigma.
      const double amb =
          0.5 * h.offset_mps / track_m * static_cast<double>(t_ns - h.since_ns) * kNsToS;
      *add_theta_var = amb * amb;
      return done(WheelHold{});
    }
    // Another step of the held wheel alone. Back by at least half the held step, or to within
    // half of what the slip had grown or shrunk to: the slip is over (one ending inside a period
    // steps back over two: the rest is not a new slip), and this reading is the wheel's own again.
    // The same way: the slip began inside the previous period, whose mean reading showed only part
    // of it; the rest is added to the step.
    if (std::abs(step[i]) > limit &&
        std::abs(step[o]) <= std::min(limit, 0.25 * std::abs(step[i]))) {
      // (The slip's size now, if it changed while held, is the step plus the drift below.)
      const double slip_now = h.offset_mps + h.drift_mps;
      if ((step[i] > 0.0) != (h.offset_mps > 0.0) &&
          (std::abs(step[i]) >= 0.5 * std::abs(h.offset_mps) ||
           std::abs(step[i] + slip_now) <= 0.5 * std::abs(slip_now))) {
        WheelHold released;
        released.released_ns = t_ns;
        released.released_wheel = i;
        released.released_step_mps = step[i];
        return done(released);
      }
      h.offset_mps += step[i];
    }
  } else {
    const bool releasing = h.released_ns == prev.t_ns;
    for (int i = 0; i < 2; ++i) {
      // The other wheel steady: within the limit and a quarter of this step (a turn's start or
      // end inside a period steps both wheels by about as much, opposite).
      if (releasing && i == h.released_wheel && (step[i] > 0.0) == (h.released_step_mps > 0.0))
        continue;
      if (std::abs(step[i]) > limit &&
          std::abs(step[1 - i]) <= std::min(limit, 0.25 * std::abs(step[i]))) {
        const double pre = prev.hold.step_mps[i], pre_other = prev.hold.step_mps[1 - i];
        h = WheelHold{};
        h.wheel = i;
        h.offset_mps = step[i];
        h.since_ns = prev.t_ns;
        h.diff0_mps = (now[i] - step[i]) - now[1 - i];
        // Begun inside the previous period: that period's step of this wheel, the same way and
        // beyond what the vehicle's acceleration explains (the other wheel steady), is the
        // slip's first part. The heading already took it: its yaw rate over the period as sigma.
        if ((pre > 0.0) == (step[i] > 0.0) &&
            std::abs(pre) > config_.max_accel_mps2 * dt_s + 0.5 * config_.wheel_step_min_mps &&
            std::abs(pre_other) <= 0.25 * std::abs(pre)) {
          h.offset_mps += pre;
          h.diff0_mps -= pre;
          const double missed_rad = pre / track_m * dt_s;
          h.sigma_rad = std::abs(missed_rad);
          *add_theta_var += missed_rad * missed_rad;
        }
        break;
      }
    }
    if (h.wheel < 0) return done(WheelHold{});
  }
  // Two readings of the held wheel: less the step (the slip kept its size) and the other wheel
  // plus the difference at the onset (the yaw rate kept its value). While they agree either is
  // right; where they part, the slip's size or the yaw rate changed and the wheels cannot say
  // which: the mean of the two is used, half their difference is the yaw-rate doubt, and the
  // heading sigma adds it up over the hold (a run's error adds up, it does not average out),
  // with slip_hold_sigma_fraction of the step as a floor.
  const int i = h.wheel, o = 1 - i;
  double w[2] = {now[0], now[1]};
  w[i] -= h.offset_mps;
  h.drift_mps = (w[i] - w[o]) - h.diff0_mps;
  w[i] -= 0.5 * h.drift_mps;
  *v_use_mps = 0.5 * (w[0] + w[1]);
  *omega_use_radps = (w[1] - w[0]) / track_m;
  const double doubt_radps =
      (0.5 * std::abs(h.drift_mps) + config_.slip_hold_sigma_fraction * std::abs(h.offset_mps)) /
      track_m;
  const double sigma = h.sigma_rad + doubt_radps * dt_s;
  *add_theta_var += sigma * sigma - h.sigma_rad * h.sigma_rad;
  h.sigma_rad = sigma;
  return done(h);
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
    const bool was_slip = ev->slip;
    const bool was_start = was_slip && !prev.slip;
    apply_odometry(&x, &P, prev.t_ns, odom_t, ev->t_ns, ev->v_mps, ev->omega_radps, &prev, ev);
    // Counted once per period however often it is replayed (a later gyro sample or a delayed
    // fix re-propagates it).
    const bool is_start = ev->slip && !prev.slip;
    if (ev->slip != was_slip) {
      if (ev->slip)
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
  } else {
    predict_span(&x, &P, prev.t_ns, ev->t_ns, odom_t);
    update_fix(&x, &P, ev->z, ev->R);
    carry_over_fix(prev, ev);
  }
  ev->odom_t_ns = odom_t;
  ev->x = x;
  ev->P = P;
  ev->valid = true;
}

void Ekf::carry_over_fix(const Event& prev, Event* fix) {
  // A fix measured what a slip run had integrated so far; the slip itself (its sign, its last
  // speed equivalent, a held wheel) and the newest readings go on to the next period.
  fix->slip_run = prev.slip_run;
  fix->slip_run.sigma_m = 0.0;
  fix->v_read_mps = prev.v_read_mps;
  fix->omega_read_radps = prev.omega_read_radps;
  fix->hold = prev.hold;
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
