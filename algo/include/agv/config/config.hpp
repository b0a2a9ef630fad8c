// The localizer's configuration: one YAML text, validated completely. Every key, its type,
// default, accepted range and trade-off is one record of the key table (agv/config/keys.hpp);
// the checker, the defaults test and docs/guide/config.md are all produced from that table. Pure:
// YAML text in, structs and error lines out (file reading: firmware/src/config.hpp).
#pragma once

#include <cmath>
#include <cstdint>
#include <string>
#include <vector>

#include "agv/common/camera_model.hpp"
#include "agv/fusion/ekf.hpp"
#include "agv/hal/camera.hpp"
#include "agv/localizer/time_base.hpp"
#include "agv/protocol/codec.hpp"
#include "agv/vision/landmark_localizer.hpp"

namespace agv::config {

// Defaults here must equal the key table's (test_config: DefaultsEqualTheTable); the meaning of
// each field is documented once, in the table (docs/guide/config.md).
struct CameraSection {
  std::string driver = "libcamera";  // libcamera | v4l2 | replay
  hal::CameraConfig camera;
  double timeout_ms = 500.0;
  double time_offset_ms = 0.0;  // -> localizer::TimeBase::camera_offset_ns
};

struct CanSection {
  std::string interface = "can0";
  std::uint32_t base_id = 0x300;
  bool extended_ids = false;
  std::string odometry_mode = "v_omega";  // v_omega | wheels
  std::uint32_t odometry_id = 0;          // 0 = the DBC's ID: base_id + 0x10 (wheels) / 0x11
  bool odometry_protected = true;
  // The track width (key can.odometry.track_width_mm) lives in fusion.wheel_track_mm only.
  double wheel_speed_scale = 1.0;
  // The odometry timeout (key can.odometry.timeout_ms) lives in fusion.odom_timeout_ns only.
  // The gyro input AGV_Gyro (protocol::GyroConfig; ID type = can.extended_ids).
  bool gyro_enabled = false;
  std::uint32_t gyro_id = 0;  // 0 = the DBC's ID: base_id + 0x12
  bool gyro_protected = true;
  double gyro_timeout_ms = 100.0;  // -> LocalizerConfig::gyro_timeout_ns
};

// The odometry correction (localizer::OdometryCorrection; written by calibrate vehicle).
struct OdometrySection {
  double speed_scale = 1.0;
  double yaw_rate_scale = 1.0;
  double yaw_rate_bias_radps = 0.0;
  double yaw_per_metre_rad = 0.0;
};

// The gyro correction (localizer::GyroCorrection).
struct ImuSection {
  double scale = 1.0;
  double bias_radps = 0.0;
  double time_offset_ms = 0.0;  // -> localizer::TimeBase::gyro_offset_ns
  // Where the gyro comes from: "can" (AGV_Gyro when can.gyro.enabled), "iio" (a Linux IIO
  // device, drivers/iio), "none" (wheels only).
  std::string source = "can";
  std::string iio_device;      // IIO device name (e.g. "bmi160")
  std::string iio_trigger;     // IIO trigger name; empty = the device's own
  double iio_rate_hz = 200.0;  // 0 = leave the device's rate
};

struct LoopSection {
  double output_rate_hz = 100.0;
  double heartbeat_rate_hz = 1.0;
  int realtime_priority = 0;
  int vision_priority = 0;
  int spin_before_deadline_us = 0;
  std::string realtime_cpus;  // CPU list (config/cpu_list.hpp); empty = not pinned
  std::string vision_cpus;    // CPU list; empty = not pinned
  std::string service_cpus;   // CPU list; empty = not pinned
  bool lock_memory = false;
  double log_period_s = 10.0;
  bool pose_on_fix = true;
};

// VDA 5050 position over MQTT (docs/guide/vda5050.md); the firmware's MQTT publisher reads it.
struct Vda5050Section {
  bool enabled = false;
  std::string broker_host = "localhost";
  int broker_port = 1883;
  std::string interface_name = "uagv";
  std::string version = "2.1.0";  // 2.1.0 | 3.0.0
  std::string manufacturer = "agvloc";
  std::string serial_number = "agv-0001";
  std::string map_id = "default";
  double rate_hz = 10.0;      // visualization messages
  std::string username;       // empty = anonymous
  std::string password_file;  // resolved relative to the config file; empty = no password
  std::string tls_ca_file;    // resolved relative to the config file; empty = plain TCP
};

// Live diagnostics page and /metrics (docs/guide/diagnostics.md); the firmware's diagnostics server
// reads it.
struct DiagSection {
  bool enabled = false;
  std::string bind_address = "127.0.0.1";
  int port = 8088;  // 0 = any free port (printed at start)
  bool allow_remote = false;
  int max_clients = 16;
  int threads = 2;
  double frame_interval_ms = 500.0;
};

struct Config {
  CameraSection camera;
  CameraModel camera_model;  // intrinsics + mounting
  double landmark_size_mm = 60.0;
  std::string map_file;  // resolved relative to the config file; empty = payload poses only
  CanSection can;
  OdometrySection odometry;
  ImuSection imu;
  LoopSection loop;
  vision::VisionConfig vision;
  fusion::EkfConfig fusion;
  double replay_fix_delay_ms = 30.0;
  Vda5050Section vda5050;
  DiagSection diag;
  std::string source;  // file name the config came from, for messages
};

// What the configuration is read for. kLive (run, record, --check-config) requires the camera
// calibration (intrinsics fx, fy, cx, cy); kReplay takes the camera from the recording's
// meta.yaml, so intrinsics may be absent (if present they are still checked).
enum class ConfigUse { kLive, kReplay };

// Parses YAML text. On error returns false and fills *errors with one line per problem, each
// naming the key path and accepted range ("can.base_id: value 4096 outside ..."). Unknown,
// removed, duplicate and non-scalar keys are errors; never throws. base_dir resolves a relative
// landmark.map (a path operation only: nothing is read).
bool parse_config(const std::string& yaml_text, const std::string& base_dir, Config* out,
                  std::vector<std::string>* errors, ConfigUse use = ConfigUse::kLive);
// The CAN protocol configuration implied by the can section.
protocol::ProtocolConfig protocol_config(const Config& cfg);
// The gyro part of it (can.gyro.*): protocol_config(cfg).gyro is left at its defaults (disabled),
// so whoever receives AGV_Gyro sets ProtocolConfig::gyro from this (firmware localizer_config).
inline protocol::GyroConfig gyro_protocol_config(const Config& cfg) {
  protocol::GyroConfig g;
  g.enabled = cfg.can.gyro_enabled;
  g.can_id = cfg.can.gyro_id;
  g.protected_e2e = cfg.can.gyro_protected;
  return g;
}

// The time base the camera and gyro offsets (camera.time_offset_ms, imu.time_offset_ms) imply,
// built here once for the core and the threaded loop alike.
inline localizer::TimeBase time_base(const Config& cfg) {
  localizer::TimeBase t;
  t.camera_offset_ns = std::llround(cfg.camera.time_offset_ms * 1e6);
  t.gyro_offset_ns = std::llround(cfg.imu.time_offset_ms * 1e6);
  return t;
}

}  // namespace agv::config
