// The localizer's configuration: one YAML file, validated at start. Every key, its default and
// its accepted range: docs/config.md. Example: firmware/config/agvloc.yaml.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "agv/common/camera_model.hpp"
#include "agv/common/landmark.hpp"
#include "agv/fusion/ekf.hpp"
#include "agv/hal/camera.hpp"
#include "agv/protocol/codec.hpp"
#include "agv/vision/landmark_localizer.hpp"

namespace agv::config {

struct CameraSection {
  std::string driver = "libcamera";  // libcamera | v4l2 | replay
  hal::CameraConfig camera;
  // No frame for this long -> camera flagged stalled; fusion keeps dead-reckoning.
  double timeout_ms = 500.0;
};

struct CanSection {
  std::string interface = "can0";
  std::uint32_t base_id = 0x300;
  bool extended_ids = false;
  std::string odometry_mode = "v_omega";  // v_omega | wheels
  std::uint32_t odometry_id = 0;          // 0 = the DBC's ID: base_id + 0x10 (wheels) / 0x11
  bool odometry_protected = true;         // E2E counter + CRC checked on odometry input
  double track_width_mm = 500.0;          // wheels mode: distance between the wheel contact points
  double wheel_speed_scale = 1.0;         // wheels mode: multiplies decoded wheel speeds
  double odometry_timeout_ms = 100.0;
};

struct LoopSection {
  double output_rate_hz = 100.0;  // pose, velocity, quality, status frames
  double heartbeat_rate_hz = 1.0;
  int realtime_priority = 0;  // SCHED_FIFO priority of the output thread; 0 = off
  // SCHED_FIFO priority of the capture and vision threads; 0 = normal scheduling. Must be below
  // realtime_priority so vision can never delay the fixed-rate output. Shortens the exposure ->
  // fix latency under CPU contention, at the cost of starving normal tasks on a core while a
  // frame is processed.
  int vision_priority = 0;
  // Hybrid wait of the output thread: sleep to (deadline - spin), then busy-poll the clock to the
  // deadline. Removes the kernel's wake-up latency from the period jitter for up to this many
  // microseconds, at the cost of that much busy CPU per period. 0 = plain absolute sleep.
  int spin_before_deadline_us = 0;
  bool lock_memory = false;    // mlockall at start
  double log_period_s = 10.0;  // periodic statistics line; 0 = off
  // Also send the pose pair right after a fix is fused, outside the fixed schedule: the
  // correction reaches the bus ~1 vision-time after exposure instead of waiting up to one output
  // period, at the cost of irregular pose-frame spacing (receivers must not derive speed from
  // pose-frame intervals). The fixed-rate stream (all frames every period) runs either way. On by
  // default: without it the end-to-end latency is bounded below by the period
  // (docs/performance.md).
  bool pose_on_fix = true;
};

struct Config {
  CameraSection camera;
  CameraModel camera_model;  // intrinsics + mounting
  double landmark_size_mm = 60.0;
  std::string map_file;  // resolved relative to the config file; empty = payload poses only
  CanSection can;
  LoopSection loop;
  // Algorithm sections, read by config_algo.cpp.
  vision::VisionConfig vision;
  fusion::EkfConfig fusion;
  // Replay only: delay between a frame's exposure and its fix reaching fusion in --fast mode
  // (live, it is whatever the vision worker takes).
  double replay_fix_delay_ms = 30.0;
  std::string source;  // file name the config came from, for messages
};

// What the configuration is read for. kLive (run, record, --check-config) requires the camera
// calibration (intrinsics fx, fy, cx, cy); kReplay takes the camera from the recording's
// meta.yaml, so intrinsics may be absent (if present they are still checked).
enum class ConfigUse { kLive, kReplay };

// Size caps of the files the localizer reads (docs/security.md); larger files are errors.
inline constexpr std::uintmax_t kMaxConfigBytes = 1u << 20;  // 1 MiB
inline constexpr std::uintmax_t kMaxMapBytes = 4u << 20;     // 4 MiB (65535 landmarks ~ 2.6 MB)

// Parses YAML text. On error returns false and fills *errors with one line per problem, each
// naming the key path and accepted range ("can.base_id: value 4096 outside ..."). Unknown,
// duplicate and non-scalar keys are errors; never throws.
bool parse_config(const std::string& yaml_text, const std::string& base_dir, Config* out,
                  std::vector<std::string>* errors, ConfigUse use = ConfigUse::kLive);
// The CAN protocol configuration implied by the can section.
protocol::ProtocolConfig protocol_config(const Config& cfg);

// Reads and parses a file (base_dir = the file's directory). The file must be a regular file of
// at most kMaxConfigBytes.
bool load_config(const std::string& path, Config* out, std::vector<std::string>* errors,
                 ConfigUse use = ConfigUse::kLive);
// load_config for the entry points: prints every error as "<who>: config: <error>".
bool load_config_or_report(const std::string& path, const char* who, Config* out,
                           ConfigUse use = ConfigUse::kLive);
// Reads a landmark map file (docs/landmark.md; a regular file of at most kMaxMapBytes); false
// with *error naming file and line.
bool load_map_file(const std::string& path, LandmarkMap* map, std::string* error);

}  // namespace agv::config
