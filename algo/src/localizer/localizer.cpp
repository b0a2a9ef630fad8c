#include "agv/localizer/localizer.hpp"

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>

namespace agv::localizer {

namespace {

protocol::Health to_protocol(fusion::HealthState h) {
  switch (h) {
    case fusion::HealthState::kLocalized:
      return protocol::Health::kOk;
    case fusion::HealthState::kDeadReckoning:
      return protocol::Health::kDegraded;
    case fusion::HealthState::kLost:
    case fusion::HealthState::kUninitialized:
      return protocol::Health::kLost;
  }
  return protocol::Health::kLost;
}

// The status frame's rejection flag for a vision result without a fix (0: nothing to flag).
std::uint8_t rejection_of(vision::FixStatus status) {
  using vision::FixStatus;
  switch (status) {
    case FixStatus::kOk:
    case FixStatus::kNoLandmark:
    case FixStatus::kBadInput:
      return 0;
    case FixStatus::kUnknownLandmark:
      return protocol::reject::kUnknownLandmark;
    case FixStatus::kQrUnreadable:
    case FixStatus::kPayloadInvalid:
      return protocol::reject::kDecodeFailed;
    case FixStatus::kPartlyOutside:
    case FixStatus::kDirectionAmbiguous:
    case FixStatus::kTooFewEdgePoints:
      return protocol::reject::kGeometry;
  }
  return 0;
}

const protocol::ProtocolConfig& checked(const protocol::ProtocolConfig& p) {
  const std::string err = protocol::validate(p);
  if (!err.empty()) throw std::invalid_argument("protocol: " + err);
  return p;
}

}  // namespace

Localizer::Localizer(const LocalizerConfig& cfg)
    : cfg_(cfg), ekf_(cfg.fusion), odom_(checked(cfg.protocol)), gyro_(cfg.protocol) {
  if (cfg_.heartbeat_period_ns <= 0) throw std::invalid_argument("heartbeat period must be > 0");
  if (cfg_.fusion.health.odom_timeout_ns <= 0)
    throw std::invalid_argument("odometry timeout must be > 0");
  if (cfg_.gyro_timeout_ns <= 0) throw std::invalid_argument("gyro timeout must be > 0");
  const OdometryCorrection& o = cfg_.odometry;
  if (!(o.speed_scale > 0.0) || !(o.yaw_rate_scale > 0.0) || !std::isfinite(o.speed_scale) ||
      !std::isfinite(o.yaw_rate_scale) || !std::isfinite(o.yaw_rate_bias_radps) ||
      !std::isfinite(o.yaw_per_metre_rad)) {
    throw std::invalid_argument("odometry correction: scales must be finite and > 0");
  }
  if (cfg_.ranging.floor_check) floor_twin_.emplace(cfg_.fusion);
}

int receive_filters(const protocol::ProtocolConfig& cfg, hal::CanFilter* out, int max) {
  int n = 0;
  for (const protocol::MessageDef& m : protocol::message_table()) {
    if (m.dir != protocol::Direction::kRx || !protocol::rx_enabled(cfg, m.msg)) continue;
    if (n < max) {
      const bool ext = protocol::is_extended(cfg, m.msg);
      out[n].id = protocol::can_id_of(cfg, m.msg);
      out[n].mask = ext ? protocol::kCanExtIdMask : protocol::kCanStdIdMask;
      out[n].extended = ext;
    }
    ++n;
  }
  return n;
}

int Localizer::receive_filters(hal::CanFilter* out, int max) const {
  return localizer::receive_filters(cfg_.protocol, out, max);
}

InitPositionSigma init_position_sigma(const fusion::EkfConfig& fusion) {
  return {kInitPositionSigmaOfLostLimit * fusion.health.lost_position_sigma_mm,
          kInitPositionSigmaOfLostLimit * fusion.health.lost_heading_sigma_rad};
}

void fix_outcome_counts(const fusion::Ekf::Counters& ekf, std::uint64_t exposed_after_arrival,
                        const OperatorPoseCounts& operator_poses, OutputStats* out) {
  // The EKF counts a kidnap (consecutive agreeing fixes outside the gate) as a gate rejection and
  // a re-initialisation; the re-initialisations that are not re-localisations are those.
  const std::uint64_t from_fixes = ekf.reinitialisations - operator_poses.reinitialisations;
  const std::uint64_t kidnaps = ekf.reinitialisations - ekf.relocalisations;
  out->fixes_fused =
      ekf.fixes_fused + ekf.fixes_initialised - operator_poses.initialisations + from_fixes;
  out->fixes_rejected_gate = ekf.fixes_rejected_gate - kidnaps;
  out->fixes_rejected_too_old = ekf.fixes_rejected_too_old;
  out->fixes_rejected_invalid = ekf.fixes_rejected_invalid + exposed_after_arrival;
  out->fixes_rejected_not_tracking = ekf.fixes_rejected_not_tracking;
  out->reinitialisations = from_fixes;
}

bool Localizer::init_position(std::int64_t now_ns, const Pose2& pose) {
  const InitPositionSigma s = init_position_sigma(cfg_.fusion);
  return set_pose(now_ns, pose, s.position_mm, s.heading_rad);
}

bool Localizer::set_pose(std::int64_t now_ns, const Pose2& pose, double sigma_mm,
                         double sigma_rad) {
  Eigen::Matrix3d R = Eigen::Matrix3d::Zero();
  R(0, 0) = R(1, 1) = sigma_mm * sigma_mm;
  R(2, 2) = sigma_rad * sigma_rad;
  const fusion::Ekf::Counters before = ekf_.counters();
  const bool ok = ekf_.set_pose(now_ns, pose, R);
  if (floor_twin_) floor_twin_->set_pose(now_ns, pose, R);
  floor_conflict_streak_ = 0;
  operator_poses_.initialisations += ekf_.counters().fixes_initialised - before.fixes_initialised;
  operator_poses_.reinitialisations += ekf_.counters().reinitialisations - before.reinitialisations;
  refresh_fix_counts();
  return ok;
}

void Localizer::on_odometry(std::int64_t t_ns, double v_mps, double omega_radps) {
  ++stats_.odom_samples;
  // THE place the configured odometry correction is applied (OdometryCorrection). Multiplying
  // by exactly 1.0 leaves a value bit-identical; a zero bias is skipped (-0.0 + 0.0 = +0.0).
  t_ns = cfg_.time_base.odometry_to_vehicle_ns(t_ns);
  const OdometryCorrection& c = cfg_.odometry;
  const double v_read_mps = v_mps, omega_read_radps = omega_radps;
  v_mps *= c.speed_scale;
  omega_radps *= c.yaw_rate_scale;
  if (c.yaw_rate_bias_radps != 0.0) omega_radps += c.yaw_rate_bias_radps;
  if (c.yaw_per_metre_rad != 0.0) {
    omega_radps += c.yaw_per_metre_rad * v_read_mps;
    const double track_width_m = cfg_.fusion.slip.wheel_track_mm * 1e-3;
    v_mps += c.yaw_per_metre_rad * 0.25 * track_width_m * track_width_m * omega_read_radps;
  }
  const bool accepted = ekf_.add_odometry(t_ns, v_mps, omega_radps);
  if (floor_twin_) floor_twin_->add_odometry(t_ns, v_mps, omega_radps);
  refresh_fix_counts();  // odometry that catches up releases held fixes
  if (!accepted) {
    ++stats_.odom_rejected;
    return;
  }
  last_odom_ns_ = t_ns;
  last_v_mps_ = v_mps;
  last_omega_radps_ = omega_radps;
}

bool Localizer::on_gyro(std::int64_t t_ns, double gyro_z_radps) {
  ++stats_.gyro_samples;
  const GyroCorrection& c = cfg_.gyro;
  t_ns = cfg_.time_base.gyro_to_vehicle_ns(t_ns);
  gyro_z_radps *= c.scale;
  if (c.bias_radps != 0.0) gyro_z_radps += c.bias_radps;
  const bool accepted = ekf_.add_gyro(t_ns, gyro_z_radps);
  if (floor_twin_) floor_twin_->add_gyro(t_ns, gyro_z_radps);
  refresh_fix_counts();
  if (!accepted) {
    ++stats_.gyro_rejected;
    return false;
  }
  last_gyro_ns_ = t_ns;
  return true;
}

bool Localizer::gyro_timed_out(std::int64_t now_ns) const {
  return stats_.gyro_samples > 0 &&
         (last_gyro_ns_ == INT64_MIN || now_ns - last_gyro_ns_ > cfg_.gyro_timeout_ns);
}

bool Localizer::on_can_frame(const hal::CanFrame& frame, protocol::OdomSample* sample) {
  return on_can_frame(frame, sample, nullptr) == CanRx::kOdometry;
}

CanRx Localizer::on_can_frame(const hal::CanFrame& frame, protocol::OdomSample* odom,
                              protocol::GyroSample* gyro) {
  ++stats_.can_rx_frames;
  // Dispatch by ID over the signal table's enabled inputs (the decoders hold the IDs).
  for (const protocol::MessageDef& m : protocol::message_table()) {
    if (m.dir != protocol::Direction::kRx || !protocol::rx_enabled(cfg_.protocol, m.msg)) continue;
    switch (m.msg) {
      case protocol::Msg::kOdomWheels:
      case protocol::Msg::kOdomTwist: {  // the variant of the configured mode
        if (frame.id != odom_.can_id() || frame.extended != odom_.extended()) continue;
        protocol::OdomSample s;
        if (odom_.decode(frame, &s) != protocol::DecodeResult::kOk) return CanRx::kRejected;
        on_odometry(s.t_ns, s.v_mps, s.omega_radps);
        if (odom) *odom = s;
        return CanRx::kOdometry;
      }
      case protocol::Msg::kGyro: {
        if (frame.id != gyro_.can_id() || frame.extended != gyro_.extended()) continue;
        protocol::GyroSample s;
        if (gyro_.decode(frame, &s) != protocol::DecodeResult::kOk) return CanRx::kRejected;
        if (gyro) *gyro = s;
        if (s.saturated) {  // the sensor says the rate is not usable: never fused
          ++stats_.gyro_saturated;
          return CanRx::kGyroSaturated;
        }
        on_gyro(s.t_ns, s.gyro_z_radps);
        return CanRx::kGyro;
      }
      default:  // an input without a receiver here
        continue;
    }
  }
  ++stats_.can_rx_other;
  return CanRx::kOther;
}

bool Localizer::odometry_timed_out(std::int64_t now_ns) const {
  // Whatever the source (CAN or a recording): the newest sample fusion accepted.
  return last_odom_ns_ == INT64_MIN || now_ns - last_odom_ns_ > cfg_.fusion.health.odom_timeout_ns;
}

void Localizer::on_fix(const vision::LandmarkMeasurement& fix, std::int64_t t_exposure_ns,
                       std::int64_t t_arrival_ns) {
  if (fix.status != vision::FixStatus::kOk) {
    rejections_ |= rejection_of(fix.status);
    return;
  }
  ++stats_.fixes_received;
  if (t_exposure_ns > t_arrival_ns) {
    ++fixes_exposed_after_arrival_;
    refresh_fix_counts();
    rejections_ |= protocol::reject::kGeometry;
    return;
  }
  t_exposure_ns = cfg_.time_base.camera_to_vehicle_ns(t_exposure_ns);
  const bool guided = fix.identity == vision::FixIdentity::kMapGuided;
  if (guided) ++stats_.fixes_map_guided;
  // A map-guided fix never vouches for itself, and neither does a tag (the map entry is all it
  // has: a map that puts it at another tag's pose cannot be caught by the tag): map_verified
  // means a QR payload the map confirmed.
  const bool vouches =
      fix.map_verified && !guided && fix.identity != vision::FixIdentity::kAprilTag;
  fusion::FixOutcome outcome =
      ekf_.add_fix(t_exposure_ns, fix.vehicle_in_world, fix.cov_world, vouches, guided);
  if (floor_twin_) {
    const fusion::FixOutcome twin =
        floor_twin_->add_fix(t_exposure_ns, fix.vehicle_in_world, fix.cov_world, vouches, guided);
    outcome = floor_arbitration(t_exposure_ns, outcome, twin, guided);
  }
  refresh_fix_counts();
  switch (outcome) {
    case fusion::FixOutcome::kHeld:  // fused (or rejected) when odometry catches up
      return;
    case fusion::FixOutcome::kFused:
    case fusion::FixOutcome::kInitialised:
      if (guided) {
        ++stats_.fixes_map_guided_fused;
        map_guided_fused_ = true;
      }
      break;
    case fusion::FixOutcome::kReinitialised:
      break;
    case fusion::FixOutcome::kRejectedNotTracking:
    case fusion::FixOutcome::kRejectedGate:
      rejections_ |= protocol::reject::kGate;
      return;
    case fusion::FixOutcome::kRejectedTooOld:
      rejections_ |= protocol::reject::kFixTooOld;
      return;
    case fusion::FixOutcome::kRejectedInvalid:
      rejections_ |= protocol::reject::kGeometry;
      return;
  }
  last_landmark_id_ = static_cast<std::uint16_t>(fix.landmark_id);
  last_landmark_valid_ = true;
  if (t_exposure_ns > pending_e2e_exposure_ns_) pending_e2e_exposure_ns_ = t_exposure_ns;
}

protocol::PoseOut Localizer::pose_out(const fusion::PoseEstimate& est, std::int64_t now_ns,
                                      bool* odom_timeout) const {
  protocol::PoseOut pose;
  pose.valid = est.valid && est.health != fusion::HealthState::kLost;
  pose.x_mm = est.pose.x_mm;
  pose.y_mm = est.pose.y_mm;
  pose.theta_rad = est.pose.theta_rad;
  pose.latency_ms =
      last_odom_ns_ == INT64_MIN ? 0.0 : static_cast<double>(now_ns - last_odom_ns_) / 1e6;
  *odom_timeout = odometry_timed_out(now_ns) || (est.flags & fusion::flags::kOdomTimeout);
  if (*odom_timeout) pose.valid = false;  // without odometry behind it, not for control
  return pose;
}

PoseOutput Localizer::take_pose(const protocol::PoseOut& pose) {
  PoseOutput out{pose, pending_e2e_exposure_ns_};
  pending_e2e_exposure_ns_ = INT64_MIN;
  return out;
}

vision::MotionSnapshot Localizer::snapshot_at(std::int64_t t_ns) const {
  const fusion::PoseEstimate est = ekf_.estimate_at(t_ns);
  bool odom_timeout = false;
  pose_out(est, t_ns, &odom_timeout);
  vision::MotionSnapshot s;
  // Lost or not: what the prediction may be used for is decided by its covariance (tracking's
  // sigma limits, map identity's gate against the nearest mapped neighbour). Without
  // odometry behind it there is no prediction.
  s.valid = est.valid && !odom_timeout;
  if (!s.valid) return s;
  s.t_ns = t_ns;
  s.vehicle_in_world = est.pose;
  s.cov = est.cov.topLeftCorner<3, 3>();
  s.v_mm_per_s = est.v_mps * 1000.0;
  s.omega_rad_per_s = est.omega_radps;
  return s;
}

vision::Prediction Localizer::prediction_at(std::int64_t t_exposure_ns) const {
  vision::MotionSnapshot s = snapshot_at(cfg_.time_base.camera_to_vehicle_ns(t_exposure_ns));
  vision::Prediction p;
  p.valid = s.valid;
  p.vehicle_in_world = s.vehicle_in_world;
  p.cov = s.cov;
  return p;
}

PoseOutput Localizer::pose_now(std::int64_t now_ns) {
  const fusion::PoseEstimate est = ekf_.estimate_at(now_ns);
  bool odom_timeout = false;
  const PoseOutput out = take_pose(pose_out(est, now_ns, &odom_timeout));
  ++stats_.fix_poses;
  return out;
}

protocol::QualityOut Localizer::quality_of(const fusion::PoseEstimate& est) {
  protocol::QualityOut q;
  q.valid = est.valid;
  q.sigma_x_mm = std::sqrt(std::max(0.0, est.cov(0, 0)));
  q.sigma_y_mm = std::sqrt(std::max(0.0, est.cov(1, 1)));
  q.sigma_theta_rad = std::sqrt(std::max(0.0, est.cov(2, 2)));
  q.map_guided_fix = map_guided_fused_;
  map_guided_fused_ = false;
  return q;
}

protocol::StatusOut Localizer::status_at(std::int64_t now_ns, const fusion::PoseEstimate& est,
                                         bool odom_timeout) {
  protocol::StatusOut st;
  st.health = to_protocol(est.health);
  st.last_landmark_id = last_landmark_id_;
  st.last_landmark_valid = last_landmark_valid_;
  st.time_since_fix_ms =
      est.time_since_fix_ns < 0 ? -1.0 : static_cast<double>(est.time_since_fix_ns) / 1e6;
  const bool camera_stalled = last_frame_ns_ != INT64_MIN && !camera_eos_ &&
                              now_ns - last_frame_ns_ > cfg_.camera_timeout_ns;
  if (camera_stalled) st.faults |= protocol::fault::kCameraStalled;
  if (camera_error_) st.faults |= protocol::fault::kCameraError;
  if (odom_timeout) st.faults |= protocol::fault::kOdomTimeout;
  const std::uint64_t odom_rej = odom_.counters().rejected();
  if (odom_rej != odom_rejected_seen_) {
    st.faults |= protocol::fault::kOdomE2E;
    odom_rejected_seen_ = odom_rej;
  }
  // Gyro: timed out after samples were seen (any source), or configured on CAN and silent (or
  // only saturated) since the first tick for longer than the timeout.
  const bool gyro_never = (cfg_.protocol.gyro.enabled || cfg_.gyro_expected) &&
                          stats_.gyro_samples == 0 &&
                          now_ns - first_tick_ns_ > cfg_.gyro_timeout_ns;
  if (gyro_timed_out(now_ns) || gyro_never) st.faults |= protocol::fault::kImuTimeout;
  const std::uint64_t gyro_rej = gyro_.counters().rejected();
  if (gyro_rej != gyro_rejected_seen_) {
    st.faults |= protocol::fault::kImuE2E;
    gyro_rejected_seen_ = gyro_rej;
  }
  if (have_can_state_) st.faults |= can_faults_.update(can_state_, can_stats_);
  if (overrun_) st.faults |= protocol::fault::kLoopOverrun;
  overrun_ = false;
  if (est.flags & fusion::flags::kRejectedGate) rejections_ |= protocol::reject::kGate;
  if (est.flags & fusion::flags::kRejectedTooOld) rejections_ |= protocol::reject::kFixTooOld;
  st.rejections = rejections_;
  rejections_ = 0;
  return st;
}

bool Localizer::heartbeat_due(std::int64_t now_ns, protocol::HeartbeatOut* hb) {
  if (now_ns < next_heartbeat_ns_) return false;
  hb->sw_major = cfg_.sw_major;
  hb->sw_minor = cfg_.sw_minor;
  hb->sw_patch = cfg_.sw_patch;
  hb->uptime_s = static_cast<double>(now_ns - first_tick_ns_) / 1e9;
  next_heartbeat_ns_ =
      (next_heartbeat_ns_ == INT64_MIN ? now_ns : next_heartbeat_ns_) + cfg_.heartbeat_period_ns;
  if (next_heartbeat_ns_ <= now_ns) next_heartbeat_ns_ = now_ns + cfg_.heartbeat_period_ns;
  return true;
}

TickRecord Localizer::tick(std::int64_t now_ns) {
  ++stats_.ticks;
  if (first_tick_ns_ == INT64_MIN) first_tick_ns_ = now_ns;

  TickRecord rec;
  rec.t_ns = now_ns;
  rec.estimate = ekf_.estimate_at(now_ns);
  rec.estimate.flags |= ekf_.take_flags();
  const fusion::PoseEstimate& est = rec.estimate;

  bool odom_timeout = false;
  const protocol::PoseOut pose = pose_out(est, now_ns, &odom_timeout);
  rec.velocity.valid = est.valid;
  rec.velocity.v_mps = est.v_mps;
  rec.velocity.omega_radps = est.omega_radps;
  rec.quality = quality_of(est);
  rec.status = status_at(now_ns, est, odom_timeout);
  rec.pose = take_pose(pose);
  rec.pose_valid = protocol::pose_valid_on_can(pose);
  rec.heartbeat_due = heartbeat_due(now_ns, &rec.heartbeat);
  return rec;
}

}  // namespace agv::localizer
