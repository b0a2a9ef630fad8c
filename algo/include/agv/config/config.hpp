// The localizer's configuration: one YAML text, validated completely. Every key, its type,
// default, accepted range and trade-off is one record of the key table (agv/config/keys.hpp);
// the checker, the defaults test and docs/guide/config.md are all produced from that table. Pure:
// YAML text in, structs and error lines out (file reading: firmware/src/config.hpp).
#pragma once

#include <cmath>
#include <cstdint>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include "agv/common/camera_model.hpp"
#include "agv/fusion/ekf.hpp"
#include "agv/hal/camera.hpp"
#include "agv/localizer/time_base.hpp"
#include "agv/protocol/codec.hpp"
#include "agv/ranging/range_models.hpp"
#include "agv/vision/landmark_localizer.hpp"

namespace agv::config {

// The choice keys' values as enums: each name is converted once, by the key table's row (which
// reads these tables); code compares enums. *_name gives the name back for messages.
enum class CameraDriver : std::uint8_t { kLibcamera, kV4l2, kReplay };
enum class ImuSource : std::uint8_t { kCan, kIio, kNone };
inline constexpr std::pair<std::string_view, CameraDriver> kCameraDriverNames[] = {
    {"libcamera", CameraDriver::kLibcamera},
    {"v4l2", CameraDriver::kV4l2},
    {"replay", CameraDriver::kReplay}};
inline constexpr std::pair<std::string_view, ImuSource> kImuSourceNames[] = {
    {"can", ImuSource::kCan}, {"iio", ImuSource::kIio}, {"none", ImuSource::kNone}};
inline constexpr std::pair<std::string_view, protocol::OdometryMode> kOdometryModeNames[] = {
    {"v_omega", protocol::OdometryMode::kTwist}, {"wheels", protocol::OdometryMode::kWheels}};

template <typename E, std::size_t N>
const char* choice_name(const std::pair<std::string_view, E> (&table)[N], E e) {
  for (const auto& [n, v] : table) {
    if (v == e) return n.data();  // a literal: NUL-terminated
  }
  return "?";
}
inline const char* camera_driver_name(CameraDriver d) { return choice_name(kCameraDriverNames, d); }
inline const char* imu_source_name(ImuSource s) { return choice_name(kImuSourceNames, s); }
inline const char* odometry_mode_name(protocol::OdometryMode m) {
  return choice_name(kOdometryModeNames, m);
}

// Defaults here must equal the key table's (test_config: DefaultsEqualTheTable); the meaning of
// each field is documented once, in the table (docs/guide/config.md).
struct CameraSection {
  CameraDriver driver = CameraDriver::kLibcamera;
  hal::CameraConfig camera;
  double timeout_ms = 500.0;
  double time_offset_ms = 0.0;  // -> localizer::TimeBase::camera_offset_ns
};

struct CanSection {
  std::string interface = "can0";
  std::uint32_t base_id = 0x300;
  bool extended_ids = false;
  protocol::OdometryMode odometry_mode = protocol::OdometryMode::kTwist;
  std::uint32_t odometry_id = 0;
  bool odometry_protected = true;
  // The track width (key can.odometry.track_width_mm) lives in fusion.wheel_track_mm only.
  double wheel_speed_scale = 1.0;
  // The odometry timeout (key can.odometry.timeout_ms) lives in fusion.odom_timeout_ns only.
  // The gyro input AGV_Gyro (protocol::GyroConfig; ID type = can.extended_ids).
  bool gyro_enabled = false;
  std::uint32_t gyro_id = 0;
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
  ImuSource source = ImuSource::kCan;
  std::string iio_device;
  std::string iio_trigger;
  double iio_rate_hz = 200.0;
};

struct LoopSection {
  double output_rate_hz = 100.0;
  double heartbeat_rate_hz = 1.0;
  int realtime_priority = 0;
  int vision_priority = 0;
  int spin_before_deadline_us = 0;
  std::string realtime_cpus;  // CPU lists (config/cpu_list.hpp)
  std::string vision_cpus;
  std::string service_cpus;
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
  std::string version = "2.1.0";
  std::string manufacturer = "agvloc";
  std::string serial_number = "agv-0001";
  std::string map_id = "default";
  double rate_hz = 10.0;
  std::string username;
  std::string password_file;  // resolved relative to the config file by parse_config
  std::string tls_ca_file;    // resolved relative to the config file by parse_config
};

// Live diagnostics page and /metrics (docs/guide/diagnostics.md); the firmware's diagnostics server
// reads it.
struct DiagSection {
  bool enabled = false;
  std::string bind_address = "127.0.0.1";
  int port = 8088;
  bool allow_remote = false;
  int max_clients = 16;
  int threads = 2;
  double frame_interval_ms = 500.0;
};

// The second camera, looking at landmarks on racks (docs/design/ranging.md): its stream as the
// floor camera's, its own calibration and 6-DoF mount, and the site file whose vertical
// landmarks it reads.
inline hal::CameraConfig ranging_camera_stream() {
  hal::CameraConfig c;
  c.width_px = 1280;
  c.height_px = 800;
  c.fps = 15.0;
  c.exposure_us = 2000;
  return c;
}
struct RangingCameraSection {
  bool enabled = false;
  CameraDriver driver = CameraDriver::kLibcamera;
  hal::CameraConfig camera = ranging_camera_stream();
  double time_offset_ms = 0.0;  // -> localizer::RangingAidConfig::camera_offset_ns
  // Resolved relative to the configuration file; required when enabled.
  std::string site_file;
  CameraIntrinsics intrinsics;  // image size from camera.width_px / height_px
  ranging::RangingMount mount;
  // The calibration's doubt (1 sigma): each mount angle, each mount offset, a systematic error of
  // an undistorted point (px), the focal length's relative error (ranging::ObserveOptions).
  double mount_sigma_rad = 0.0;
  double mount_sigma_mm = 0.0;
  double calibration_sigma_px = 0.0;
  double focal_sigma_rel = 0.0;
  bool shallow_pairs_from_face_yaws = true;  // ranging::FixOptions::face_yaw_pairs_below_crossing
  bool predicted_first = true;               // ranging::WindowOptions::predicted_first
  std::int64_t sweep_interval_frames = 150;  // ranging::WindowOptions::full_sweep_interval_frames
  double interval_sweep_decimate = 2.0;      // ranging::ObserveOptions::interval_sweep_decimate
};

// The doubt every bearing of a second-camera frame shares: the mount's yaw and the principal
// point's column (calibration_sigma_px / fx), 1 sigma.
inline double common_bearing_sigma_rad(const RangingCameraSection& r) {
  const double pp_rad = r.intrinsics.fx > 0.0 ? r.calibration_sigma_px / r.intrinsics.fx : 0.0;
  return std::hypot(r.mount_sigma_rad, pp_rad);
}

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
  RangingCameraSection ranging_camera;
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
// The CAN protocol configuration implied by the can section, the gyro input (can.gyro.*)
// included.
protocol::ProtocolConfig protocol_config(const Config& cfg);

// The printed landmark's geometry (landmark.size_mm; the rest at its defaults).
inline LandmarkGeometry landmark_geometry(const Config& cfg) {
  LandmarkGeometry g;
  g.size_mm = cfg.landmark_size_mm;
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
