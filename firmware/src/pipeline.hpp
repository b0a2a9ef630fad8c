// The localizer loop: capture -> vision worker -> fusion -> CAN output at a fixed rate.
// `run_threads` is the live shape (three threads, absolute-time periodic output) used by
// `agvloc run` and `agvloc replay --realtime`; `run_fast` drives the same stages from one
// thread in recording time as fast as the CPU allows (`agvloc replay --fast`).
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
#include "agv/recording/recording.hpp"
#include "agv/vision/landmark_localizer.hpp"
#include "config.hpp"
#include "output_stage.hpp"

namespace agv::app {

inline constexpr int kFixStatusCount = 9;

struct VisionStats {
  std::uint64_t frames_processed = 0;
  std::uint64_t by_status[kFixStatusCount] = {};
  LatencyHistogram exposure_to_start_ns;  // frame exposure mid-time -> vision start
  LatencyHistogram vision_ns;             // whole vision stage
  LatencyHistogram detect_ns, decode_ns, direction_ns, pose_ns;
};

struct FixRecord {
  std::int64_t t_exposure_ns = 0;
  std::int64_t t_done_ns = 0;  // when the fix was handed to fusion
  vision::LandmarkFix fix;
};

struct RunResult {
  OutputStats output;
  VisionStats vision;
  hal::CameraStats camera;
  std::uint64_t frames_dropped_mailbox = 0;  // newest-wins replacements
  std::uint64_t fixes_dropped_queue = 0;
  std::uint64_t odometry_rejected_can = 0;
  hal::CanStats can;
  bool can_present = false;
  std::int64_t wall_ns = 0;
  std::string camera_error;     // last camera error, if any
  bool simulated_time = false;  // --fast: latencies other than the vision stage are simulated
};

struct PipelineIo {
  hal::Camera* camera = nullptr;
  hal::CanBus* bus = nullptr;   // null: no CAN output / input
  hal::Clock* clock = nullptr;  // loop clock (monotonic, or scaled replay time)
  // Replay odometry (recording time == loop clock time); null: odometry comes from CAN.
  const std::vector<recording::OdomRow>* odometry = nullptr;
  // Optional outputs, reserved by the caller (the loop never grows them past their capacity).
  std::vector<TickRecord>* ticks = nullptr;
  std::vector<FixRecord>* fixes = nullptr;
  std::atomic<bool>* stop = nullptr;  // set by signal handlers
  // Stop when the camera reports end of stream and replay odometry is used up.
  bool stop_at_end_of_stream = true;
  bool quiet = false;  // no periodic log lines
};

// Runs until *io.stop or end of stream. Returns 0, or 1 when the loop could not start.
int run_threads(const config::Config& cfg, const LandmarkMap* map, PipelineIo& io,
                RunResult* result);

// Fast replay: frames, odometry and output ticks interleaved in recording time; each fix reaches
// fusion cfg.replay_fix_delay_ms after its exposure. Deterministic for a recording.
int run_fast(const config::Config& cfg, const LandmarkMap* map, const recording::Recording& rec,
             hal::CanBus* bus, std::vector<TickRecord>* ticks, std::vector<FixRecord>* fixes,
             std::atomic<bool>* stop, RunResult* result, bool show_progress,
             std::atomic<std::int64_t>* loop_time_ns = nullptr);

// Human-readable statistics block (printed at exit).
std::string format_statistics(const RunResult& r);

}  // namespace agv::app
