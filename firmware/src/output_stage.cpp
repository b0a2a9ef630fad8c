#include "output_stage.hpp"

#include <cmath>

#include "agv/can/frame_convert.hpp"

namespace agv::app {

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

}  // namespace

OutputStage::OutputStage(const config::Config& cfg, hal::CanBus* bus)
    : cfg_(cfg),
      bus_(bus),
      ekf_(cfg.fusion),
      proto_(config::protocol_config(cfg)),
      encoder_(proto_),
      odom_(proto_),
      heartbeat_period_ns_(static_cast<std::int64_t>(1e9 / cfg.loop.heartbeat_rate_hz)) {
  if (bus_) {
    // Only odometry reaches us; the kernel filters the rest.
    hal::CanFilter f;
    f.id = odom_.can_id();
    f.mask = odom_.extended() ? protocol::kCanExtIdMask : protocol::kCanStdIdMask;
    f.extended = odom_.extended();
    bus_->set_filters(&f, 1);
  }
}

void OutputStage::on_odometry(std::int64_t t_ns, double v_mps, double omega_radps) {
  ++stats_.odom_samples;
  if (!ekf_.add_odometry(t_ns, v_mps, omega_radps)) {
    ++stats_.odom_rejected;
    return;
  }
  last_odom_ns_ = t_ns;
}

void OutputStage::poll_can() {
  if (!bus_) return;
  hal::CanFrame frame;
  // Bounded: at 1 Mbit/s at most ~80 frames arrive in 10 ms.
  for (int i = 0; i < 256; ++i) {
    if (bus_->receive(&frame, 0) != hal::CanStatus::kOk) break;
    ++stats_.can_rx_frames;
    protocol::OdomSample s;
    const protocol::DecodeResult r = odom_.decode(can::from_hal(frame), &s);
    if (r == protocol::DecodeResult::kOk) {
      on_odometry(s.t_ns, s.v_mps, s.omega_radps);
    } else if (r == protocol::DecodeResult::kNotOdometry) {
      ++stats_.can_rx_other;
    }
  }
}

bool OutputStage::odometry_timed_out(std::int64_t now_ns) const {
  // Whatever the source (CAN or a recording): the newest sample fusion accepted.
  return last_odom_ns_ == INT64_MIN ||
         now_ns - last_odom_ns_ > static_cast<std::int64_t>(cfg_.can.odometry_timeout_ms * 1e6);
}

void OutputStage::on_fix(const vision::LandmarkFix& fix, std::int64_t t_exposure_ns,
                         std::int64_t t_arrival_ns) {
  using vision::FixStatus;
  switch (fix.status) {
    case FixStatus::kOk:
      break;
    case FixStatus::kNoLandmark:
    case FixStatus::kBadInput:
      return;
    case FixStatus::kUnknownLandmark:
      rejections_ |= protocol::reject::kUnknownLandmark;
      return;
    case FixStatus::kQrUnreadable:
    case FixStatus::kPayloadInvalid:
      rejections_ |= protocol::reject::kDecodeFailed;
      return;
    case FixStatus::kPartlyOutside:
    case FixStatus::kDirectionAmbiguous:
    case FixStatus::kTooFewEdgePoints:
      rejections_ |= protocol::reject::kGeometry;
      return;
  }
  ++stats_.fixes_received;
  if (t_exposure_ns > t_arrival_ns) {
    ++stats_.fixes_rejected_invalid;
    rejections_ |= protocol::reject::kGeometry;
    return;
  }
  switch (ekf_.add_fix(t_exposure_ns, fix.vehicle_in_world, fix.cov_world, fix.map_verified)) {
    case fusion::FixOutcome::kHeld:  // fused (or rejected) when odometry catches up
      return;
    case fusion::FixOutcome::kFused:
    case fusion::FixOutcome::kInitialised:
      ++stats_.fixes_fused;
      break;
    case fusion::FixOutcome::kReinitialised:
      ++stats_.fixes_fused;
      ++stats_.reinitialisations;
      break;
    case fusion::FixOutcome::kRejectedGate:
      ++stats_.fixes_rejected_gate;
      rejections_ |= protocol::reject::kGate;
      return;
    case fusion::FixOutcome::kRejectedTooOld:
      ++stats_.fixes_rejected_too_old;
      rejections_ |= protocol::reject::kFixTooOld;
      return;
    case fusion::FixOutcome::kRejectedInvalid:
      ++stats_.fixes_rejected_invalid;
      rejections_ |= protocol::reject::kGeometry;
      return;
  }
  last_landmark_id_ = static_cast<std::uint16_t>(fix.landmark_id);
  if (t_exposure_ns > pending_e2e_exposure_ns_) pending_e2e_exposure_ns_ = t_exposure_ns;
}

void OutputStage::send(const protocol::CanFrameData& f) {
  if (!bus_) return;
  if (bus_->send(can::to_hal(f)) == hal::CanStatus::kOk) {
    ++stats_.can_tx_ok;
  } else {
    ++stats_.can_tx_failed;  // counted, never retried: the next period carries fresher data
  }
}

protocol::PoseOut OutputStage::pose_out(const fusion::PoseEstimate& est, std::int64_t now_ns,
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

void OutputStage::send_pose(const protocol::PoseOut& pose, const hal::Clock* clock,
                            std::int64_t now_ns) {
  protocol::CanFrameData a, b;
  encoder_.encode_pose(pose, &a, &b);
  send(a);
  send(b);
  if (pending_e2e_exposure_ns_ != INT64_MIN) {
    stats_.end_to_end_ns.record_ns((clock ? clock->now_ns() : now_ns) - pending_e2e_exposure_ns_);
    pending_e2e_exposure_ns_ = INT64_MIN;
  }
}

void OutputStage::send_pose_now(std::int64_t now_ns, const hal::Clock* clock) {
  const fusion::PoseEstimate est = ekf_.estimate_at(now_ns);
  bool odom_timeout = false;
  send_pose(pose_out(est, now_ns, &odom_timeout), clock, now_ns);
}

void OutputStage::tick(std::int64_t now_ns, const hal::Clock* clock, TickRecord* rec) {
  const std::int64_t t_start = clock ? clock->now_ns() : now_ns;
  ++stats_.ticks;
  if (first_tick_ns_ == INT64_MIN) first_tick_ns_ = now_ns;

  fusion::PoseEstimate est = ekf_.estimate_at(now_ns);
  est.flags |= ekf_.take_flags();

  bool odom_timeout = false;
  const protocol::PoseOut pose = pose_out(est, now_ns, &odom_timeout);
  protocol::VelocityOut vel;
  vel.valid = est.valid;
  vel.v_mps = est.v_mps;
  vel.omega_radps = est.omega_radps;
  protocol::QualityOut q;
  q.valid = est.valid;
  q.sigma_x_mm = std::sqrt(std::max(0.0, est.cov(0, 0)));
  q.sigma_y_mm = std::sqrt(std::max(0.0, est.cov(1, 1)));
  q.sigma_theta_rad = std::sqrt(std::max(0.0, est.cov(2, 2)));

  protocol::StatusOut st;
  st.health = to_protocol(est.health);
  st.last_landmark_id = last_landmark_id_;
  st.time_since_fix_ms =
      est.time_since_fix_ns < 0 ? -1.0 : static_cast<double>(est.time_since_fix_ns) / 1e6;
  if (camera_stalled_) st.faults |= protocol::fault::kCameraStalled;
  if (camera_error_) st.faults |= protocol::fault::kCameraError;
  if (odom_timeout) st.faults |= protocol::fault::kOdomTimeout;
  const std::uint64_t odom_rej = odom_.counters().rejected();
  if (odom_rej != odom_rejected_seen_) {
    st.faults |= protocol::fault::kOdomE2E;
    odom_rejected_seen_ = odom_rej;
  }
  if (bus_) st.faults |= can_faults_.update(bus_->state(), bus_->stats());
  if (overrun_) st.faults |= protocol::fault::kLoopOverrun;
  overrun_ = false;
  if (est.flags & fusion::flags::kRejectedGate) rejections_ |= protocol::reject::kGate;
  if (est.flags & fusion::flags::kRejectedTooOld) rejections_ |= protocol::reject::kFixTooOld;
  st.rejections = rejections_;
  rejections_ = 0;

  const std::int64_t t_fused = clock ? clock->now_ns() : now_ns;
  stats_.fusion_ns.record_ns(t_fused - t_start);

  send_pose(pose, clock, now_ns);
  protocol::CanFrameData a;
  encoder_.encode_velocity(vel, &a);
  send(a);
  encoder_.encode_quality(q, &a);
  send(a);
  encoder_.encode_status(st, &a);
  send(a);
  if (now_ns >= next_heartbeat_ns_) {
    protocol::HeartbeatOut hb;
    hb.sw_major = AGV_VERSION_MAJOR;
    hb.sw_minor = AGV_VERSION_MINOR;
    hb.sw_patch = AGV_VERSION_PATCH;
    hb.uptime_s = static_cast<double>(now_ns - first_tick_ns_) / 1e9;
    encoder_.encode_heartbeat(hb, &a);
    send(a);
    next_heartbeat_ns_ =
        (next_heartbeat_ns_ == INT64_MIN ? now_ns : next_heartbeat_ns_) + heartbeat_period_ns_;
    if (next_heartbeat_ns_ <= now_ns) next_heartbeat_ns_ = now_ns + heartbeat_period_ns_;
  }
  stats_.can_send_ns.record_ns((clock ? clock->now_ns() : now_ns) - t_fused);

  if (rec) {
    rec->t_ns = now_ns;
    rec->estimate = est;
    rec->status = st;
  }
}

}  // namespace agv::app
