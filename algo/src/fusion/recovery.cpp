// Ekf recovery: a pose the fixes disagree with.
//  - Kidnap: consecutive gate-rejected fixes that agree with each other (a candidate track
//    carried with the same odometry) re-initialise the filter (RecoveryConfig::kidnap_fixes).
//  - Re-localisation: a lost filter re-initialises from one precise, map-verified fix
//    (the decision is in aid_fix.cpp's gate; the reset here), or from an external pose.
//  - Unseen slip (RecoveryConfig::unseen_slip_max_rad): the path driven since the last fused
//    fix, and the test whether one heading change on it explains a gate-rejected fix.
//
// Why a turn about a point of the path: a wheel that slips for a few tenths of a second turns
// the vehicle by some degrees the odometry did not see; everything driven after it is the
// believed path turned about where the slip happened, and the next landmark measures both the
// heading change (precisely) and the position the turn moved. A misread or a wrong map entry
// has no reason to match a turn of exactly the measured heading change about a point of the
// path, so it stays refused.
#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>
#include <cmath>
#include <limits>

#include "agv/fusion/ekf.hpp"

namespace agv::fusion {

// ---------------------------------------------------------------------------------------------
// Kidnap

bool Ekf::kidnap_candidate(std::int64_t t_ns, const Eigen::Vector3d& z, const Eigen::Matrix3d& R,
                           const FilterVec& prior_x, const FilterCov& prior_P,
                           bool prior_worthless) {
  if (!extend_hypothesis(t_ns, z, R)) start_hypothesis(t_ns, z, R, prior_x, prior_P);
  // A filter whose position is unknown has no pose worth protecting: two consistent fixes of
  // separate landmarks (what makes a tag, which carries no position, trustworthy) re-initialise
  // it at once.
  const RecoveryConfig& c = config_.recovery;
  const bool enough = prior_worthless ? hyp_.count >= 2
                                      : hyp_.count >= c.kidnap_fixes &&
                                            hyp_.t_ns - hyp_.t_first_ns >= c.kidnap_min_duration_ns;
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

bool Ekf::extend_hypothesis(std::int64_t t_ns, const Eigen::Vector3d& z, const Eigen::Matrix3d& R) {
  if (!(hyp_.count > 0 && t_ns >= hyp_.t_ns && size_ > 0 && hyp_.t_ns >= at(0).t_ns)) return false;
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
  if (!(mahalanobis_sq(x, P, z, R) <= gate_threshold_)) return false;
  update_fix(&x, &P, z, R);
  hyp_.x = x;
  hyp_.P = P;
  // Fixes of one landmark (consecutive frames, or standing on it) count once, so one
  // misprinted landmark cannot hijack the pose: only fixes kidnap_min_separation_mm apart.
  if (std::hypot(z(0) - hyp_.x_count_mm, z(1) - hyp_.y_count_mm) >=
      config_.recovery.kidnap_min_separation_mm) {
    ++hyp_.count;
    hyp_.x_count_mm = z(0);
    hyp_.y_count_mm = z(1);
  }
  hyp_.t_ns = t_ns;
  return true;
}

void Ekf::start_hypothesis(std::int64_t t_ns, const Eigen::Vector3d& z, const Eigen::Matrix3d& R,
                           const FilterVec& prior_x, const FilterCov& prior_P) {
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

void Ekf::widen_calibration(FilterCov* P) const {
  auto at_least = [P](int i, double sigma) {
    const double var = sigma * sigma;
    if ((*P)(i, i) < var) (*P)(i, i) = var;  // adding to the diagonal keeps P positive
  };
  at_least(kIbg, config_.gyro.init_bias_sigma_radps);
  at_least(kIsg, config_.gyro.init_scale_sigma);
  const OdometryConfig& o = config_.odometry;
  if (o.estimate_calibration) {
    at_least(kIsv, o.init_v_scale_sigma);
    at_least(kIsomega, o.init_omega_scale_sigma);
    at_least(kIbomega, o.init_omega_bias_sigma_radps);
    at_least(kIcomegav, o.init_omega_per_v_sigma_radpm);
  }
}

// ---------------------------------------------------------------------------------------------
// Re-localisation

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

void Ekf::adopt_estimate(const Ekf& other) {
  if (&other == this) return;
  const Counters kept = counters_;
  *this = other;
  counters_ = kept;
  ++counters_.reinitialisations;
  pending_flags_ |= flags::kReinitialised;
}

// ---------------------------------------------------------------------------------------------
// Unseen slip

void Ekf::track_odometry() {
  if (size_ == 0) return;
  const Event& ev = at(size_ - 1);
  if (!ev.valid) return;
  if (track_size_ > 0 && ev.t_ns - track_[track_size_ - 1].t_ns < track_spacing_ns_) return;
  if (track_size_ == kTrackPoints) {  // thin to every other point: a long leg at half the density
    for (std::size_t i = 0; 2 * i < kTrackPoints; ++i) track_[i] = track_[2 * i];
    track_size_ = kTrackPoints / 2;
    track_spacing_ns_ *= 2;
  }
  track_[track_size_++] = {ev.t_ns, ev.x(kIx), ev.x(kIy), ev.x(kItheta), ev.x(kIv)};
}

void Ekf::track_restart(std::size_t fix_index) {
  track_size_ = 0;
  track_rb_fused_t_ns_ = std::numeric_limits<std::int64_t>::min();
  rb_slip_.count = 0;
  track_spacing_ns_ = 50'000'000;  // 50 mm at 1 m/s; 128 points cover 6.4 s before thinning
  const Event& ev = at(fix_index);
  track_[track_size_++] = {ev.t_ns, ev.x(kIx), ev.x(kIy), ev.x(kItheta), ev.x(kIv)};
  track_odometry();  // a delayed fix: the newest state as well
}

bool Ekf::unseen_slip_possible() const {
  if (!(config_.recovery.unseen_slip_max_rad > 0.0) || track_size_ == 0) return false;
  // A gyro that reported since the last fix saw every turn: a heading it disagrees with is the
  // gyro's fault (a bias step), for the kidnap rule, which widens its calibration.
  return !(gyro_size_ > 0 && gyro_at(gyro_size_ - 1).t_ns >= track_[0].t_ns);
}

Ekf::UnseenTurn Ekf::unseen_turn(const TrackPoint& tp, const Eigen::Vector2d& p,
                                 double dth_rad) const {
  // One wheel's unseen extra distance e turns the vehicle by e / track and moves it e / 2 along
  // its direction. A slip lasting up to slip_max_duration_ns spreads the turn over that stretch;
  // to first order that is a turn at its middle, and a quarter of the stretch times the turn
  // covers the rest and the spacing of the path's points.
  UnseenTurn turn;
  const double c = std::cos(dth_rad), s = std::sin(dth_rad);
  const Eigen::Vector2d lever = p - Eigen::Vector2d(tp.x_mm, tp.y_mm);
  turn.q =
      Eigen::Vector2d((c - 1.0) * lever.x() - s * lever.y(), s * lever.x() + (c - 1.0) * lever.y());
  turn.u = Eigen::Vector2d(std::cos(tp.theta_rad), std::sin(tp.theta_rad));
  turn.along_mm = 0.5 * config_.slip.wheel_track_mm * std::abs(dth_rad);
  turn.smear_mm = std::abs(dth_rad) * 0.25 * static_cast<double>(config_.slip.max_duration_ns) *
                  1e-9 * std::abs(tp.v_mps) * 1000.0;
  return turn;
}

void Ekf::add_unseen_turn(const UnseenTurn& turn, double dth_rad, FilterCov* P) const {
  // The position moves along the chord (exact for this size, not the tangent).
  Eigen::Matrix<double, 3, 2> J;
  J.col(0) << turn.q.x() / dth_rad, turn.q.y() / dth_rad, 1.0;
  J.col(1) << turn.u.x(), turn.u.y(), 0.0;
  const Eigen::Vector2d q_var(dth_rad * dth_rad, turn.along_mm * turn.along_mm);
  P->topLeftCorner<3, 3>() += J * q_var.asDiagonal() * J.transpose();
  (*P)(kIx, kIx) += turn.smear_mm * turn.smear_mm;
  (*P)(kIy, kIy) += turn.smear_mm * turn.smear_mm;
}

bool Ekf::explain_unseen_slip(std::int64_t t_ns, const Eigen::Vector3d& z, const Eigen::Matrix3d& R,
                              const FilterVec& x, FilterCov* P) const {
  if (!unseen_slip_possible()) return false;
  const double dth = wrap_angle_rad(z(2) - x(kItheta));
  const double var_th = (*P)(kItheta, kItheta) + R(2, 2);
  // Only a heading change the prior cannot explain, and not beyond what a slip turns.
  if (std::abs(dth) > config_.recovery.unseen_slip_max_rad || dth * dth <= 9.0 * var_th)
    return false;
  const Eigen::Vector2d p(x(kIx), x(kIy));
  const Eigen::Vector2d nu = z.head<2>() - p;
  const Eigen::Matrix2d S0 = P->topLeftCorner<2, 2>() + R.topLeftCorner<2, 2>();
  double best_d2 = std::numeric_limits<double>::infinity();
  UnseenTurn best;
  for (std::size_t j = 0; j < track_size_; ++j) {
    const TrackPoint& tp = track_[j];
    if (tp.t_ns > t_ns) break;
    const UnseenTurn turn = unseen_turn(tp, p, dth);
    const Eigen::Matrix2d S = S0 + turn.along_mm * turn.along_mm * turn.u * turn.u.transpose() +
                              turn.smear_mm * turn.smear_mm * Eigen::Matrix2d::Identity();
    // The turn's own displacement must be beyond what the prior and the hypothesis' own slack
    // explain: a heading change with the position where the prior has it (a turn right at the
    // landmark) cannot be told from a heading misread of the landmark, and stays refused.
    const auto S_ldlt = S.ldlt();
    if (!(turn.q.dot(S_ldlt.solve(turn.q)) > gate_threshold_2d_)) continue;
    const Eigen::Vector2d r = nu - turn.q;
    const double d2 = r.dot(S_ldlt.solve(r));
    if (d2 < best_d2) {
      best_d2 = d2;
      best = turn;
    }
  }
  if (!(best_d2 <= gate_threshold_2d_)) return false;
  add_unseen_turn(best, dth, P);
  return true;
}

}  // namespace agv::fusion
