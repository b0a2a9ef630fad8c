// Landmarks on racks in the localizer: one second-camera frame's range-bearing observations.
// Tracking, each landmark is an EKF range-bearing update (gated there). Uninitialised or lost,
// the frame's landmarks give a prior-free fix, and the filter starts from it only under the trust
// rules of tags on the floor: a tag carries no position of its own (its map entry is all there
// is), so a filter whose position is unknown re-initialises only from two agreeing fixes. Here
// each fix already needs two landmarks and an OK status (not too few, shallow, ambiguous,
// inconsistent ...), and init_fixes consecutive fixes must agree, the earlier carried to the
// later by the odometry. What no rule inside two-landmark fixes can catch, a wrong map entry
// that keeps their chi-square small, is in docs/design/ranging.md.
#include <Eigen/Cholesky>
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
  const fusion::PoseEstimate est = ekf_.estimate_at(t_ns);
  if (est.valid && est.health != fusion::HealthState::kLost) {
    rack_candidate_.count = 0;  // agreement is counted among consecutive untracked frames
    return ranging_track(t_ns, obs);
  }
  return ranging_fix(t_ns, obs);
}

RangingResult Localizer::ranging_track(std::int64_t t_ns, std::span<const RackObservation> obs) {
  bool fused = false;
  for (const RackObservation& o : obs)
    fused = ekf_.add_range_bearing(t_ns, o.sensor) == fusion::FixOutcome::kFused || fused;
  const fusion::Ekf::Counters& c = ekf_.counters();
  stats_.ranging_fused = c.range_bearing_fused;
  stats_.ranging_rejected_gate = c.range_bearing_rejected_gate;
  stats_.ranging_rejected_other = c.range_bearing_rejected_too_old +
                                  c.range_bearing_rejected_invalid +
                                  c.range_bearing_rejected_not_initialised;
  return fused ? RangingResult::kFused : RangingResult::kRejected;
}

bool Localizer::rack_fix_agrees(std::int64_t t_ns, const ranging::FixResult& fix) const {
  const RackCandidate& c = rack_candidate_;
  const double dt_s = static_cast<double>(t_ns - c.t_ns) * 1e-9;
  if (c.count == 0 || dt_s < 0.0 || t_ns - c.t_ns > cfg_.ranging.init_max_gap_ns) return false;
  // The earlier fix carried by the newest odometry over the gap (a frame or a few at 15 fps).
  const double dist_mm = last_v_mps_ * dt_s * 1e3;
  const double turn_rad = last_omega_radps_ * dt_s;
  const double mid_rad = c.fix.pose.theta_rad + 0.5 * turn_rad;
  const Eigen::Vector3d carried(c.fix.pose.x_mm + dist_mm * std::cos(mid_rad),
                                c.fix.pose.y_mm + dist_mm * std::sin(mid_rad),
                                c.fix.pose.theta_rad + turn_rad);
  Eigen::Vector3d d(fix.pose.x_mm - carried(0), fix.pose.y_mm - carried(1), 0.0);
  d(2) = wrap_angle_rad(fix.pose.theta_rad - carried(2));
  const double share = cfg_.ranging.motion_sigma_share;
  Eigen::Matrix3d S = c.fix.cov + fix.cov;
  S(0, 0) += share * share * dist_mm * dist_mm;
  S(1, 1) += share * share * dist_mm * dist_mm;
  S(2, 2) += share * share * turn_rad * turn_rad;
  const Eigen::LLT<Eigen::Matrix3d> llt(S);
  if (llt.info() != Eigen::Success) return false;
  const double d2 = d.dot(llt.solve(d));
  return d2 <= cfg_.ranging.agreement_gate;
}

RangingResult Localizer::ranging_fix(std::int64_t t_ns, std::span<const RackObservation> obs) {
  std::array<ranging::Observation, kMaxRackLandmarks> in;
  for (std::size_t i = 0; i < obs.size(); ++i) in[i] = obs[i].vehicle;
  const ranging::FixResult fix =
      ranging::fix_from_landmarks(std::span(in.data(), obs.size()), cfg_.ranging.fix);
  ++stats_.ranging_fixes;
  if (fix.status != ranging::FixStatus::kOk) {
    const auto k = static_cast<std::size_t>(fix.status);
    if (k < stats_.ranging_fix_refused.size()) ++stats_.ranging_fix_refused[k];
    rack_candidate_.count = 0;  // a refused frame breaks the run of consecutive fixes
    return RangingResult::kFixRefused;
  }
  if (rack_fix_agrees(t_ns, fix)) {
    ++rack_candidate_.count;
  } else {
    if (rack_candidate_.count > 0) ++stats_.ranging_fixes_disagreed;
    rack_candidate_.count = 1;
  }
  rack_candidate_.t_ns = t_ns;
  rack_candidate_.fix = fix;
  if (rack_candidate_.count < std::max(1, cfg_.ranging.init_fixes))
    return RangingResult::kFixPending;

  // Initialised from the newest fix: uninitialised, as from a first fix; lost, re-localised
  // keeping speed and calibration (Ekf::set_pose). Counted apart from floor fixes.
  const fusion::Ekf::Counters before = ekf_.counters();
  const bool ok = ekf_.set_pose(t_ns, fix.pose, fix.cov);
  rack_poses_.initialisations += ekf_.counters().fixes_initialised - before.fixes_initialised;
  rack_poses_.reinitialisations += ekf_.counters().reinitialisations - before.reinitialisations;
  refresh_fix_counts();
  rack_candidate_.count = 0;
  if (!ok) return RangingResult::kFixRefused;
  ++stats_.ranging_initialisations;
  return RangingResult::kInitialised;
}

}  // namespace agv::localizer
