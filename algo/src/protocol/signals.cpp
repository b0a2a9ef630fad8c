#include "agv/protocol/signals.hpp"

#include <cmath>
#include <cstring>

namespace agv::protocol {

namespace {

// Bytes 0 and the low nibble of byte 1 of every frame (e2e.hpp).
// clang-format off
constexpr SignalDef kCrcSignal{"CRC", 0, 8, true, false, 1, 0, 0, 255, "",
    "CRC-8 SAE J1850 over data ID (low, high byte) and bytes 1..7 (docs/guide/can.md)"};
constexpr SignalDef kCounterSignal{"AliveCounter", 8, 4, true, false, 1, 0, 0, 14, "",
    "E2E alive counter 0..14, +1 per frame of this ID, wraps 14->0; 15 is invalid"};
// clang-format on

constexpr SignalDef kPoseXY[] = {
    kCrcSignal,
    kCounterSignal,
    {"PoseValid", 12, 1, true, false, 1, 0, 0, 1, "",
     "1: pose initialised and usable; 0: X/Y/Theta must be ignored"},
    {"X", 16, 24, true, true, 0.1, 0, -838860.8, 838860.7, "mm",
     "World x of the vehicle reference point; saturates at the range limits"},
    {"Y", 40, 24, true, true, 0.1, 0, -838860.8, 838860.7, "mm",
     "World y of the vehicle reference point; saturates at the range limits"},
};
constexpr SignalDef kPoseHeading[] = {
    kCrcSignal,
    kCounterSignal,
    {"PoseValid", 12, 1, true, false, 1, 0, 0, 1, "", "Same as PoseXY.PoseValid"},
    {"Theta", 16, 16, true, true, 0.0001, 0, -3.1416, 3.1416, "rad",
     "Heading, counter-clockwise from world +x, wrapped to (-pi, pi]"},
    {"Latency", 32, 16, true, false, 0.1, 0, 0, 6553.5, "ms",
     "Age of the pose estimate when the frame was encoded; saturates at 6553.5 ms"},
};
constexpr SignalDef kVelocity[] = {
    kCrcSignal,
    kCounterSignal,
    {"VelocityValid", 12, 1, true, false, 1, 0, 0, 1, "", "1: V and Omega are usable"},
    {"V", 16, 16, true, true, 0.001, 0, -32.768, 32.767, "m/s",
     "Forward speed of the vehicle reference point"},
    {"Omega", 32, 16, true, true, 0.0001, 0, -3.2768, 3.2767, "rad/s",
     "Yaw rate, counter-clockwise positive"},
};
constexpr SignalDef kQuality[] = {
    kCrcSignal,
    kCounterSignal,
    {"QualityValid", 12, 1, true, false, 1, 0, 0, 1, "", "1: the sigmas are meaningful"},
    {"MapGuidedFix", 13, 1, true, false, 1, 0, 0, 1, "",
     "1: a fix identified from the map (QR unreadable) was fused since the previous frame"},
    {"SigmaX", 16, 16, true, false, 0.1, 0, 0, 6553.5, "mm",
     "Standard deviation of X; saturates at 6553.5 mm (= at least that)"},
    {"SigmaY", 32, 16, true, false, 0.1, 0, 0, 6553.5, "mm",
     "Standard deviation of Y; saturates at 6553.5 mm"},
    {"SigmaTheta", 48, 16, true, false, 0.0001, 0, 0, 6.5535, "rad",
     "Standard deviation of Theta; saturates at 6.5535 rad"},
};
constexpr SignalDef kStatus[] = {
    kCrcSignal,
    kCounterSignal,
    {"Health", 12, 2, true, false, 1, 0, 0, 3, "",
     "0 OK, 1 DEGRADED (dead reckoning: no fix fused for longer than the localized timeout, "
     "sigma within the lost limits), 2 LOST (no usable pose: sigma above the lost limits, no "
     "odometry, or not initialised), 3 FAULT (reserved: not sent by this version)"},
    {"LastLandmarkId", 16, 16, true, false, 1, 0, 0, 65535, "",
     "Id of the landmark of the last accepted fix; valid only when LastLandmarkValid is 1 (0 is "
     "a landmark id: tag36h11's first tag)"},
    {"TimeSinceFix", 32, 16, true, false, 1, 0, 0, 65535, "ms",
     "Time since the last accepted landmark fix; 65535 = at least 65.535 s, or never"},
    {"FaultCameraStalled", 48, 1, true, false, 1, 0, 0, 1, "", "No camera frame within timeout"},
    {"FaultCameraError", 49, 1, true, false, 1, 0, 0, 1, "", "Camera driver reports an error"},
    {"FaultOdomTimeout", 50, 1, true, false, 1, 0, 0, 1, "",
     "No accepted odometry frame within the odometry timeout"},
    {"FaultOdomE2E", 51, 1, true, false, 1, 0, 0, 1, "",
     "Odometry frames rejected (length, CRC, counter) since the last status frame"},
    {"FaultCanErrorPassive", 52, 1, true, false, 1, 0, 0, 1, "",
     "CAN controller error-passive (or warning) since the last status frame"},
    {"FaultCanBusOff", 53, 1, true, false, 1, 0, 0, 1, "",
     "CAN bus-off, interface down or frames dropped on a full queue since the last status"},
    {"FaultNoMap", 54, 1, true, false, 1, 0, 0, 1, "",
     "Reserved: never set by this version (a missing or invalid map stops agvloc at start)"},
    {"FaultLoopOverrun", 55, 1, true, false, 1, 0, 0, 1, "",
     "The real-time loop missed its deadline since the last status frame"},
    // The two gyro flags sit in the free upper bits of byte 1 (after Health): byte 6 is full and
    // byte 7 keeps its reserved bits for further rejection flags.
    {"FaultImuTimeout", 14, 1, true, false, 1, 0, 0, 1, "",
     "No usable AGV_Gyro sample within the gyro timeout (silent, saturated or rejected gyro)"},
    {"FaultImuE2E", 15, 1, true, false, 1, 0, 0, 1, "",
     "AGV_Gyro frames rejected (length, CRC, counter) since the last status frame"},
    {"RejectGate", 56, 1, true, false, 1, 0, 0, 1, "",
     "A landmark fix failed the innovation (Mahalanobis) gate since the last status frame"},
    {"RejectUnknownLandmark", 57, 1, true, false, 1, 0, 0, 1, "",
     "A decoded landmark id is not in the map"},
    {"RejectDecodeFailed", 58, 1, true, false, 1, 0, 0, 1, "",
     "A landmark was seen but its code could not be decoded"},
    {"RejectGeometry", 59, 1, true, false, 1, 0, 0, 1, "",
     "A landmark pose measurement was inconsistent or ambiguous"},
    {"RejectFixTooOld", 60, 1, true, false, 1, 0, 0, 1, "",
     "A fix arrived later than the fusion history covers"},
    // The top bit of byte 7: bits 61..62 stay next to the rejection flags for further ones. Id 0
    // is a mappable tag36h11 landmark, so LastLandmarkId 0 alone cannot mean "none yet".
    {"LastLandmarkValid", 63, 1, true, false, 1, 0, 0, 1, "",
     "1: a landmark fix has been accepted since start and LastLandmarkId is its landmark; 0: none "
     "yet, LastLandmarkId must be ignored"},
};
constexpr SignalDef kHeartbeat[] = {
    kCrcSignal,
    kCounterSignal,
    {"ProtocolVersion", 12, 4, true, false, 1, 0, 0, 15, "",
     "Version of this frame layout (agv::protocol::kProtocolVersion)"},
    {"SwMajor", 16, 8, true, false, 1, 0, 0, 255, "", "Software version major"},
    {"SwMinor", 24, 8, true, false, 1, 0, 0, 255, "", "Software version minor"},
    {"SwPatch", 32, 8, true, false, 1, 0, 0, 255, "", "Software version patch"},
    {"Uptime", 40, 24, true, false, 1, 0, 0, 16777215, "s",
     "Time since the localizer started; saturates at 16777215 s"},
};
constexpr SignalDef kOdomWheels[] = {
    kCrcSignal,
    kCounterSignal,
    {"LeftSpeed", 16, 16, true, true, 0.001, 0, -32.768, 32.767, "m/s",
     "Left wheel ground speed, forward positive"},
    {"RightSpeed", 32, 16, true, true, 0.001, 0, -32.768, 32.767, "m/s",
     "Right wheel ground speed, forward positive"},
};
constexpr SignalDef kOdomTwist[] = {
    kCrcSignal,
    kCounterSignal,
    {"V", 16, 16, true, true, 0.001, 0, -32.768, 32.767, "m/s",
     "Forward speed of the vehicle reference point"},
    {"Omega", 32, 16, true, true, 0.0001, 0, -3.2768, 3.2767, "rad/s",
     "Yaw rate, counter-clockwise positive"},
};

constexpr SignalDef kGyro[] = {
    kCrcSignal,
    kCounterSignal,
    {"Saturated", 12, 1, true, false, 1, 0, 0, 1, "",
     "1: the sensor reports a rate beyond its range or otherwise invalid; the sample is not "
     "fused"},
    // 24 bits byte-aligned (readable in a raw candump): 1e-5 rad/s = 0.00057 deg/s, +-83.9 rad/s
    // covers every MEMS range (+-2000 deg/s = 34.9 rad/s).
    {"GyroZ", 16, 24, true, true, 0.00001, 0, -83.88608, 83.88607, "rad/s",
     "Yaw rate about the vehicle z axis (up), counter-clockwise positive; the sender maps the "
     "sensor's mounting onto the vehicle axes"},
    {"GyroX", 40, 12, true, true, 0.002, 0, -4.096, 4.094, "rad/s",
     "Roll rate about the vehicle x axis (forward); informational, not fused"},
    {"GyroY", 52, 12, true, true, 0.002, 0, -4.096, 4.094, "rad/s",
     "Pitch rate about the vehicle y axis (left); informational, not fused"},
};

const MessageDef kMessages[] = {
    {Msg::kPoseXY, "AGV_PoseXY", 0x00, 0x4C00, 8, Direction::kTx, 10,
     "Vehicle position. Sent together with AGV_PoseHeading from the same estimate; both carry "
     "the same AliveCounter, which pairs them.",
     kPoseXY},
    {Msg::kPoseHeading, "AGV_PoseHeading", 0x01, 0x4C01, 8, Direction::kTx, 10,
     "Vehicle heading and pose latency; pairs with AGV_PoseXY by AliveCounter.", kPoseHeading},
    {Msg::kVelocity, "AGV_Velocity", 0x02, 0x4C02, 8, Direction::kTx, 10,
     "Estimated vehicle velocity.", kVelocity},
    {Msg::kQuality, "AGV_Quality", 0x03, 0x4C03, 8, Direction::kTx, 10,
     "Standard deviations of the pose estimate.", kQuality},
    {Msg::kStatus, "AGV_Status", 0x04, 0x4C04, 8, Direction::kTx, 10,
     "Health, last fix, fault and rejection flags. Event flags are latched between two status "
     "frames.",
     kStatus},
    {Msg::kHeartbeat, "AGV_Heartbeat", 0x05, 0x4C05, 8, Direction::kTx, 1000,
     "Software and protocol version, uptime.", kHeartbeat},
    {Msg::kOdomWheels, "MC_OdomWheels", 0x10, 0x4C10, 8, Direction::kRx, 10,
     "Odometry input, wheel-speed variant (config can.odometry.mode: wheels). CRC and "
     "AliveCounter are checked only when can.odometry.protected is true.",
     kOdomWheels},
    {Msg::kOdomTwist, "MC_OdomTwist", 0x11, 0x4C11, 8, Direction::kRx, 10,
     "Odometry input, v/omega variant (config can.odometry.mode: v_omega). CRC and "
     "AliveCounter are checked only when can.odometry.protected is true.",
     kOdomTwist},
    // id_offset 0x12: the first free input offset after the odometry frames (0x10, 0x11).
    {Msg::kGyro, "AGV_Gyro", 0x12, 0x4C12, 8, Direction::kRx, 10,
     "Gyro (IMU) rate input; received only with can.gyro.enabled. CRC and AliveCounter are "
     "checked only when can.gyro.protected is true. Samples with Saturated = 1 are not fused.",
     kGyro},
};
static_assert(sizeof kMessages / sizeof kMessages[0] == static_cast<std::size_t>(Msg::kCount));

}  // namespace

std::span<const MessageDef> message_table() { return kMessages; }

const MessageDef& message_def(Msg m) { return kMessages[static_cast<std::size_t>(m)]; }

const SignalDef* find_signal(const MessageDef& m, const char* name) {
  for (const SignalDef& s : m.signals) {
    if (std::strcmp(s.name, name) == 0) return &s;
  }
  return nullptr;
}

std::int64_t raw_min(const SignalDef& s) {
  return static_cast<std::int64_t>(std::ceil((s.min - s.offset) / s.scale - 1e-9));
}
std::int64_t raw_max(const SignalDef& s) {
  return static_cast<std::int64_t>(std::floor((s.max - s.offset) / s.scale + 1e-9));
}

std::int64_t to_raw(const SignalDef& s, double phys, bool* saturated, bool* was_nan) {
  const std::int64_t lo = raw_min(s), hi = raw_max(s);
  if (was_nan) *was_nan = std::isnan(phys);
  if (std::isnan(phys)) phys = 0.0;
  const double r = std::round((phys - s.offset) / s.scale);
  std::int64_t raw;
  bool sat = false;
  if (!(r > static_cast<double>(lo))) {
    raw = lo;
    sat = r < static_cast<double>(lo);
  } else if (!(r < static_cast<double>(hi))) {
    raw = hi;
    sat = r > static_cast<double>(hi);
  } else {
    raw = static_cast<std::int64_t>(r);
  }
  if (saturated) *saturated = sat;
  return raw;
}

double to_phys(const SignalDef& s, std::int64_t raw) {
  return static_cast<double>(raw) * s.scale + s.offset;
}

namespace {
std::uint64_t load_le(const std::uint8_t d[8]) {
  std::uint64_t v = 0;
  for (int i = 7; i >= 0; --i) v = (v << 8) | d[i];
  return v;
}
void store_le(std::uint64_t v, std::uint8_t d[8]) {
  for (int i = 0; i < 8; ++i) d[i] = static_cast<std::uint8_t>(v >> (8 * i));
}
std::uint64_t mask_of(int length) {
  return length >= 64 ? ~std::uint64_t{0} : ((std::uint64_t{1} << length) - 1);
}
}  // namespace

void put_raw(const SignalDef& s, std::int64_t raw, std::uint8_t data[8]) {
  const std::uint64_t m = mask_of(s.length) << s.start_bit;
  std::uint64_t v = load_le(data);
  v = (v & ~m) | ((static_cast<std::uint64_t>(raw) << s.start_bit) & m);
  store_le(v, data);
}

std::int64_t get_raw(const SignalDef& s, const std::uint8_t data[8]) {
  const std::uint64_t u = (load_le(data) >> s.start_bit) & mask_of(s.length);
  if (s.is_signed && s.length < 64 && (u >> (s.length - 1)) != 0) {
    return static_cast<std::int64_t>(u | ~mask_of(s.length));
  }
  return static_cast<std::int64_t>(u);
}

void put_phys(const SignalDef& s, double phys, std::uint8_t data[8]) {
  put_raw(s, to_raw(s, phys), data);
}

double get_phys(const SignalDef& s, const std::uint8_t data[8]) {
  return to_phys(s, get_raw(s, data));
}

}  // namespace agv::protocol
