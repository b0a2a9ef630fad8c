// Landmarks on racks in the localizer: one second-camera frame's range-bearing observations.
// Tracking, each landmark is an EKF range-bearing update (gated there). Uninitialised or lost,
// the frame's landmarks give a prior-free fix, and the filter starts from it only under the trust
// rules of tags on the floor: a tag carries no position of its own (its map entry is all there
// is), so a filter whose position is unknown re-initialises only from two agreeing fixes. Here
// each fix already needs two landmarks and an OK status (not too few, shallow, ambiguous,
// inconsistent ...), and init_fixes consecutive fixes must agree, the earlier carried to the
// later by the odometry (a frame that read fewer than two landmarks is skipped, not a break).
// The agreeing fixes are stacked: a vehicle at rest sees the same landmarks in every frame, and
// each frame's noise is its own while the calibration's share of the covariance repeats, so the
// stack averages the one and keeps the other once; it initialises when within
// init_position_sd_mm. What no rule inside two-landmark fixes can catch, a wrong map
// entry that keeps their chi-square small, is in docs/design/ranging.md.
//
// Tracking, a slip the wheels did not show (wheels only: one wheel a few percent over for a few
// tenths of a second turns the vehicle by degrees) leaves a filter confident of a wrong heading,
// and every later rack landmark fails its gate. The floor fixes' answer (the EKF's unseen-slip
// test) needs a fix, which a range-bearing update is not; here the frame's prior-free fix is the
// witness, under that test's preconditions: no gyro carried the heading, and the fix's heading
// differs from the filter's by more than 3 sigma (of both) and at most
// fusion.recovery.unseen_slip_max_rad. init_fixes consecutive such frames whose fixes agree with
// each other re-localise the filter from their stack (Ekf::set_pose, speed and calibration kept).
// A frame with any landmark fused breaks the run, so one wrong map entry among correct ones in
// view, or one bad frame, cannot move a confident filter.
#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>
#include <algorithm>
#include <array>
#include <cmath>

#include "agv/localizer/localizer.hpp"

namespace agv::localizer {

const char* to_string(RangingResult r) {
  switch (r) {
    case RangingResult::kEmpty:
      return "empty";
    case RangingResult::kFused:
      return "fused";
    case RangingResult::kRejected:
      return "rejected";
    case RangingResult::kFixRefused:
      return "fix_refused";
    case RangingResult::kFixPending:
      return "fix_pending";
    case RangingResult::kInitialised:
      return "initialised";
    case RangingResult::kRelocalised:
      return "relocalised";
    case RangingResult::kSuspended:
      return "suspended";
  }
  return "?";
}

RangingResult Localizer::on_ranging(std::int64_t t_exposure_ns,
                                    std::span<const RackObservation> obs) {
  ++stats_.ranging_frames;
  if (obs.size() > kMaxRackLandmarks) obs = obs.first(kMaxRackLandmarks);
  stats_.ranging_landmarks += obs.size();
  if (obs.empty()) return RangingResult::kEmpty;
  const std::int64_t t_ns = t_exposure_ns + cfg_.ranging.camera_offset_ns;
  if (t_ns < rack_suspended_until_ns_) {
    ++stats_.ranging_suspended_frames;
    return RangingResult::kSuspended;
  }
  fusion::PoseEstimate est = ekf_.estimate_at(t_ns);
  // The filter's own covariance: a reported, unconfirmed heading change is no evidence against
  // a frame's fix (the re-localisation's 3-sigma test).
  if (est.valid)
    est.cov.topLeftCorner<3, 3>() -=
        ekf_.unconfirmed_slip_cov(t_ns, Eigen::Vector2d(est.pose.x_mm, est.pose.y_mm));
  if (est.valid && est.health != fusion::HealthState::kLost) return ranging_track(t_ns, obs, est);
  return ranging_fix(t_ns, obs);
}

RangingResult Localizer::ranging_track(std::int64_t t_ns, std::span<const RackObservation> obs,
                                       const fusion::PoseEstimate& prior) {
  const std::uint64_t gated_before = ekf_.counters().range_bearing_rejected_gate;
  bool fused = false;
  for (const RackObservation& o : obs) {
    fusion::RangeBearingObs sensor = o.sensor;
    sensor.common_bearing_sigma_rad =
        std::max(sensor.common_bearing_sigma_rad, cfg_.ranging.common_bearing_sigma_rad);
    fused = ekf_.add_range_bearing(t_ns, sensor) == fusion::FixOutcome::kFused || fused;
  }
  const fusion::Ekf::Counters& c = ekf_.counters();
  stats_.ranging_fused = c.range_bearing_fused;
  stats_.ranging_rejected_gate = c.range_bearing_rejected_gate;
  stats_.ranging_rejected_other = c.range_bearing_rejected_too_old +
                                  c.range_bearing_rejected_invalid +
                                  c.range_bearing_rejected_not_initialised;
  const bool gated = c.range_bearing_rejected_gate > gated_before;
  if (fused) rack_since_floor_fix_ = true;
  if (t_ns < rack_probation_until_ns_ && (fused || gated)) {
    // The first frame after a floor fix overruled the rack aid: agreeing with the floor camera's
    // pose, the filter had only been overconfident (an unseen slip); disagreeing, the rack
    // landmarks or the camera are wrong, and the rack aid is suspended.
    rack_probation_until_ns_ = INT64_MIN;
    if (!fused) {
      ++stats_.ranging_suspensions;
      rack_suspended_until_ns_ = t_ns + cfg_.ranging.conflict_suspend_ns;
      rack_candidate_.count = 0;
      return RangingResult::kRejected;
    }
  }
  if (fused || !gated) {
    rack_candidate_.count = 0;  // only consecutive all-gated frames count towards a step
    return fused ? RangingResult::kFused : RangingResult::kRejected;
  }
  return ranging_step(t_ns, obs, prior);
}

bool Localizer::rack_heading_step(const ranging::FixResult& fix,
                                  const fusion::PoseEstimate& prior) const {
  const double max_rad = cfg_.fusion.recovery.unseen_slip_max_rad;
  if (!(max_rad > 0.0) || prior.gyro_heading) return false;
  const double dth = wrap_angle_rad(fix.pose.theta_rad - prior.pose.theta_rad);
  const double var = prior.cov(2, 2) + fix.cov(2, 2);
  return std::abs(dth) <= max_rad && dth * dth > 9.0 * var;
}

RangingResult Localizer::ranging_step(std::int64_t t_ns, std::span<const RackObservation> obs,
                                      const fusion::PoseEstimate& prior) {
  ranging::FixResult fix;
  Eigen::Matrix3d systematic_cov;
  if (!rack_fix(obs, &fix, &systematic_cov) || !rack_heading_step(fix, prior)) {
    rack_candidate_.count = 0;
    return RangingResult::kRejected;
  }
  if (!count_rack_fix(t_ns, fix, systematic_cov)) return RangingResult::kRejected;
  const ranging::FixResult& pose = rack_candidate_.fix;
  const fusion::Ekf::Counters before = ekf_.counters();
  const bool ok = ekf_.set_pose(t_ns, pose.pose, pose.cov);
  rack_poses_.reinitialisations += ekf_.counters().reinitialisations - before.reinitialisations;
  refresh_fix_counts();
  rack_candidate_.count = 0;
  if (!ok) return RangingResult::kRejected;
  rack_since_floor_fix_ = true;
  ++stats_.ranging_initialisations;
  ++stats_.ranging_step_relocalisations;
  return RangingResult::kRelocalised;
}

void Localizer::carry_rack_candidate(std::int64_t t_ns, Eigen::Vector3d* pose,
                                     Eigen::Matrix3d* Q) const {
  const RackCandidate& c = rack_candidate_;
  const double dt_s = static_cast<double>(t_ns - c.t_ns) * 1e-9;
  // Over the gap (a frame or a few at 15 fps) with the newest odometry.
  const double dist_mm = last_v_mps_ * dt_s * 1e3;
  const double turn_rad = last_omega_radps_ * dt_s;
  const double mid_rad = c.fix.pose.theta_rad + 0.5 * turn_rad;
  *pose = Eigen::Vector3d(c.fix.pose.x_mm + dist_mm * std::cos(mid_rad),
                          c.fix.pose.y_mm + dist_mm * std::sin(mid_rad),
                          c.fix.pose.theta_rad + turn_rad);
  const double share = cfg_.ranging.motion_sigma_share;
  *Q = Eigen::Vector3d(share * share * dist_mm * dist_mm, share * share * dist_mm * dist_mm,
                       share * share * turn_rad * turn_rad)
           .asDiagonal();
}

bool Localizer::rack_fix_agrees(std::int64_t t_ns, const ranging::FixResult& fix) const {
  const RackCandidate& c = rack_candidate_;
  if (c.count == 0 || t_ns < c.t_ns || t_ns - c.t_ns > cfg_.ranging.init_max_gap_ns) return false;
  Eigen::Vector3d carried;
  Eigen::Matrix3d Q;
  carry_rack_candidate(t_ns, &carried, &Q);
  Eigen::Vector3d d(fix.pose.x_mm - carried(0), fix.pose.y_mm - carried(1), 0.0);
  d(2) = wrap_angle_rad(fix.pose.theta_rad - carried(2));
  // Both covariances whole: the shares the two repeat count twice, which only widens the gate.
  const Eigen::LLT<Eigen::Matrix3d> llt(c.fix.cov + fix.cov + Q);
  if (llt.info() != Eigen::Success) return false;
  return d.dot(llt.solve(d)) <= cfg_.ranging.agreement_gate;
}

void Localizer::stack_rack_fix(std::int64_t t_ns, const ranging::FixResult& fix,
                               const Eigen::Matrix3d& systematic_cov) {
  RackCandidate& c = rack_candidate_;
  Eigen::Vector3d carried;
  Eigen::Matrix3d Q;
  carry_rack_candidate(t_ns, &carried, &Q);
  const Eigen::Matrix3d P = c.own_cov + Q;
  const Eigen::Matrix3d F = fix.cov - systematic_cov;
  const Eigen::LLT<Eigen::Matrix3d> llt(P + F);
  if (llt.info() != Eigen::Success) return;  // kept as it was: the run still counts the fix
  Eigen::Vector3d d(fix.pose.x_mm - carried(0), fix.pose.y_mm - carried(1), 0.0);
  d(2) = wrap_angle_rad(fix.pose.theta_rad - carried(2));
  const Eigen::Matrix3d K = llt.solve(P).transpose();  // P (P + F)^-1, both symmetric
  const Eigen::Vector3d m = carried + K * d;
  c.own_cov = (Eigen::Matrix3d::Identity() - K) * P;
  c.own_cov = 0.5 * (c.own_cov + c.own_cov.transpose());
  c.systematic_cov = systematic_cov;
  c.fix.pose = {m(0), m(1), wrap_angle_rad(m(2))};
  c.fix.cov = c.own_cov + c.systematic_cov;
}

bool Localizer::rack_fix(std::span<const RackObservation> obs, ranging::FixResult* fix,
                         Eigen::Matrix3d* systematic_cov) {
  std::array<ranging::Observation, kMaxRackLandmarks> in;
  for (std::size_t i = 0; i < obs.size(); ++i) in[i] = obs[i].vehicle;
  const std::span<const ranging::Observation> seen(in.data(), obs.size());
  ranging::FixOptions opt = cfg_.ranging.fix;
  if (!cfg_.ranging.stack_fixes)
    opt.max_position_sd_mm = std::min(opt.max_position_sd_mm, cfg_.ranging.init_position_sd_mm);
  *fix = ranging::fix_from_landmarks(seen, opt);
  ++stats_.ranging_fixes;
  if (fix->status == ranging::FixStatus::kOk) {
    // Both terms below repeat in every frame; each is the response of the least squares' own
    // covariance, so both are computed before either is added.
    *systematic_cov = ranging::fix_systematic_cov(seen, *fix);
    const Eigen::Matrix3d lens = ranging::lens_cov_change(seen, *fix);
    const Eigen::Matrix3d without_yaw = fix->cov;
    ranging::add_mount_yaw_uncertainty(seen, cfg_.ranging.common_bearing_sigma_rad, fix);
    *systematic_cov += fix->cov - without_yaw + lens;
    fix->cov += lens;
    return true;
  }
  const auto k = static_cast<std::size_t>(fix->status);
  if (k < stats_.ranging_fix_refused.size()) ++stats_.ranging_fix_refused[k];
  return false;
}

bool Localizer::count_rack_fix(std::int64_t t_ns, const ranging::FixResult& fix,
                               const Eigen::Matrix3d& systematic_cov) {
  RackCandidate& c = rack_candidate_;
  if (rack_fix_agrees(t_ns, fix)) {
    ++c.count;
    if (cfg_.ranging.stack_fixes) {
      stack_rack_fix(t_ns, fix, systematic_cov);
    } else {
      c.fix = fix;
    }
  } else {
    if (c.count > 0) ++stats_.ranging_fixes_disagreed;
    c.count = 1;
    c.fix = fix;
    c.systematic_cov = systematic_cov;
    c.own_cov = fix.cov - systematic_cov;
  }
  c.t_ns = t_ns;
  if (c.count < std::max(1, cfg_.ranging.init_fixes)) return false;
  if (!cfg_.ranging.stack_fixes) return true;  // each fix was held to the limit alone
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix2d> pos(c.fix.cov.topLeftCorner<2, 2>());
  const double worst_sd_mm = std::sqrt(std::max(0.0, pos.eigenvalues().maxCoeff()));
  return worst_sd_mm <= cfg_.ranging.init_position_sd_mm;
}

RangingResult Localizer::ranging_fix(std::int64_t t_ns, std::span<const RackObservation> obs) {
  ranging::FixResult fix;
  Eigen::Matrix3d systematic_cov;
  if (!rack_fix(obs, &fix, &systematic_cov)) {
    // A frame that read one landmark says no more against the run than a frame that read none:
    // both leave it to the gap limit. A fix refused for what its landmarks say (shallow,
    // ambiguous, inconsistent ...) breaks it.
    if (fix.status != ranging::FixStatus::kTooFew) rack_candidate_.count = 0;
    return RangingResult::kFixRefused;
  }
  if (!count_rack_fix(t_ns, fix, systematic_cov)) return RangingResult::kFixPending;

  // Initialised from the run's pose: uninitialised, as from a first fix; lost, re-localised
  // keeping speed and calibration (Ekf::set_pose). Counted apart from floor fixes.
  const ranging::FixResult& pose = rack_candidate_.fix;
  const fusion::Ekf::Counters before = ekf_.counters();
  const bool ok = ekf_.set_pose(t_ns, pose.pose, pose.cov);
  rack_poses_.initialisations += ekf_.counters().fixes_initialised - before.fixes_initialised;
  rack_poses_.reinitialisations += ekf_.counters().reinitialisations - before.reinitialisations;
  refresh_fix_counts();
  rack_candidate_.count = 0;
  if (!ok) return RangingResult::kFixRefused;
  rack_since_floor_fix_ = true;
  ++stats_.ranging_initialisations;
  return RangingResult::kInitialised;
}

fusion::FixOutcome Localizer::floor_arbitration(std::int64_t t_ns, fusion::FixOutcome outcome,
                                                fusion::FixOutcome twin_outcome, bool guided) {
  using fusion::FixOutcome;
  if (outcome == FixOutcome::kFused || outcome == FixOutcome::kInitialised ||
      outcome == FixOutcome::kReinitialised) {
    rack_since_floor_fix_ = false;
    floor_conflict_streak_ = 0;
    // The twin refused a floor fix that floor and rack landmarks agree on: it holds an older floor
    // fix (a misread it fused, 0.1 mm sure) and would stay wrong and confident, drifting on the
    // odometry calibration that fix taught it, to overrule the rack landmarks later.
    if (twin_outcome == FixOutcome::kRejectedGate) {
      floor_twin_->adopt_estimate(ekf_);
      ++stats_.ranging_floor_twin_resyncs;
    }
    return outcome;
  }
  if (outcome != FixOutcome::kRejectedGate || twin_outcome != FixOutcome::kFused || guided ||
      !rack_since_floor_fix_)
    return outcome;
  if (++floor_conflict_streak_ < std::max(cfg_.ranging.conflict_fixes, 1)) {
    ++stats_.ranging_floor_disputes;
    return outcome;
  }
  floor_conflict_streak_ = 0;
  ekf_.adopt_estimate(*floor_twin_);
  ++stats_.ranging_floor_conflicts;
  rack_probation_until_ns_ = t_ns + cfg_.ranging.probation_ns;
  rack_since_floor_fix_ = false;
  rack_candidate_.count = 0;
  return FixOutcome::kReinitialised;
}

}  // namespace agv::localizer
