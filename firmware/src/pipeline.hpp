// The localizer loop: capture -> vision worker -> fusion -> CAN output at a fixed rate.
// `run_threads` is the live shape (three threads, absolute-time periodic output) used by
// `agvloc run` and `agvloc replay --realtime`; `run_fast` drives the same output step
// (OutputLoop) from one thread on a stepped clock in recording time (`agvloc replay --fast`).
#pragma once

#include <atomic>
#include <cstdint>
#include <string>
#include <vector>

#include "agv/common/landmark.hpp"
#include "agv/common/latency_histogram.hpp"
#include "agv/hal/camera.hpp"
#include "agv/hal/can_bus.hpp"
#include "agv/hal/clock.hpp"
#include "agv/localizer/run_statistics.hpp"
#include "agv/recording/recording.hpp"
#include "agv/vision/landmark_localizer.hpp"
#include "config.hpp"
#include "diag_handoff.hpp"
#include "output_loop.hpp"
#include "ranging_stream.hpp"

namespace agv::app {

using localizer::RunResult;
using localizer::VisionStats;

struct PipelineIo {
  hal::Camera* camera = nullptr;
  hal::CanBus* bus = nullptr;   // null: no CAN output / input
  hal::Clock* clock = nullptr;  // loop clock (monotonic, or scaled replay time)
  // Replay odometry (recording time == loop clock time); null: odometry comes from CAN.
  const std::vector<recording::OdomRow>* odometry = nullptr;
  // Replay gyro samples (imu.csv, recording time == loop clock time); null: none.
  const std::vector<recording::ImuRow>* imu = nullptr;
  // Optional outputs, reserved by the caller (the loop never grows them past their capacity).
  std::vector<TickRecord>* ticks = nullptr;
  std::vector<FrameRecord>* fixes = nullptr;
  // Odometry decoded from CAN, as fusion got it (OutputLoop::keep_received_odometry).
  std::vector<recording::OdomRow>* odometry_received = nullptr;
  std::atomic<bool>* stop = nullptr;  // set by signal handlers
  GyroRing* live_gyro = nullptr;      // imu.source iio: the reader thread's samples; null: none
  // The outputs besides CAN, in order (the VDA 5050 publisher's and the diagnostics page's
  // hand-offs); run_threads adds the fault journal unless quiet.
  std::vector<OutputSink*> sinks;
  FrameTap* diag_frames = nullptr;  // camera frames for the page (vision thread); null: none
  // Stop when the camera reports end of stream and replay odometry is used up.
  bool stop_at_end_of_stream = true;
  // Odometry from CAN (`replay --odom-from-can`): the last odometry time of the recording being
  // played onto the bus. The run then also lasts until that time plus the odometry timeout
  // (fusion.odom_timeout_ns), so the bus's last frames are received, not cut off when the camera's
  // last frame is done (HIL: "1 sent but not received", the recording's last row). INT64_MIN:
  // no such wait.
  std::int64_t can_odometry_end_ns = INT64_MIN;
  bool quiet = false;  // no periodic log lines
  // ranging_camera.enabled: the second camera's frames, read by rack_observer, counted in
  // ranging_counts (written by the run, read after it). run_fast takes the recording's second
  // stream (ranging_frames), run_threads a camera (ranging_camera: live, or a replay of that
  // stream); without rack_observer and ranging_counts neither is read.
  const recording::Recording* ranging_frames = nullptr;
  hal::Camera* ranging_camera = nullptr;
  RackObserver* rack_observer = nullptr;
  RangingCounts* ranging_counts = nullptr;
};

// Runs until *io.stop or end of stream. Returns 0, or 1 when the loop could not start.
int run_threads(const config::Config& cfg, const LandmarkMap* map, PipelineIo& io,
                RunResult* result);

// Fast replay on a stepped clock (*io.clock, e.g. adapters::SteppedClock, which the bus may also
// read): time advances in recording time; the vision stage runs inline for the recording's frames
// exposed up to now; each fix arrives cfg.replay_fix_delay_ms after its exposure, where with
// loop.pose_on_fix the output step is woken as live. io.odometry and io.imu are the inputs fused
// (the recording's odom.csv and imu.csv); io.camera, io.live_gyro, io.odometry_received and
// io.can_odometry_end_ns are not used; no log lines (io.quiet does not apply). Deterministic for
// a recording.
int run_fast(const config::Config& cfg, const LandmarkMap* map, const recording::Recording& rec,
             PipelineIo& io, RunResult* result, bool show_progress);

using localizer::format_statistics;

}  // namespace agv::app
