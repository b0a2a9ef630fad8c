// The output thread's work, shared by every mode: `run` and `replay --realtime` call it from the
// real-time thread on the monotonic (or scaled) clock, `replay --fast` from one thread on a
// stepped clock in recording time. One CAN writer: only this sends.
#pragma once

#include <array>
#include <cstdint>
#include <vector>

#include "agv/hal/can_bus.hpp"
#include "agv/hal/clock.hpp"
#include "agv/http/latest_slot.hpp"
#include "agv/localizer/can_output.hpp"
#include "agv/localizer/fault_transitions.hpp"
#include "agv/localizer/localizer.hpp"
#include "agv/recording/recording.hpp"
#include "agv/vision/landmark_localizer.hpp"
#include "config.hpp"
#include "gyro_reader.hpp"
#include "handoff.hpp"
#include "output_sink.hpp"

namespace agv::app {

using localizer::OutputStats;
using localizer::TickRecord;

// Vision -> output. Sized for replay --fast too, where fixes wait for their simulated arrival
// (replay.fix_delay_ms x frame rate of them at most).
using FixRing = SpscRing<FixRecord, 64>;

// One second-camera frame's landmarks, as Localizer::on_ranging takes them (ranging_stream.hpp).
struct RangingRecord {
  std::int64_t t_exposure_ns = 0;  // the second camera's clock (the core adds its offset)
  std::int64_t t_done_ns = 0;      // when it reaches the core (loop clock)
  std::size_t n = 0;
  std::array<localizer::RackObservation, localizer::Localizer::kMaxRackLandmarks> obs{};
};
// Second camera -> output step; at 15 fps, 16 frames are a second of a stalled output step.
using RangingRing = SpscRing<RangingRecord, 16>;

// The whole configuration of the localizer core, from the YAML tree: the one place that reads
// config::Config for it.
localizer::LocalizerConfig localizer_config(const config::Config& cfg);

struct CameraState {
  std::int64_t last_frame_ns = INT64_MIN;  // receive time of the newest frame
  bool end_of_stream = false;
  bool error = false;
  std::uint64_t frames_dropped = 0;  // newest-wins replacements (periodic log line)
};

// The journal's fault lines: each set / clear of a status fault bit on stderr, rate-limited per
// bit (localizer::FaultTransitionLog). Not added in tests and quiet replays.
class FaultLogSink : public OutputSink {
 public:
  void on_tick(const TickOutput& out) override;

 private:
  localizer::FaultTransitionLog log_;
};

class OutputLoop {
 public:
  // bus: null = no CAN. odometry: replay odometry on the loop clock, null = from CAN.
  // log_period_ns: periodic statistics line on stderr, 0 = none. imu: replay gyro samples
  // (imu.csv) on the loop clock, null = none (or from CAN). sinks: the outputs besides CAN, each
  // given every fix and tick in this order (VDA 5050, the diagnostics page, the fault journal);
  // they must outlive the loop. Installs the receive filters on the bus.
  OutputLoop(localizer::Localizer& core, hal::CanBus* bus, const hal::Clock& clock,
             const std::vector<recording::OdomRow>* odometry, FixRing& fixes,
             std::int64_t log_period_ns, const std::vector<recording::ImuRow>* imu = nullptr,
             std::vector<OutputSink*> sinks = {});

  // Keeps every odometry sample decoded from CAN (what fusion was given, on the loop clock) in
  // *received, up to its reserved capacity; the rest are counted (odometry_not_recorded). Null:
  // none kept. Called before the loop runs.
  void keep_received_odometry(std::vector<recording::OdomRow>* received) { received_ = received; }
  std::uint64_t odometry_not_recorded() const { return odometry_not_recorded_; }
  // imu.source iio: gyro samples from the reader thread (gyro_reader.hpp), fused in take_inputs
  // after the CAN frames. Null (default): none. Called before the loop runs.
  void set_live_gyro(GyroRing* ring) { live_gyro_ = ring; }
  // ranging_camera.enabled: the second camera's frames, handed to the core in take_inputs in
  // arrival order with the floor fixes. Null (default): none. Called before the loop runs.
  void set_ranging(RangingRing* ring) { ranging_ = ring; }
  // The run is over: hands the final state to every sink (they may wait: nothing real-time left).
  void finish(std::uint64_t frames_dropped);

  // One output period at now_ns: odometry up to now, CAN receive, fixes that arrived, camera
  // state, core tick, send, periodic log. Fills *rec when not null.
  void tick(std::int64_t now_ns, const CameraState& camera, TickRecord* rec);
  // Fix-triggered output (loop.pose_on_fix), outside the periodic schedule: the same inputs up
  // to now_ns, then the pose pair at once if a good fix was taken. True when it sent.
  bool on_wake(std::int64_t now_ns);
  // Odometry, gyro and fixes merged in time order up to now_ns (odometry, then gyro, then fixes
  // on equal times), after the CAN receive queue; returns the number of good (FixStatus::kOk)
  // fixes handed to the core.
  int take_inputs(std::int64_t now_ns);

  bool odometry_done() const { return !odometry_ || odom_i_ >= odometry_->size(); }
  const localizer::Localizer& core() const { return core_; }
  localizer::Localizer& core() { return core_; }

 private:
  // Replay odometry and gyro rows up to up_to_ns, merged in time order (odometry first on equal
  // times: the filter refuses gyro samples ahead of the newest odometry).
  void drain_odometry(std::int64_t up_to_ns);
  void send(const localizer::OutFrames& out);

  localizer::Localizer& core_;
  hal::CanBus* bus_;
  const hal::Clock& clock_;
  const std::vector<recording::OdomRow>* odometry_;
  std::size_t odom_i_ = 0;
  const std::vector<recording::ImuRow>* imu_;
  std::size_t imu_i_ = 0;
  std::vector<recording::OdomRow>* received_ = nullptr;
  GyroRing* live_gyro_ = nullptr;
  RangingRing* ranging_ = nullptr;
  RangingRecord ranging_rec_;  // the ring's front, kept here: 2.5 kB
  std::vector<OutputSink*> sinks_;
  TickRecord last_tick_;
  bool have_tick_ = false;
  std::uint64_t odometry_not_recorded_ = 0;
  FixRing& fixes_;
  std::int64_t log_period_ns_;
  PeriodicDue log_due_;
  localizer::CanOutput can_;  // the CAN encoding of the core's output (alive counters, E2E)
  localizer::OutFrames frames_;
};

}  // namespace agv::app
