// Encoder for the localizer's output frames and decoders for the input frames (odometry, gyro)
// (layout: signals.hpp, contract: can/agvloc.dbc, rules: docs/guide/can.md). Pure: no I/O, no
// clocks, no heap; time is an argument.
#pragma once

#include <cstdint>
#include <string>

#include "agv/common/track_width.hpp"
#include "agv/protocol/can_frame.hpp"
#include "agv/protocol/e2e.hpp"
#include "agv/protocol/signals.hpp"

namespace agv::protocol {

enum class OdometryMode : std::uint8_t {
  kWheels = 0,  // MC_OdomWheels: left and right wheel ground speeds
  kTwist = 1,   // MC_OdomTwist: v and omega of the reference point
};

struct OdometryConfig {
  OdometryMode mode = OdometryMode::kWheels;
  // CAN ID of the odometry frame. Default base_id + 0x10 (wheels) / + 0x11 (twist) when 0.
  std::uint32_t can_id = 0;
  bool extended_id = false;
  // true: CRC and alive counter are checked (E2E as for our own frames). Motor controllers that
  // cannot compute the CRC set false; then only ID and length are checked.
  bool protected_e2e = true;
  std::uint16_t data_id = 0;           // 0 = the DBC's data ID for the selected mode
  std::uint8_t max_delta_counter = 3;  // see E2eCheckerConfig
  // Distance between the wheel contact points (wheels mode only; key can.odometry.track_width_mm).
  double track_width_mm = kDefaultTrackWidthMm;
  // Multiplies decoded speeds (wheel speeds, or v) / omega: calibrates wheel radius errors.
  // 1.0 = the DBC scaling is exact.
  double speed_scale = 1.0;
  double omega_scale = 1.0;
};

// The gyro input AGV_Gyro (Msg::kGyro). Its ID type is the odometry's
// (OdometryConfig::extended_id): both inputs come from the vehicle side of the same bus.
struct GyroConfig {
  // Receive AGV_Gyro at all (Localizer: a receive filter, decoding, fusion, FaultImu* flags).
  // GyroDecoder itself decodes whatever it is given.
  bool enabled = false;
  // CAN ID of the gyro frame. Default base_id + 0x12 (signals.cpp) when 0.
  std::uint32_t can_id = 0;
  // true: CRC and alive counter are checked; false: only ID and length (as for odometry).
  bool protected_e2e = true;
  std::uint16_t data_id = 0;           // 0 = the DBC's data ID (0x4C12)
  std::uint8_t max_delta_counter = 3;  // see E2eCheckerConfig
};

struct ProtocolConfig {
  // CAN ID of AGV_PoseXY; the other output frames follow at +1..+5 (signals.hpp id_offset).
  std::uint32_t base_id = 0x300;
  bool extended_ids = false;  // 29-bit IDs for the output frames
  OdometryConfig odometry;
  GyroConfig gyro;
  // The periods the output messages are sent at (keys loop.output_rate_hz and
  // loop.heartbeat_rate_hz): the DBC's GenMsgCycleTime of the output messages comes from here,
  // so a vehicle configured at another rate gets a DBC that says so. The signal table's
  // cycle_ms are these defaults (checked by a test).
  double output_period_ms = 10.0;
  double heartbeat_period_ms = 1000.0;
};

// Empty string when valid; otherwise why not (ID does not fit 11/29 bits, track width <= 0, an
// enabled gyro ID equal to an output or the odometry ID, ...).
std::string validate(const ProtocolConfig& cfg);

// CAN ID of message m under cfg (input IDs honour OdometryConfig::can_id / GyroConfig::can_id).
std::uint32_t can_id_of(const ProtocolConfig& cfg, Msg m);
bool is_extended(const ProtocolConfig& cfg, Msg m);
// True for the input (kRx) messages the localizer receives under cfg: the odometry variant of
// OdometryConfig::mode, and AGV_Gyro when GyroConfig::enabled. False for every output message.
bool rx_enabled(const ProtocolConfig& cfg, Msg m);
// GenMsgCycleTime of message m under cfg, in whole ms: the configured periods for the output
// messages (the heartbeat its own), the signal table's nominal period for the inputs (what the
// motor controller is expected to send).
std::uint32_t cycle_ms_of(const ProtocolConfig& cfg, Msg m);

struct PoseOut {
  double x_mm = 0.0;
  double y_mm = 0.0;
  double theta_rad = 0.0;   // wrapped to (-pi, pi] before encoding
  double latency_ms = 0.0;  // age of the estimate at encoding time
  bool valid = false;
};
// PoseValid of AGV_PoseXY / AGV_PoseHeading for p: p.valid (set by the localizer: initialised, not
// lost, odometry flowing) and a finite pose. The one definition: the encoder sends it, the
// diagnostics page and /metrics show it (localizer::TickRecord::pose_valid).
bool pose_valid_on_can(const PoseOut& p);
struct VelocityOut {
  double v_mps = 0.0;
  double omega_radps = 0.0;
  bool valid = false;
};
struct QualityOut {
  double sigma_x_mm = 0.0;
  double sigma_y_mm = 0.0;
  double sigma_theta_rad = 0.0;
  bool valid = false;
  // A map-guided fix (identity from the prediction, QR unreadable; docs/design/map_identity.md) was
  // fused since the previous quality frame: the sigmas rest partly on the filter's own belief.
  bool map_guided_fix = false;
};

enum class Health : std::uint8_t { kOk = 0, kDegraded = 1, kLost = 2, kFault = 3 };

// Fault flags: bits 0..7 = the Fault* signals of AGV_Status in byte 6 (bits 48..55, signals.cpp
// order); bits 8, 9 = FaultImuTimeout / FaultImuE2E (frame bits 14, 15: byte 6 is full).
namespace fault {
inline constexpr std::uint8_t kCameraStalled = 1u << 0;
inline constexpr std::uint8_t kCameraError = 1u << 1;
inline constexpr std::uint8_t kOdomTimeout = 1u << 2;
inline constexpr std::uint8_t kOdomE2E = 1u << 3;
inline constexpr std::uint8_t kCanErrorPassive = 1u << 4;
inline constexpr std::uint8_t kCanBusOff = 1u << 5;
inline constexpr std::uint8_t kNoMap = 1u << 6;
inline constexpr std::uint8_t kLoopOverrun = 1u << 7;
// No usable gyro sample within the gyro timeout (condition flag).
inline constexpr std::uint16_t kImuTimeout = 1u << 8;
// AGV_Gyro frames rejected by the decoder since the last status frame (event flag).
inline constexpr std::uint16_t kImuE2E = 1u << 9;
}  // namespace fault
namespace reject {
inline constexpr std::uint8_t kGate = 1u << 0;
inline constexpr std::uint8_t kUnknownLandmark = 1u << 1;
inline constexpr std::uint8_t kDecodeFailed = 1u << 2;
inline constexpr std::uint8_t kGeometry = 1u << 3;
inline constexpr std::uint8_t kFixTooOld = 1u << 4;
}  // namespace reject

struct StatusOut {
  Health health = Health::kLost;
  std::uint16_t last_landmark_id = 0;  // meaningful only when last_landmark_valid
  // A fix has been accepted since start (id 0 is tag36h11's first tag, not "none").
  bool last_landmark_valid = false;
  double time_since_fix_ms = -1.0;  // negative or non-finite = never (sent as 65535)
  std::uint16_t faults = 0;         // fault::* (bits 10..15 must be 0)
  std::uint8_t rejections = 0;      // reject::* (bits 5..7 must be 0)
};
struct HeartbeatOut {
  std::uint8_t sw_major = 0;
  std::uint8_t sw_minor = 0;
  std::uint8_t sw_patch = 0;
  double uptime_s = 0.0;
};

// Fills 8-byte frames with ID, data, alive counter and CRC. One counter per output message,
// starting at 0. Non-finite values clear the frame's valid flag and encode 0 (NaN) or saturate
// (+-inf); finite values beyond the range saturate.
class Encoder {
 public:
  explicit Encoder(const ProtocolConfig& cfg);
  // Writes the AGV_PoseXY / AGV_PoseHeading pair; both get the same counter value.
  void encode_pose(const PoseOut& p, hal::CanFrame* xy, hal::CanFrame* heading);
  void encode_velocity(const VelocityOut& v, hal::CanFrame* out);
  void encode_quality(const QualityOut& q, hal::CanFrame* out);
  void encode_status(const StatusOut& s, hal::CanFrame* out);
  void encode_heartbeat(const HeartbeatOut& h, hal::CanFrame* out);
  // The counter the next frame of m will carry (tests, diagnostics).
  std::uint8_t next_counter(Msg m) const { return counters_[static_cast<int>(m)]; }

 private:
  void begin(Msg m, hal::CanFrame* out) const;
  void finish(Msg m, hal::CanFrame* out);
  ProtocolConfig cfg_;
  std::uint8_t counters_[static_cast<int>(Msg::kCount)] = {};
};

// Typed decoding of output frames (tests, HIL checks, log inspection). Returns false when the
// frame is not the expected message (ID, length); the E2E check is separate (E2eChecker).
bool decode_pose(const ProtocolConfig& cfg, const hal::CanFrame& xy, const hal::CanFrame& heading,
                 PoseOut* out);
bool decode_velocity(const ProtocolConfig& cfg, const hal::CanFrame& f, VelocityOut* out);
bool decode_quality(const ProtocolConfig& cfg, const hal::CanFrame& f, QualityOut* out);
bool decode_status(const ProtocolConfig& cfg, const hal::CanFrame& f, StatusOut* out);
bool decode_heartbeat(const ProtocolConfig& cfg, const hal::CanFrame& f, HeartbeatOut* out,
                      int* protocol_version);
// Which message a frame is under cfg (by ID and ID type; an input message whether enabled or
// not); Msg::kCount when none.
Msg identify(const ProtocolConfig& cfg, const hal::CanFrame& f);

// One odometry measurement, in the units of docs/design/frames.md.
struct OdomSample {
  std::int64_t t_ns = 0;  // frame receive timestamp
  double v_mps = 0.0;
  double omega_radps = 0.0;
  double left_mps = 0.0;          // wheels mode only
  double right_mps = 0.0;         // wheels mode only
  std::uint32_t lost_before = 0;  // frames lost just before this one (E2E gap)
};

enum class DecodeResult : std::uint8_t {
  kOk = 0,
  kNotOdometry,  // other ID or ID type (not this decoder's message): ignored, not counted
  kBadLength,    // len != 8
  kBadCrc,
  kRepeated,     // alive counter did not advance
  kCounterJump,  // counter advanced by more than max_delta_counter
  kBadCounter,   // counter value 15
  kStale,        // receive timestamp older than the last accepted frame's
};
const char* to_string(DecodeResult r);

// What an E2E-protected input decoder (odometry, gyro) counted: one set of checks, one set of
// counters (check_input in codec.cpp).
struct InputCounters {
  std::uint64_t accepted = 0;
  std::uint64_t lost_frames = 0;  // gaps within max_delta_counter (accepted frames after a gap)
  std::uint64_t bad_length = 0;
  std::uint64_t bad_crc = 0;
  std::uint64_t repeated = 0;
  std::uint64_t counter_jump = 0;
  std::uint64_t bad_counter = 0;
  std::uint64_t stale = 0;
  std::uint64_t rejected() const {
    return bad_length + bad_crc + repeated + counter_jump + bad_counter + stale;
  }
};
using OdometryCounters = InputCounters;

// Motor-controller side (simulators, tests, the HIL peer): one odometry frame as the DBC
// describes it, E2E-protected with `counter` (0..14) whether or not the receiver checks it.
// a, b = left and right wheel speeds in m/s (wheels mode) or v_mps and omega_radps (twist mode).
void encode_odometry(const ProtocolConfig& cfg, double a, double b, std::uint8_t counter,
                     hal::CanFrame* out);

class OdometryDecoder {
 public:
  explicit OdometryDecoder(const ProtocolConfig& cfg);
  // kOk fills *out; anything else leaves it untouched. Rejections are counted.
  DecodeResult decode(const hal::CanFrame& f, OdomSample* out);
  // Receive time of the last accepted frame; INT64_MIN when none.
  std::int64_t last_accepted_ns() const { return last_ok_ns_; }
  const OdometryCounters& counters() const { return counters_; }
  std::uint32_t can_id() const { return id_; }
  bool extended() const { return ext_; }

 private:
  OdometryConfig cfg_;
  std::uint32_t id_;
  bool ext_;
  E2eChecker checker_;
  OdometryCounters counters_;
  std::int64_t last_ok_ns_;
};

// One gyro measurement (AGV_Gyro), rates in rad/s about the vehicle axes (docs/design/frames.md).
struct GyroSample {
  std::int64_t t_ns = 0;          // frame receive timestamp
  double gyro_z_radps = 0.0;      // yaw rate, counter-clockwise positive
  bool saturated = false;         // the sensor's Saturated bit: the rates must not be fused
  double gyro_x_radps = 0.0;      // roll rate (informational)
  double gyro_y_radps = 0.0;      // pitch rate (informational)
  std::uint32_t lost_before = 0;  // frames lost just before this one (E2E gap)
};

// accepted includes the saturated frames.
struct GyroCounters : InputCounters {
  std::uint64_t saturated = 0;  // accepted frames with Saturated = 1
};

// Gyro side (simulators, tests, the HIL peer): one AGV_Gyro frame as the DBC describes it, with
// s's rates and Saturated bit (s.t_ns and s.lost_before are ignored), E2E-protected with
// `counter` (0..14) whether or not the receiver checks it. Rates saturate at the signal ranges.
void encode_gyro(const ProtocolConfig& cfg, const GyroSample& s, std::uint8_t counter,
                 hal::CanFrame* out);

// AGV_Gyro decoder, the same checks and order as OdometryDecoder (ID, length, stale, E2E when
// GyroConfig::protected_e2e). A frame with Saturated = 1 is kOk with sample.saturated set (and
// counted): whether to fuse it is the caller's decision (the Localizer does not).
class GyroDecoder {
 public:
  explicit GyroDecoder(const ProtocolConfig& cfg);
  // kOk fills *out; anything else leaves it untouched. Rejections are counted.
  DecodeResult decode(const hal::CanFrame& f, GyroSample* out);
  // Receive time of the last accepted frame; INT64_MIN when none.
  std::int64_t last_accepted_ns() const { return last_ok_ns_; }
  const GyroCounters& counters() const { return counters_; }
  std::uint32_t can_id() const { return id_; }
  bool extended() const { return ext_; }

 private:
  GyroConfig cfg_;
  std::uint32_t id_;
  bool ext_;
  E2eChecker checker_;
  GyroCounters counters_;
  std::int64_t last_ok_ns_;
};

}  // namespace agv::protocol
