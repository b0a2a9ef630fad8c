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
// Wheels only, a gated observation may be explained by a heading change the wheels did not see
// (the floor fixes' unseen-slip rule, recovery.cpp): one range and bearing fit such a change
// about nearly any point of the path, so it takes a second consecutive gated observation, at
// another exposure, of another landmark and with no observation or fix fused between, that the
// same change explains; the second is then fused with the change's uncertainty added. A wrong
// map entry never gets there alone: seen among correct landmarks, they are fused between; seen
// alone frame after frame, it is always the same landmark.
#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>
#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <limits>

#include "agv/fusion/ekf.hpp"
#include "ekf_internal.hpp"

namespace agv::fusion {

namespace {

// Below this predicted range the bearing is undefined (the landmark at the sensor).
constexpr double kMinRangeMm = 1.0;

struct RangeBearingModel {
  detail::MeasRow<2> H = detail::MeasRow<2>::Zero();
  Eigen::Vector2d nu = Eigen::Vector2d::Zero();  // innovation, bearing wrapped
  double range_mm = 0.0;                         // predicted
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
  m->range_mm = r;
  m->nu(0) = obs.range_mm - r;
  m->nu(1) = wrap_angle_rad(obs.bearing_rad - bearing);
  return true;
}

// Part of what the range floor stands for is common to all frames of a landmark, and of the
// landmarks on one face (its map position against the print, the mount's calibration, the pose
// solver's bias at a distance): frames fused as independent would locate the vehicle along the
// line of sight better than any of them can. The position variance along the sight is kept at
// least at this share of the floor's; the state is not touched.
constexpr double kCommonFloorShare = 0.5;

void keep_floor_along_sight(const RangeBearingModel& m, double range_floor_mm, FilterCov* P) {
  const double floor_mm = kCommonFloorShare * range_floor_mm;
  const Eigen::Vector2d u(-m.H(0, kIx), -m.H(0, kIy));  // unit, sensor towards the landmark
  const double add = floor_mm * floor_mm - u.dot(P->block<2, 2>(kIx, kIx) * u);
  if (add > 0.0) P->block<2, 2>(kIx, kIx) += add * u * u.transpose();
}

// The position covariance an observation's repeated share (RangeBearingObs::R_systematic) alone
// leaves: its range share along the line of sight, its bearing share times the range squared
// across it.
Eigen::Matrix2d repeated_floor(const RangeBearingModel& m, const Eigen::Matrix2d& R_systematic) {
  const Eigen::Vector2d u(-m.H(0, kIx), -m.H(0, kIy));
  const Eigen::Vector2d across(-u.y(), u.x());
  return R_systematic(0, 0) * u * u.transpose() +
         R_systematic(1, 1) * m.range_mm * m.range_mm * across * across.transpose();
}

// The positive semi-definite part of a symmetric 2x2 matrix.
Eigen::Matrix2d psd_part(const Eigen::Matrix2d& M) {
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix2d> eig(0.5 * (M + M.transpose()));
  if (eig.info() != Eigen::Success) return Eigen::Matrix2d::Zero();
  const Eigen::Vector2d l = eig.eigenvalues().cwiseMax(0.0);
  return eig.eigenvectors() * l.asDiagonal() * eig.eigenvectors().transpose();
}

// The sensor's yaw error is common to all its bearings (RangeBearingObs::common_bearing_sigma_rad):
// an update never takes the heading variance below the smaller of its prior and that error's.
void keep_heading_floor(double prior_var_rad2, double common_sigma_rad, FilterCov* P) {
  const double floor = std::min(prior_var_rad2, common_sigma_rad * common_sigma_rad);
  if ((*P)(kItheta, kItheta) < floor) (*P)(kItheta, kItheta) = floor;
}

bool valid_observation(const RangeBearingObs& obs) {
  if (!std::isfinite(obs.common_bearing_sigma_rad) || obs.common_bearing_sigma_rad < 0.0)
    return false;
  if (!obs.landmark_xy_mm.allFinite() || !obs.sensor_xy_mm.allFinite() ||
      !std::isfinite(obs.sensor_yaw_rad) || !std::isfinite(obs.range_mm) ||
      !std::isfinite(obs.bearing_rad) || !obs.R.allFinite())
    return false;
  if (!(obs.range_mm > 0.0)) return false;
  const Eigen::Matrix2d& S = obs.R_systematic;
  if (!S.allFinite() || !(S(0, 0) >= 0.0 && S(1, 1) >= 0.0) || S(0, 0) > obs.R(0, 0) ||
      S(1, 1) > obs.R(1, 1) || S(0, 0) * S(1, 1) < S(0, 1) * S(1, 0))
    return false;
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
  const double prior_heading_var = (*P)(kItheta, kItheta);
  detail::joseph_update<2>(x, P, m.H, m.nu, obs.R);
  keep_floor_along_sight(m, config_.range_bearing.range_floor_sigma_mm, P);
  keep_heading_floor(prior_heading_var, obs.common_bearing_sigma_rad, P);
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
  if (!(detail::mahalanobis_sq<2>(P, m.H, m.nu, eff.R) <= range_bearing_threshold_) &&
      !range_bearing_unseen_slip(t_ns, eff, x, &P)) {
    ++counters_.range_bearing_rejected_gate;
    return FixOutcome::kRejectedGate;
  }
  rb_slip_.count = 0;
  track_rb_fused_t_ns_ = std::max(track_rb_fused_t_ns_, t_ns);

  // Fuse at the exposure and re-propagate newer events.
  const double prior_heading_var = P(kItheta, kItheta);
  detail::joseph_update<2>(&x, &P, m.H, m.nu, eff.R);
  keep_floor_along_sight(m, c.range_floor_sigma_mm, &P);
  if (!obs.R_systematic.isZero(0.0))
    rb_repeated_floor_ += psd_part(repeated_floor(m, obs.R_systematic) - rb_repeated_floor_);
  keep_heading_floor(prior_heading_var, eff.common_bearing_sigma_rad, &P);
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

// ---------------------------------------------------------------------------------------------
// Unseen slip

namespace {

// Two observations explaining the same unseen slip are at most this far apart: a slip
// lasts tenths of a second, and the camera sees a landmark several times a second.
constexpr std::int64_t kRbSlipWindowNs = 1'000'000'000;

// Gauss-Newton on the one unknown, the heading change, from dth (innovations whitened by L0);
// turned(dth, &m): the observation's model at the state turned by dth, false at the landmark.
template <class Turned>
double fit_turn(const Turned& turned, const Eigen::LLT<Eigen::Matrix2d>& L0, double dth) {
  constexpr double kStepRad = 1e-6;
  for (int it = 0; it < 4; ++it) {
    RangeBearingModel m, m1;
    if (!turned(dth, &m) || !turned(dth + kStepRad, &m1)) break;
    const Eigen::Vector2d r = L0.matrixL().solve(m.nu);
    const Eigen::Vector2d g = (L0.matrixL().solve(m1.nu) - r) / kStepRad;
    if (!(g.squaredNorm() > 0.0)) break;
    dth -= g.dot(r) / g.squaredNorm();
  }
  return dth;
}

}  // namespace

bool Ekf::explain_unseen_slip(std::int64_t t_ns, const RangeBearingObs& obs, const FilterVec& x,
                              FilterCov* P, double* dth_rad) const {
  if (!unseen_slip_possible()) return false;
  RangeBearingModel m0;
  if (!range_bearing_model(x, obs, &m0)) return false;
  const Eigen::Matrix2d S0 = m0.H * *P * m0.H.transpose() + obs.R;
  const Eigen::LLT<Eigen::Matrix2d> L0(S0);
  if (L0.info() != Eigen::Success) return false;
  const Eigen::Vector2d p(x(kIx), x(kIy));
  // The observation at the state turned by dth about tp (false at the landmark).
  auto turned = [&](const TrackPoint& tp, double dth, RangeBearingModel* m, UnseenTurn* turn) {
    *turn = unseen_turn(tp, p, dth);
    FilterVec xt = x;
    xt(kIx) += turn->q.x();
    xt(kIy) += turn->q.y();
    xt(kItheta) = wrap_angle_rad(x(kItheta) + dth);
    return range_bearing_model(xt, obs, m);
  };
  // Turn points: the path since the last fused observation (the heading was confirmed there),
  // and the exposure itself.
  const TrackPoint here{t_ns, x(kIx), x(kIy), x(kItheta), x(kIv)};
  double best_d2 = std::numeric_limits<double>::infinity(), best_dth = 0.0;
  UnseenTurn best;
  for (std::size_t j = 0; j <= track_size_; ++j) {
    const TrackPoint& tp = j < track_size_ ? track_[j] : here;
    if (tp.t_ns > t_ns || tp.t_ns + track_spacing_ns_ < track_rb_fused_t_ns_) continue;
    // A turn by dth lowers the bearing by about dth: the fit starts from its innovation.
    UnseenTurn turn;
    const auto at_tp = [&](double d, RangeBearingModel* m) { return turned(tp, d, m, &turn); };
    const double dth = fit_turn(at_tp, L0, -m0.nu(1));
    RangeBearingModel m;
    if (!turned(tp, dth, &m, &turn)) continue;
    const auto Hp = m.H.leftCols<2>();
    const Eigen::Matrix2d slack = turn.along_mm * turn.along_mm * turn.u * turn.u.transpose() +
                                  turn.smear_mm * turn.smear_mm * Eigen::Matrix2d::Identity();
    const Eigen::Matrix2d S = m.H * *P * m.H.transpose() + obs.R + Hp * slack * Hp.transpose();
    const double d2 = m.nu.dot(S.ldlt().solve(m.nu));
    if (d2 < best_d2) {
      best_d2 = d2;
      best_dth = dth;
      best = turn;
    }
  }
  // Only a heading change the prior cannot explain, and not beyond what a slip turns.
  const double var_th = (*P)(kItheta, kItheta) + obs.R(1, 1);
  if (!(best_d2 <= range_bearing_threshold_) ||
      std::abs(best_dth) > config_.recovery.unseen_slip_max_rad ||
      best_dth * best_dth <= 9.0 * var_th)
    return false;
  FilterCov P_slip = *P;
  add_unseen_turn(best, best_dth, &P_slip);
  if (!(detail::mahalanobis_sq<2>(P_slip, m0.H, m0.nu, obs.R) <= range_bearing_threshold_))
    return false;
  *P = P_slip;
  *dth_rad = best_dth;
  return true;
}

bool Ekf::range_bearing_unseen_slip(std::int64_t t_ns, const RangeBearingObs& obs,
                                    const FilterVec& x, FilterCov* P) {
  FilterCov P_slip = *P;
  double dth = 0.0;
  if (!explain_unseen_slip(t_ns, obs, x, &P_slip, &dth)) {
    rb_slip_.count = 0;
    return false;
  }
  // The change is known to about the bearing's and the prior heading's sigma, per observation.
  const double tol_rad = 3.0 * std::sqrt(2.0 * ((*P)(kItheta, kItheta) + obs.R(1, 1)));
  RbSlipCandidate& c = rb_slip_;
  const bool agrees = c.count > 0 && std::llabs(t_ns - c.t_ns) <= kRbSlipWindowNs &&
                      std::abs(wrap_angle_rad(dth - c.dth_rad)) <= std::max(tol_rad, c.tol_rad);
  // Another landmark (as the kidnap rule counts fixes): one wrong map entry, seen alone frame
  // after frame, fits a heading change every time and must not confirm itself.
  const bool other_landmark =
      (obs.landmark_xy_mm - c.landmark_xy_mm).norm() >= config_.recovery.kidnap_min_separation_mm;
  // Until confirmed, the change is reported (estimate_at) but not fused: one landmark fits a
  // turn almost always, a wrong map entry included, and the state must not follow it.
  RbSlipCandidate fresh;
  fresh.count = 1;
  fresh.t_ns = t_ns;
  fresh.dth_rad = dth;
  fresh.tol_rad = tol_rad;
  fresh.landmark_xy_mm = obs.landmark_xy_mm;
  fresh.turn_cov = (P_slip - *P).topLeftCorner<3, 3>();
  fresh.p_mm = Eigen::Vector2d(x(kIx), x(kIy));
  if (!agrees) {
    c = fresh;
    return false;
  }
  // The same frame's landmarks are the localizer's (its re-localisation from a frame's fix).
  if (!other_landmark || t_ns == c.t_ns) {
    if (!other_landmark && t_ns != c.t_ns) c = fresh;
    return false;
  }
  c.count = 0;
  *P = P_slip;
  ++counters_.range_bearing_unseen_slips;
  pending_flags_ |= flags::kWheelSlip;
  return true;
}

Eigen::Matrix2d Ekf::repeated_share_excess(const Eigen::Matrix2d& P_xy) const {
  if (rb_repeated_floor_.isZero(0.0)) return Eigen::Matrix2d::Zero();
  return psd_part(rb_repeated_floor_ - P_xy);
}

Eigen::Matrix3d Ekf::unconfirmed_slip_cov(std::int64_t t_ns, const Eigen::Vector2d& p_mm) const {
  const RbSlipCandidate& c = rb_slip_;
  if (!initialised_ || c.count == 0 || t_ns < c.t_ns || t_ns - c.t_ns > kRbSlipWindowNs)
    return Eigen::Matrix3d::Zero();
  // The heading's share moves the position as the vehicle drives on from the exposure.
  Eigen::Matrix3d F = Eigen::Matrix3d::Identity();
  F(0, 2) = -(p_mm.y() - c.p_mm.y());
  F(1, 2) = p_mm.x() - c.p_mm.x();
  return F * c.turn_cov * F.transpose();
}

}  // namespace agv::fusion
