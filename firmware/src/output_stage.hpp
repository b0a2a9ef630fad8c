// The real-time half of the localizer: odometry in, fixes in, fused pose out over CAN at a fixed
// rate. Shared by `run`, `replay --realtime` and `replay --fast`. After construction none of
// its methods allocates (tests/firmware/test_alloc.cpp proves it).
#pragma once

#include <cstdint>

#include "agv/can/can_faults.hpp"
#include "agv/common/latency_histogram.hpp"
#include "agv/fusion/ekf.hpp"
#include "agv/hal/can_bus.hpp"
#include "agv/hal/clock.hpp"
#include "agv/protocol/codec.hpp"
#include "agv/vision/landmark_localizer.hpp"
#include "config.hpp"

namespace agv::app {

struct OutputStats {
  std::uint64_t ticks = 0;
  std::uint64_t missed_periods = 0;  // wake-ups later than one full period
  std::uint64_t odom_samples = 0;
  std::uint64_t odom_rejected = 0;  // by the EKF (time or plausibility)
  std::uint64_t fixes_received = 0;
  std::uint64_t fixes_fused = 0;
  std::uint64_t fixes_rejected_gate = 0;
  std::uint64_t fixes_rejected_too_old = 0;
  std::uint64_t fixes_rejected_invalid = 0;
  std::uint64_t reinitialisations = 0;
  std::uint64_t can_tx_ok = 0;
  std::uint64_t can_tx_failed = 0;
  std::uint64_t can_rx_frames = 0;
  std::uint64_t can_rx_other = 0;     // frames that are not odometry (ignored)
  LatencyHistogram fusion_ns;         // on_fix + estimate for one tick
  LatencyHistogram can_send_ns;       // all sends of one tick
  LatencyHistogram end_to_end_ns;     // first pose frame sent after a fix - that frame's exposure
  LatencyHistogram period_jitter_ns;  // |actual wake-up - scheduled wake-up|
};

// What one tick produced (replay writes these to poses.csv).
struct TickRecord {
  std::int64_t t_ns = 0;
  fusion::PoseEstimate estimate;
  protocol::StatusOut status;
};

class OutputStage {
 public:
  // bus may be null (no CAN output). Throws std::invalid_argument on an invalid fusion or
  // protocol configuration (validated earlier by the config reader).
  OutputStage(const config::Config& cfg, hal::CanBus* bus);

  // Odometry from any source (recording, CAN). t_ns on the loop's clock.
  void on_odometry(std::int64_t t_ns, double v_mps, double omega_radps);
  // Drains the CAN receive queue without blocking; odometry frames are decoded, checked and
  // fused, others counted and ignored.
  void poll_can();
  // A vision result for a frame exposed at t_exposure_ns, ready at t_arrival_ns (same clock).
  // Failed fixes only set status flags. An exposure after the arrival can only come from a
  // camera clock that jumped ahead: rejected as invalid, never fused at a time it was not taken.
  void on_fix(const vision::LandmarkFix& fix, std::int64_t t_exposure_ns,
              std::int64_t t_arrival_ns = INT64_MAX);
  // Camera health as seen by the capture side.
  void set_camera_state(bool stalled, bool error) {
    camera_stalled_ = stalled;
    camera_error_ = error;
  }
  // Estimates the pose at now_ns and sends pose, velocity, quality and status (heartbeat when
  // due). `clock` times the sends for latency accounting; null in fast replay, where the send
  // is taken to happen at now_ns. Fills *rec when not null.
  void tick(std::int64_t now_ns, const hal::Clock* clock, TickRecord* rec);
  // Sends the pose pair at once, estimated at now_ns, outside the periodic schedule (used after
  // a fused fix when loop.pose_on_fix is set, so the correction reaches the bus without waiting
  // up to one period). Counts end-to-end latency like tick().
  void send_pose_now(std::int64_t now_ns, const hal::Clock* clock);
  void note_missed_period() {
    ++stats_.missed_periods;
    overrun_ = true;
  }

  const OutputStats& stats() const { return stats_; }
  OutputStats& mutable_stats() { return stats_; }
  const fusion::Ekf& ekf() const { return ekf_; }
  const protocol::OdometryDecoder& odometry_decoder() const { return odom_; }
  bool odometry_timed_out(std::int64_t now_ns) const;

 private:
  void send(const protocol::CanFrameData& f);
  // Pose output for an estimate: invalid when uninitialised, lost or without odometry.
  protocol::PoseOut pose_out(const fusion::PoseEstimate& est, std::int64_t now_ns,
                             bool* odom_timeout) const;
  void send_pose(const protocol::PoseOut& pose, const hal::Clock* clock, std::int64_t now_ns);

  config::Config cfg_;
  hal::CanBus* bus_;
  fusion::Ekf ekf_;
  protocol::ProtocolConfig proto_;
  protocol::Encoder encoder_;
  protocol::OdometryDecoder odom_;
  std::int64_t last_odom_ns_ = INT64_MIN;
  std::uint64_t odom_rejected_seen_ = 0;
  std::int64_t heartbeat_period_ns_;
  std::int64_t next_heartbeat_ns_ = INT64_MIN;
  std::int64_t first_tick_ns_ = INT64_MIN;
  std::uint16_t last_landmark_id_ = 0;
  std::uint8_t rejections_ = 0;  // reject::* since the last status frame
  bool camera_stalled_ = false;
  bool camera_error_ = false;
  bool overrun_ = false;
  std::int64_t pending_e2e_exposure_ns_ = INT64_MIN;  // newest fused fix not yet sent
  can::CanFaultMonitor can_faults_;  // latches bus-off / passive / drops between status frames
  OutputStats stats_;
};

}  // namespace agv::app
