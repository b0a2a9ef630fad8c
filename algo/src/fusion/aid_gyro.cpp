// Ekf aid: the gyro (docs/design/fusion.md, "Gyro"). Its samples, kept in a time-ordered ring,
// carry the heading over every odometry period they cover; the wheels keep the speed and are
// compared with the gyro for slips (aid_wheel_slip.cpp). Standing still teaches its bias.
#include <algorithm>
#include <cmath>
#include <limits>

#include "agv/fusion/ekf.hpp"
#include "ekf_internal.hpp"

namespace agv::fusion {

using detail::kNsToS;
using detail::symmetrize;

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
  const bool saturated = std::abs(gyro_z_radps) >= config_.gyro.saturation_radps;
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

// ---------------------------------------------------------------------------------------------
// Samples

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
  // two consecutive samples are further apart than gap_ns.
  if (gyro_size_ < 2 || t1_ns <= t0_ns) return false;
  std::size_t k = gyro_lower_bound(t0_ns + 1);  // first sample ending after t0
  if (k == 0 || k >= gyro_size_) return false;
  double integral = 0.0;
  std::int64_t t = t0_ns;
  for (; k < gyro_size_ && t < t1_ns; ++k) {
    const GyroSample& a = gyro_at(k - 1);
    const GyroSample& b = gyro_at(k);
    // A saturated sample is kept as NaN: its interval is unknown, not the next sample's.
    if (b.t_ns - a.t_ns > config_.gyro.gap_ns || std::isnan(b.rate_radps)) return false;
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
  // A query between samples (an output tick) holds the newest rate for at most gap_ns.
  if (t1_ns - last.t_ns > config_.gyro.gap_ns || std::isnan(last.rate_radps)) return false;
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

// ---------------------------------------------------------------------------------------------
// Filter steps

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
  const double n = config_.gyro.noise_density_radps_per_sqrt_hz / (1.0 + sg);
  Pn(kIomega, kIomega) += n * n / std::max(dt_s, 1e-4);
  *P = Pn;
  symmetrize(P);
  (*x)(kIomega) = w;
}

void Ekf::update_zero_rate(FilterVec* x, FilterCov* P) const {
  // z = 0 = omega: through omega's correlation with b_g (set_gyro_rate) this is the gyro's
  // reading of its own bias.
  const double r =
      config_.gyro.standstill_omega_sigma_radps * config_.gyro.standstill_omega_sigma_radps;
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

void Ekf::apply_gyro_period(FilterVec* x, FilterCov* P, std::int64_t t_prev_ns, std::int64_t t_ns,
                            double v_mps, double omega_radps, double g, const Event* prev,
                            Event* out) const {
  // The gyro carries the heading of this period, the wheels its speed. (Both timings: the gyro
  // mean is over the period itself, the speed is the period's.)
  const bool prev_slip = prev && prev->slip.slipping;
  const std::int64_t since = prev_slip ? prev->slip.since_ns : t_prev_ns;
  const bool distrust = prev_slip && t_ns - since > config_.slip.max_duration_ns;
  const double dt_s = static_cast<double>(t_ns - t_prev_ns) * kNsToS;
  SlipRun run = prev ? prev->slip.run : SlipRun{};
  const double v_read_prev =
      prev ? prev->slip.v_read_mps : std::numeric_limits<double>::quiet_NaN();
  const bool slip = gyro_period(x, P, dt_s, v_mps, omega_radps, g, distrust, v_read_prev, &run);
  if (out) {
    out->gyro = true;
    out->slip.slipping = slip;
    out->slip.since_ns = slip ? since : kNoOdom;
    out->slip.run = run;
  }
}

bool Ekf::gyro_period(FilterVec* x, FilterCov* P, double dt_s, double v_mps, double omega_radps,
                      double gyro_radps, bool distrust_gyro, double v_read_prev_mps,
                      SlipRun* run) const {
  set_gyro_rate(x, P, gyro_radps, dt_s);
  const bool still = std::abs(v_mps) < config_.gyro.standstill_v_mps &&
                     std::abs(omega_radps) < config_.gyro.standstill_omega_radps;
  const GyroSlip s =
      wheels_against_gyro(x, P, dt_s, v_mps, omega_radps, still, v_read_prev_mps, run);
  update_speed(x, P, s.v_mps, s.v_var);
  // A disagreement that lasts longer than a slip: the gyro itself is in doubt.
  if (distrust_gyro) (*P)(kIomega, kIomega) += s.d_radps * s.d_radps;
  if (still && !s.slip) {
    update_zero_rate(x, P);
    ++counters_.standstill_updates;
  }
  predict(x, P, dt_s, /*velocity_noise=*/false, /*gyro_heading=*/true);
  return s.slip;
}

}  // namespace agv::fusion
