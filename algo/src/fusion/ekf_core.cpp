// Ekf core: construction, the prediction step, the time-ordered event history and its replay.
// The aid sources: aid_odometry.cpp, aid_gyro.cpp, aid_wheel_slip.cpp, aid_fix.cpp,
// aid_range_bearing.cpp; recovery.cpp (kidnap, re-localisation, unseen slip); health.cpp.
#include <cmath>
#include <limits>
#include <stdexcept>
#include <utility>

#include "agv/fusion/chi2.hpp"
#include "agv/fusion/ekf.hpp"
#include "ekf_internal.hpp"

namespace agv::fusion {

using detail::symmetrize;

Ekf::Ekf(const EkfConfig& config)
    : config_(config), last_fix_d2_(std::numeric_limits<double>::quiet_NaN()) {
  const std::string err = validate(config_);
  if (!err.empty()) throw std::invalid_argument("EkfConfig: " + err);
  gate_threshold_ = chi2_3dof_quantile(config_.fix.gate_probability);
  gate_threshold_2d_ = chi2_2dof_quantile(config_.fix.gate_probability);
  range_bearing_threshold_ = chi2_2dof_quantile(config_.range_bearing.gate_probability);
  history_.resize(config_.core.history_capacity);  // the only allocations; never resized later
  held_.resize(config_.fix.held_capacity);
  gyro_.resize(config_.gyro.capacity);
}

// ---------------------------------------------------------------------------------------------
// Prediction

void Ekf::add_velocity_noise(FilterCov* P, double dt_s) const {
  const double adt = std::abs(dt_s);
  (*P)(kIv, kIv) += config_.core.accel_sigma_mps2 * config_.core.accel_sigma_mps2 * adt;
  (*P)(kIomega, kIomega) +=
      config_.core.yaw_accel_sigma_radps2 * config_.core.yaw_accel_sigma_radps2 * adt;
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
  const CoreConfig& c = config_.core;

  // Position noise is defined along/across the direction of travel (mid-step heading).
  const double th_mid = th + 0.5 * w * dt_s;
  const double cs = std::cos(th_mid), s = std::sin(th_mid);
  const double qa = c.along_track_sigma_mm_per_sqrt_m * c.along_track_sigma_mm_per_sqrt_m * dist_m;
  const double qc = c.cross_track_sigma_mm_per_sqrt_m * c.cross_track_sigma_mm_per_sqrt_m * dist_m;
  FilterCov Q = FilterCov::Zero();
  Q(kIx, kIx) = cs * cs * qa + s * s * qc;
  Q(kIy, kIy) = s * s * qa + cs * cs * qc;
  Q(kIx, kIy) = Q(kIy, kIx) = cs * s * (qa - qc);
  const double hd = c.heading_sigma_rad_per_sqrt_m;
  const double hdr = c.heading_drift_sigma_rad_per_sqrt_s;
  const double ht = c.turn_heading_sigma_rad_per_sqrt_rad;
  // With the gyro the heading noise is the gyro's: its rate noise (set with omega) and its
  // calibration states. The wheel terms model the wheels' heading errors.
  if (!gyro_heading) Q(kItheta, kItheta) = hd * hd * dist_m + hdr * hdr * adt + ht * ht * turn_rad;
  const GyroConfig& g = config_.gyro;
  Q(kIbg, kIbg) = g.bias_sigma_radps_per_sqrt_s * g.bias_sigma_radps_per_sqrt_s * adt;
  Q(kIsg, kIsg) = g.scale_sigma_per_sqrt_s * g.scale_sigma_per_sqrt_s * adt;
  const OdometryConfig& o = config_.odometry;
  if (o.estimate_calibration) {
    Q(kIsv, kIsv) = o.v_scale_sigma_per_sqrt_s * o.v_scale_sigma_per_sqrt_s * adt;
    Q(kIsomega, kIsomega) = o.omega_scale_sigma_per_sqrt_s * o.omega_scale_sigma_per_sqrt_s * adt;
    Q(kIbomega, kIbomega) =
        o.omega_bias_sigma_radps_per_sqrt_s * o.omega_bias_sigma_radps_per_sqrt_s * adt;
    Q(kIcomegav, kIcomegav) =
        o.omega_per_v_sigma_radpm_per_sqrt_s * o.omega_per_v_sigma_radpm_per_sqrt_s * adt;
  }

  x->head<5>() = motion_predict(x->head<5>(), dt_s);
  *P = F * (*P) * F.transpose() + Q;
  symmetrize(P);
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

bool Ekf::newest_time(std::int64_t* t_ns) const {
  bool have = false;
  if (size_ > 0) {
    *t_ns = at(size_ - 1).t_ns;
    have = true;
  }
  if (have_odom_ && (!have || last_odom_t_ns_ > *t_ns)) {
    *t_ns = last_odom_t_ns_;
    have = true;
  }
  return have;
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

void Ekf::update_measurement(const Event& ev, FilterVec* x, FilterCov* P) const {
  if (ev.kind == EventKind::kFix) {
    update_fix(x, P, ev.z, ev.R);
  } else if (ev.kind == EventKind::kRangeBearing) {
    update_range_bearing(x, P, ev.rb);
  }
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
    const bool was_slip = ev->slip.slipping;
    const bool was_start = was_slip && !prev.slip.slipping;
    apply_odometry(&x, &P, prev.t_ns, odom_t, ev->t_ns, ev->v_mps, ev->omega_radps, &prev, ev);
    count_slip(prev, was_slip, was_start, *ev);
  } else {
    predict_span(&x, &P, prev.t_ns, ev->t_ns, odom_t);
    update_measurement(*ev, &x, &P);
    ev->slip = SlipState::after_measurement(prev.slip);
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

std::size_t Ekf::insert_measurement(const Event& ev, bool* delayed) {
  const std::size_t i = insert_event(ev);
  *delayed = i + 1 < size_;
  replay_from(i + 1);
  counters_.events_replayed += size_ - i - 1;
  return i;
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
  rb_repeated_floor_.setZero();
  t_init_ns_ = t_ns;
  have_fix_ = true;
  last_fix_t_ns_ = t_ns;
  hyp_.count = 0;
}

}  // namespace agv::fusion
