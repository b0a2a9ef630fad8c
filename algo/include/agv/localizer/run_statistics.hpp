// Statistics of one localizer run (live or replay): what the capture, vision, fusion and output
// stages did, with latency histograms, and the block `agvloc` prints at exit. Pure: the firmware
// fills it from its threads and drivers.
#pragma once

#include <cstdint>
#include <string>

#include "agv/common/latency_histogram.hpp"
#include "agv/hal/camera.hpp"
#include "agv/hal/can_types.hpp"
#include "agv/localizer/localizer.hpp"
#include "agv/vision/landmark_localizer.hpp"

namespace agv::localizer {

inline constexpr int kFixStatusCount = 9;

struct VisionStats {
  std::uint64_t frames_processed = 0;
  std::uint64_t by_status[kFixStatusCount] = {};
  LatencyHistogram exposure_to_start_ns;  // frame exposure mid-time -> vision start
  LatencyHistogram vision_ns;             // whole vision stage
  LatencyHistogram detect_ns, decode_ns, direction_ns, pose_ns;
};

struct RunResult {
  OutputStats output;
  VisionStats vision;
  hal::CameraStats camera;
  std::uint64_t frames_dropped_mailbox = 0;  // newest-wins replacements
  std::uint64_t fixes_dropped_queue = 0;
  std::uint64_t odometry_rejected_can = 0;
  // The CAN odometry decoder's counters by reason (odometry_rejected_can is their sum).
  protocol::OdometryCounters odometry_can;
  // Output ticks and vision results the threaded run could not keep in its record (the --out
  // CSVs): the record is allocated before the run and not grown by the real-time threads, so a
  // run that outlasts it loses rows. Reported, never silent.
  std::uint64_t ticks_not_recorded = 0;
  std::uint64_t fixes_not_recorded = 0;
  std::uint64_t odometry_not_recorded = 0;  // odom_received.csv (replay --odom-from-can)
  hal::CanStats can;
  bool can_present = false;
  std::int64_t wall_ns = 0;
  std::string camera_error;     // last camera error, if any
  bool simulated_time = false;  // --fast: latencies other than the vision stage are simulated
};

// Counts one vision result and its stage times (exposure_to_start_ns: frame exposure -> vision
// start; vision_ns: the whole stage).
void record_vision(const vision::LandmarkFix& fix, std::int64_t exposure_to_start_ns,
                   std::int64_t vision_ns, VisionStats* vs);

// Human-readable statistics block (printed at exit).
std::string format_statistics(const RunResult& r);

}  // namespace agv::localizer
