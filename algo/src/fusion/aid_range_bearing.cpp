// Ekf aid: range and bearing to a surveyed landmark from a sensor on the vehicle (a forward or
// side camera reading a tag on a rack or a wall; agv/fusion/range_bearing.hpp). The measurement
// model goes from the vehicle state (x, y, theta) through the sensor's mount:
//   s = p + Rot(theta) m                      the sensor in the site frame (m: its mount)
//   d = l - s                                 sensor -> landmark, site frame
//   h(x) = (|d|, atan2(d_y, d_x) - theta - psi)   psi: the sensor's yaw on the vehicle
// Gated with chi-square (2 dof) against the prior at the exposure and fused there; a late
// observation is fused through the history replay, as a delayed fix is. It never initialises or
// re-localises the filter: a range and a bearing leave the pose underdetermined, and a gate
// against a prior is its only protection from a misread or a moved landmark.
#include <Eigen/Cholesky>
#include <cmath>

#include "agv/fusion/ekf.hpp"
#include "ekf_internal.hpp"

namespace agv::fusion {

namespace {

// Below this predicted range the bearing is undefined (the landmark at the sensor).
constexpr double kMinRangeMm = 1.0;

struct RangeBearingModel {
  detail::MeasRow<2> H = detail::MeasRow<2>::Zero();
  Eigen::Vector2d nu = Eigen::Vector2d::Zero();  // innovation, bearing wrapped
};

// h(x), its Jacobian and the innovation at x; false when the landmark is predicted at the sensor.
bool range_bearing_model(const FilterVec& x, const RangeBearingObs& obs, RangeBearingModel* m) {
  const double th = x(kItheta);
  const double c = std::cos(th), s = std::sin(th);
  // The sensor's offset from the reference point, site frame.
  const double ox = c * obs.sensor_xy_mm.x() - s * obs.sensor_xy_mm.y();
  const double oy = s * obs.sensor_xy_mm.x() + c * obs.sensor_xy_mm.y();
  const double dx = obs.landmark_xy_mm.x() - (x(kIx) + ox);
  const double dy = obs.landmark_xy_mm.y() - (x(kIy) + oy);
  const double r2 = dx * dx + dy * dy;
  const double r = std::sqrt(r2);
  if (!(r >= kMinRangeMm)) return false;
  const double bearing = wrap_angle_rad(std::atan2(dy, dx) - th - obs.sensor_yaw_rad);
  // d(sensor)/d(theta) = (-oy, ox): turning the vehicle swings the sensor about the reference
  // point, which moves both the range and the bearing.
  m->H(0, kIx) = -dx / r;
  m->H(0, kIy) = -dy / r;
  m->H(0, kItheta) = (dx * oy - dy * ox) / r;
  m->H(1, kIx) = dy / r2;
  m->H(1, kIy) = -dx / r2;
  m->H(1, kItheta) = -(dx * ox + dy * oy) / r2 - 1.0;
  m->nu(0) = obs.range_mm - r;
  m->nu(1) = wrap_angle_rad(obs.bearing_rad - bearing);
  return true;
}

bool valid_observation(const RangeBearingObs& obs) {
  if (!obs.landmark_xy_mm.allFinite() || !obs.sensor_xy_mm.allFinite() ||
      !std::isfinite(obs.sensor_yaw_rad) || !std::isfinite(obs.range_mm) ||
      !std::isfinite(obs.bearing_rad) || !obs.R.allFinite())
    return false;
  if (!(obs.range_mm > 0.0)) return false;
  const double scale = obs.R.cwiseAbs().maxCoeff();
  if (!(std::abs(obs.R(0, 1) - obs.R(1, 0)) <= 1e-9 * scale)) return false;
  return obs.R(0, 0) > 0.0 && obs.R(1, 1) > 0.0 &&
         obs.R(0, 0) * obs.R(1, 1) - obs.R(0, 1) * obs.R(1, 0) > 0.0;
}

}  // namespace

FixOutcome Ekf::reject_range_bearing_invalid() {
  ++counters_.range_bearing_rejected_invalid;
  return FixOutcome::kRejectedInvalid;
}

FixOutcome Ekf::reject_range_bearing_too_old() {
  ++counters_.range_bearing_rejected_too_old;
  return FixOutcome::kRejectedTooOld;
}

void Ekf::update_range_bearing(FilterVec* x, FilterCov* P, const RangeBearingObs& obs) const {
  RangeBearingModel m;
  if (!range_bearing_model(*x, obs, &m)) return;  // replayed onto a prior at the landmark
  detail::joseph_update<2>(x, P, m.H, m.nu, obs.R);
  (*x)(kItheta) = wrap_angle_rad((*x)(kItheta));
}

FixOutcome Ekf::add_range_bearing(std::int64_t t_exposure_ns, const RangeBearingObs& obs) {
  const std::int64_t t_ns = t_exposure_ns;
  if (!valid_observation(obs)) return reject_range_bearing_invalid();
  if (!initialised_) {
    ++counters_.range_bearing_rejected_not_initialised;
    return FixOutcome::kRejectedNotTracking;
  }
  std::int64_t newest_t = 0;
  if (newest_time(&newest_t) && newest_t - t_ns > config_.range_bearing.max_delay_ns)
    return reject_range_bearing_too_old();
  if (t_ns < t_init_ns_) return reject_range_bearing_too_old();
  const long k = find_last_at_or_before(t_ns);
  if (k < 0 || !at(static_cast<std::size_t>(k)).valid) return reject_range_bearing_too_old();

  // Prior at the exposure, the observation's effective covariance, the gate.
  const Event& base = at(static_cast<std::size_t>(k));
  FilterVec x = base.x;
  FilterCov P = base.P;
  predict_span(&x, &P, base.t_ns, t_ns, odom_time_after(base));
  RangeBearingObs eff = obs;
  const RangeBearingConfig& c = config_.range_bearing;
  eff.R(0, 0) += c.range_floor_sigma_mm * c.range_floor_sigma_mm;
  eff.R(1, 1) += c.bearing_floor_sigma_rad * c.bearing_floor_sigma_rad;
  RangeBearingModel m;
  if (!range_bearing_model(x, eff, &m)) return reject_range_bearing_invalid();
  if (!(detail::mahalanobis_sq<2>(P, m.H, m.nu, eff.R) <= range_bearing_threshold_)) {
    ++counters_.range_bearing_rejected_gate;
    return FixOutcome::kRejectedGate;
  }

  // Fuse at the exposure and re-propagate newer events.
  detail::joseph_update<2>(&x, &P, m.H, m.nu, eff.R);
  x(kItheta) = wrap_angle_rad(x(kItheta));
  Event ev;
  ev.t_ns = t_ns;
  ev.kind = EventKind::kRangeBearing;
  ev.rb = eff;
  ev.valid = true;
  ev.x = x;
  ev.P = P;
  ev.odom_t_ns = odom_time_after(base);
  ev.slip = SlipState::after_measurement(base.slip);
  bool delayed = false;
  insert_measurement(ev, &delayed);
  ++counters_.range_bearing_fused;
  if (delayed) ++counters_.range_bearing_delayed;
  return FixOutcome::kFused;
}

}  // namespace agv::fusion
