// A slip the wheels did not show (EkfConfig::unseen_slip_max_rad): the path driven since the
// last fused fix, and the test whether one heading change on it explains a gate-rejected fix.
//
// Why a turn about a point of the path: a wheel that slips for a few tenths of a second turns
// the vehicle by some degrees the odometry did not see; everything driven after it is the
// believed path turned about where the slip happened, and the next landmark measures both the
// heading change (precisely) and the position the turn moved. A misread or a wrong map entry
// has no reason to match a turn of exactly the measured heading change about a point of the
// path, so it stays refused.
#include <Eigen/Cholesky>
#include <cmath>
#include <limits>

#include "agv/fusion/ekf.hpp"

namespace agv::fusion {

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
  track_spacing_ns_ = 50'000'000;  // 50 mm at 1 m/s; 128 points cover 6.4 s before thinning
  const Event& ev = at(fix_index);
  track_[track_size_++] = {ev.t_ns, ev.x(kIx), ev.x(kIy), ev.x(kItheta), ev.x(kIv)};
  track_odometry();  // a delayed fix: the newest state as well
}

bool Ekf::explain_unseen_slip(std::int64_t t_ns, const Eigen::Vector3d& z, const Eigen::Matrix3d& R,
                              const FilterVec& x, FilterCov* P) const {
  if (!(config_.unseen_slip_max_rad > 0.0) || track_size_ == 0) return false;
  // A gyro that reported since the last fix saw every turn: a heading it disagrees with is the
  // gyro's fault (a bias step), for the kidnap rule, which widens its calibration.
  if (gyro_size_ > 0 && gyro_at(gyro_size_ - 1).t_ns >= track_[0].t_ns) return false;
  const double dth = wrap_angle_rad(z(2) - x(kItheta));
  const double var_th = (*P)(kItheta, kItheta) + R(2, 2);
  // Only a heading change the prior cannot explain, and not beyond what a slip turns.
  if (std::abs(dth) > config_.unseen_slip_max_rad || dth * dth <= 9.0 * var_th) return false;
  const Eigen::Vector2d p(x(kIx), x(kIy));
  const Eigen::Vector2d nu = z.head<2>() - p;
  const Eigen::Matrix2d S0 = P->topLeftCorner<2, 2>() + R.topLeftCorner<2, 2>();
  const double c = std::cos(dth), s = std::sin(dth);
  // One wheel's unseen extra distance e turns the vehicle by e / track and moves it e / 2 along
  // its direction. A slip lasting up to slip_max_duration_ns spreads the turn over that stretch;
  // to first order that is a turn at its middle, and a quarter of the stretch times the turn
  // covers the rest and the spacing of the path's points.
  const double along_mm = 0.5 * config_.wheel_track_mm * std::abs(dth);
  double best_d2 = std::numeric_limits<double>::infinity();
  Eigen::Vector2d best_q = Eigen::Vector2d::Zero(), best_u = Eigen::Vector2d::Zero();
  double best_smear_mm = 0.0;
  for (std::size_t j = 0; j < track_size_; ++j) {
    const TrackPoint& tp = track_[j];
    if (tp.t_ns > t_ns) break;
    const Eigen::Vector2d lever = p - Eigen::Vector2d(tp.x_mm, tp.y_mm);
    const Eigen::Vector2d q((c - 1.0) * lever.x() - s * lever.y(),
                            s * lever.x() + (c - 1.0) * lever.y());
    const Eigen::Vector2d u(std::cos(tp.theta_rad), std::sin(tp.theta_rad));
    const double smear_mm = std::abs(dth) * 0.25 *
                            static_cast<double>(config_.slip_max_duration_ns) * 1e-9 *
                            std::abs(tp.v_mps) * 1000.0;
    const Eigen::Matrix2d S = S0 + along_mm * along_mm * u * u.transpose() +
                              smear_mm * smear_mm * Eigen::Matrix2d::Identity();
    // The turn's own displacement must be beyond what the prior and the hypothesis' own slack
    // explain: a heading change with the position where the prior has it (a turn right at the
    // landmark) cannot be told from a heading misread of the landmark, and stays refused.
    const auto S_ldlt = S.ldlt();
    if (!(q.dot(S_ldlt.solve(q)) > gate_threshold_2d_)) continue;
    const Eigen::Vector2d r = nu - q;
    const double d2 = r.dot(S_ldlt.solve(r));
    if (d2 < best_d2) {
      best_d2 = d2;
      best_q = q;
      best_u = u;
      best_smear_mm = smear_mm;
    }
  }
  if (!(best_d2 <= gate_threshold_2d_)) return false;
  // The turn as uncertainty at the fix: heading by its own size, the position along the chord
  // it moved (exact for this size, not the tangent), the along-track and spread terms as above.
  Eigen::Matrix<double, 3, 2> J;
  J.col(0) << best_q.x() / dth, best_q.y() / dth, 1.0;
  J.col(1) << best_u.x(), best_u.y(), 0.0;
  const Eigen::Vector2d q_var(dth * dth, along_mm * along_mm);
  P->topLeftCorner<3, 3>() += J * q_var.asDiagonal() * J.transpose();
  (*P)(kIx, kIx) += best_smear_mm * best_smear_mm;
  (*P)(kIy, kIy) += best_smear_mm * best_smear_mm;
  return true;
}

}  // namespace agv::fusion
