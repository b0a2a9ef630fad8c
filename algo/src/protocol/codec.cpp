#include "agv/protocol/codec.hpp"

#include <climits>
#include <cmath>
#include <cstring>
#include <limits>

#include "agv/common/geometry.hpp"

namespace agv::protocol {

namespace {

const SignalDef& sig(Msg m, const char* name) {
  // The table is constant; a missing name is a programming error caught by the unit tests.
  return *find_signal(message_def(m), name);
}

std::uint16_t odom_data_id(const OdometryConfig& o) {
  if (o.data_id != 0) return o.data_id;
  return message_def(o.mode == OdometryMode::kWheels ? Msg::kOdomWheels : Msg::kOdomTwist).data_id;
}

Msg odom_msg(const OdometryConfig& o) {
  return o.mode == OdometryMode::kWheels ? Msg::kOdomWheels : Msg::kOdomTwist;
}

std::uint16_t gyro_data_id(const GyroConfig& g) {
  return g.data_id != 0 ? g.data_id : message_def(Msg::kGyro).data_id;
}

bool finite(double v) { return std::isfinite(v); }
constexpr double kInf = std::numeric_limits<double>::infinity();

// AGV_Status flag signals: fault::* bit i is kFaultSignals[i], reject::* bit i kRejectSignals[i].
constexpr const char* kFaultSignals[] = {
    "FaultCameraStalled",   "FaultCameraError", "FaultOdomTimeout", "FaultOdomE2E",
    "FaultCanErrorPassive", "FaultCanBusOff",   "FaultNoMap",       "FaultLoopOverrun",
    "FaultImuTimeout",      "FaultImuE2E"};
constexpr const char* kRejectSignals[] = {"RejectGate", "RejectUnknownLandmark",
                                          "RejectDecodeFailed", "RejectGeometry",
                                          "RejectFixTooOld"};

}  // namespace

std::string validate(const ProtocolConfig& cfg) {
  const std::uint32_t out_mask = cfg.extended_ids ? kCanExtIdMask : kCanStdIdMask;
  std::uint32_t max_off = 0;
  for (const MessageDef& m : message_table()) {
    if (m.dir == Direction::kTx && m.id_offset > max_off) max_off = m.id_offset;
  }
  if (cfg.base_id > out_mask || cfg.base_id + max_off > out_mask) {
    return std::string("base_id + ") + std::to_string(max_off) + " does not fit a " +
           (cfg.extended_ids ? "29" : "11") + "-bit CAN ID";
  }
  const std::uint32_t odom_id = can_id_of(cfg, odom_msg(cfg.odometry));
  if (odom_id > (cfg.odometry.extended_id ? kCanExtIdMask : kCanStdIdMask)) {
    return "odometry CAN ID does not fit its ID type";
  }
  if (cfg.odometry.extended_id == cfg.extended_ids) {
    for (const MessageDef& m : message_table()) {
      if (m.dir == Direction::kTx && cfg.base_id + m.id_offset == odom_id) {
        return std::string("odometry CAN ID collides with ") + m.name;
      }
    }
  }
  if (!(cfg.odometry.track_width_mm > 0.0) || !finite(cfg.odometry.track_width_mm)) {
    return "odometry.track_width_mm must be > 0";
  }
  // 65535 ms: the DBC's GenMsgCycleTime range.
  for (const double period_ms : {cfg.output_period_ms, cfg.heartbeat_period_ms}) {
    if (!(period_ms >= 0.5) || !(period_ms <= 65535.0)) {
      return "output and heartbeat periods must be 0.5..65535 ms";
    }
  }
  if (!finite(cfg.odometry.speed_scale) || !finite(cfg.odometry.omega_scale) ||
      cfg.odometry.speed_scale == 0.0 || cfg.odometry.omega_scale == 0.0) {
    return "odometry speed_scale/omega_scale must be finite and non-zero";
  }
  if (cfg.odometry.max_delta_counter < 1 || cfg.odometry.max_delta_counter > 14) {
    return "odometry.max_delta_counter must be 1..14";
  }
  if (cfg.gyro.enabled) {
    const std::uint32_t gyro_id = can_id_of(cfg, Msg::kGyro);
    if (gyro_id > (cfg.odometry.extended_id ? kCanExtIdMask : kCanStdIdMask)) {
      return "gyro CAN ID does not fit its ID type";
    }
    if (gyro_id == odom_id) return "gyro CAN ID collides with the odometry CAN ID";
    if (cfg.odometry.extended_id == cfg.extended_ids) {
      for (const MessageDef& m : message_table()) {
        if (m.dir == Direction::kTx && cfg.base_id + m.id_offset == gyro_id) {
          return std::string("gyro CAN ID collides with ") + m.name;
        }
      }
    }
    if (cfg.gyro.max_delta_counter < 1 || cfg.gyro.max_delta_counter > 14) {
      return "gyro.max_delta_counter must be 1..14";
    }
  }
  return {};
}

std::uint32_t can_id_of(const ProtocolConfig& cfg, Msg m) {
  const MessageDef& d = message_def(m);
  if (d.dir == Direction::kRx) {
    if (m == odom_msg(cfg.odometry) && cfg.odometry.can_id != 0) return cfg.odometry.can_id;
    if (m == Msg::kGyro && cfg.gyro.can_id != 0) return cfg.gyro.can_id;
    return cfg.base_id + d.id_offset;
  }
  return (cfg.base_id + d.id_offset) & (cfg.extended_ids ? kCanExtIdMask : kCanStdIdMask);
}

bool is_extended(const ProtocolConfig& cfg, Msg m) {
  // Every input shares the odometry's ID type (GyroConfig has none of its own).
  return message_def(m).dir == Direction::kRx ? cfg.odometry.extended_id : cfg.extended_ids;
}

bool rx_enabled(const ProtocolConfig& cfg, Msg m) {
  if (m == Msg::kGyro) return cfg.gyro.enabled;
  return m == odom_msg(cfg.odometry);
}

std::uint32_t cycle_ms_of(const ProtocolConfig& cfg, Msg m) {
  const MessageDef& d = message_def(m);
  if (d.dir != Direction::kTx) return d.cycle_ms;
  const double period_ms = m == Msg::kHeartbeat ? cfg.heartbeat_period_ms : cfg.output_period_ms;
  // validate() keeps the periods finite and positive; the DBC attribute is an integer.
  return static_cast<std::uint32_t>(std::llround(period_ms));
}

// ---------------------------------------------------------------------------------- Encoder

Encoder::Encoder(const ProtocolConfig& cfg) : cfg_(cfg) {}

void Encoder::begin(Msg m, hal::CanFrame* out) const {
  *out = hal::CanFrame{};
  out->id = can_id_of(cfg_, m);
  out->extended = cfg_.extended_ids;
  out->len = message_def(m).dlc;
}

void Encoder::finish(Msg m, hal::CanFrame* out) {
  std::uint8_t& c = counters_[static_cast<int>(m)];
  e2e_protect(message_def(m).data_id, c, out->data);
  c = static_cast<std::uint8_t>((c + 1) % kE2eCounterModulo);
}

bool pose_valid_on_can(const PoseOut& p) {
  return p.valid && finite(p.x_mm) && finite(p.y_mm) && finite(p.theta_rad);
}

void Encoder::encode_pose(const PoseOut& p, hal::CanFrame* xy, hal::CanFrame* heading) {
  const bool valid = pose_valid_on_can(p);
  begin(Msg::kPoseXY, xy);
  put_raw(sig(Msg::kPoseXY, "PoseValid"), valid ? 1 : 0, xy->data);
  put_phys(sig(Msg::kPoseXY, "X"), p.x_mm, xy->data);
  put_phys(sig(Msg::kPoseXY, "Y"), p.y_mm, xy->data);
  begin(Msg::kPoseHeading, heading);
  put_raw(sig(Msg::kPoseHeading, "PoseValid"), valid ? 1 : 0, heading->data);
  const double th = finite(p.theta_rad) ? wrap_angle_rad(p.theta_rad) : 0.0;
  put_phys(sig(Msg::kPoseHeading, "Theta"), th, heading->data);
  // Unknown latency is reported as the maximum (pessimistic).
  put_phys(sig(Msg::kPoseHeading, "Latency"), std::isnan(p.latency_ms) ? kInf : p.latency_ms,
           heading->data);
  // Pair the two frames by counter: both advance together, so use the XY counter for both.
  counters_[static_cast<int>(Msg::kPoseHeading)] = counters_[static_cast<int>(Msg::kPoseXY)];
  finish(Msg::kPoseXY, xy);
  finish(Msg::kPoseHeading, heading);
}

void Encoder::encode_velocity(const VelocityOut& v, hal::CanFrame* out) {
  begin(Msg::kVelocity, out);
  const bool valid = v.valid && finite(v.v_mps) && finite(v.omega_radps);
  put_raw(sig(Msg::kVelocity, "VelocityValid"), valid ? 1 : 0, out->data);
  put_phys(sig(Msg::kVelocity, "V"), v.v_mps, out->data);
  put_phys(sig(Msg::kVelocity, "Omega"), v.omega_radps, out->data);
  finish(Msg::kVelocity, out);
}

void Encoder::encode_quality(const QualityOut& q, hal::CanFrame* out) {
  begin(Msg::kQuality, out);
  // A NaN sigma is unknown: invalid. +inf is "very uncertain": saturates, stays valid.
  const bool valid = q.valid && !std::isnan(q.sigma_x_mm) && !std::isnan(q.sigma_y_mm) &&
                     !std::isnan(q.sigma_theta_rad);
  put_raw(sig(Msg::kQuality, "QualityValid"), valid ? 1 : 0, out->data);
  put_raw(sig(Msg::kQuality, "MapGuidedFix"), q.map_guided_fix ? 1 : 0, out->data);
  put_phys(sig(Msg::kQuality, "SigmaX"), q.sigma_x_mm, out->data);
  put_phys(sig(Msg::kQuality, "SigmaY"), q.sigma_y_mm, out->data);
  put_phys(sig(Msg::kQuality, "SigmaTheta"), q.sigma_theta_rad, out->data);
  finish(Msg::kQuality, out);
}

void Encoder::encode_status(const StatusOut& s, hal::CanFrame* out) {
  begin(Msg::kStatus, out);
  put_raw(sig(Msg::kStatus, "Health"), static_cast<std::int64_t>(s.health) & 3, out->data);
  put_raw(sig(Msg::kStatus, "LastLandmarkId"), s.last_landmark_id, out->data);
  put_raw(sig(Msg::kStatus, "LastLandmarkValid"), s.last_landmark_valid ? 1 : 0, out->data);
  const bool never = !(s.time_since_fix_ms >= 0.0);  // negative or NaN
  put_phys(sig(Msg::kStatus, "TimeSinceFix"), never ? kInf : s.time_since_fix_ms, out->data);
  int i = 0;
  for (const char* name : kFaultSignals) {  // fault bits 10..15 have no signal and are not sent
    put_raw(sig(Msg::kStatus, name), (s.faults >> i++) & 1, out->data);
  }
  i = 0;
  for (const char* name : kRejectSignals) {  // bits 5..7 are reserved and stay 0
    put_raw(sig(Msg::kStatus, name), (s.rejections >> i++) & 1, out->data);
  }
  finish(Msg::kStatus, out);
}

void Encoder::encode_heartbeat(const HeartbeatOut& h, hal::CanFrame* out) {
  begin(Msg::kHeartbeat, out);
  put_raw(sig(Msg::kHeartbeat, "ProtocolVersion"), kProtocolVersion, out->data);
  put_raw(sig(Msg::kHeartbeat, "SwMajor"), h.sw_major, out->data);
  put_raw(sig(Msg::kHeartbeat, "SwMinor"), h.sw_minor, out->data);
  put_raw(sig(Msg::kHeartbeat, "SwPatch"), h.sw_patch, out->data);
  // Whole seconds, truncated (rounding would report a second early).
  const double up = std::isnan(h.uptime_s) ? 0.0 : std::floor(h.uptime_s);
  put_phys(sig(Msg::kHeartbeat, "Uptime"), up, out->data);
  finish(Msg::kHeartbeat, out);
}

// ------------------------------------------------------------------------ output decoders

Msg identify(const ProtocolConfig& cfg, const hal::CanFrame& f) {
  for (const MessageDef& m : message_table()) {
    if (f.id == can_id_of(cfg, m.msg) && f.extended == is_extended(cfg, m.msg)) {
      if ((m.msg == Msg::kOdomWheels || m.msg == Msg::kOdomTwist) &&
          m.msg != odom_msg(cfg.odometry) && cfg.odometry.can_id != 0) {
        continue;  // the inactive odometry variant has no configured ID
      }
      return m.msg;
    }
  }
  return Msg::kCount;
}

namespace {
bool is_msg(const ProtocolConfig& cfg, const hal::CanFrame& f, Msg m) {
  return f.len == message_def(m).dlc && f.id == can_id_of(cfg, m) &&
         f.extended == is_extended(cfg, m);
}
}  // namespace

bool decode_pose(const ProtocolConfig& cfg, const hal::CanFrame& xy, const hal::CanFrame& heading,
                 PoseOut* out) {
  if (!is_msg(cfg, xy, Msg::kPoseXY) || !is_msg(cfg, heading, Msg::kPoseHeading)) return false;
  out->x_mm = get_phys(sig(Msg::kPoseXY, "X"), xy.data);
  out->y_mm = get_phys(sig(Msg::kPoseXY, "Y"), xy.data);
  out->theta_rad = get_phys(sig(Msg::kPoseHeading, "Theta"), heading.data);
  out->latency_ms = get_phys(sig(Msg::kPoseHeading, "Latency"), heading.data);
  out->valid = get_raw(sig(Msg::kPoseXY, "PoseValid"), xy.data) == 1 &&
               get_raw(sig(Msg::kPoseHeading, "PoseValid"), heading.data) == 1 &&
               (xy.data[1] & 0x0F) == (heading.data[1] & 0x0F);  // same estimate
  return true;
}

bool decode_velocity(const ProtocolConfig& cfg, const hal::CanFrame& f, VelocityOut* out) {
  if (!is_msg(cfg, f, Msg::kVelocity)) return false;
  out->valid = get_raw(sig(Msg::kVelocity, "VelocityValid"), f.data) == 1;
  out->v_mps = get_phys(sig(Msg::kVelocity, "V"), f.data);
  out->omega_radps = get_phys(sig(Msg::kVelocity, "Omega"), f.data);
  return true;
}

bool decode_quality(const ProtocolConfig& cfg, const hal::CanFrame& f, QualityOut* out) {
  if (!is_msg(cfg, f, Msg::kQuality)) return false;
  out->valid = get_raw(sig(Msg::kQuality, "QualityValid"), f.data) == 1;
  out->map_guided_fix = get_raw(sig(Msg::kQuality, "MapGuidedFix"), f.data) == 1;
  out->sigma_x_mm = get_phys(sig(Msg::kQuality, "SigmaX"), f.data);
  out->sigma_y_mm = get_phys(sig(Msg::kQuality, "SigmaY"), f.data);
  out->sigma_theta_rad = get_phys(sig(Msg::kQuality, "SigmaTheta"), f.data);
  return true;
}

bool decode_status(const ProtocolConfig& cfg, const hal::CanFrame& f, StatusOut* out) {
  if (!is_msg(cfg, f, Msg::kStatus)) return false;
  out->health = static_cast<Health>(get_raw(sig(Msg::kStatus, "Health"), f.data));
  out->last_landmark_id =
      static_cast<std::uint16_t>(get_raw(sig(Msg::kStatus, "LastLandmarkId"), f.data));
  const std::int64_t t = get_raw(sig(Msg::kStatus, "TimeSinceFix"), f.data);
  out->time_since_fix_ms = t == 65535 ? -1.0 : static_cast<double>(t);
  out->faults = 0;
  int i = 0;
  for (const char* name : kFaultSignals) {
    out->faults =
        static_cast<std::uint16_t>(out->faults | (get_raw(sig(Msg::kStatus, name), f.data) << i++));
  }
  out->last_landmark_valid = get_raw(sig(Msg::kStatus, "LastLandmarkValid"), f.data) == 1;
  // The rejection flags by their signals: byte 7 also holds LastLandmarkValid.
  out->rejections = 0;
  i = 0;
  for (const char* name : kRejectSignals) {
    out->rejections = static_cast<std::uint8_t>(out->rejections |
                                                (get_raw(sig(Msg::kStatus, name), f.data) << i++));
  }
  return true;
}

bool decode_heartbeat(const ProtocolConfig& cfg, const hal::CanFrame& f, HeartbeatOut* out,
                      int* protocol_version) {
  if (!is_msg(cfg, f, Msg::kHeartbeat)) return false;
  out->sw_major = static_cast<std::uint8_t>(get_raw(sig(Msg::kHeartbeat, "SwMajor"), f.data));
  out->sw_minor = static_cast<std::uint8_t>(get_raw(sig(Msg::kHeartbeat, "SwMinor"), f.data));
  out->sw_patch = static_cast<std::uint8_t>(get_raw(sig(Msg::kHeartbeat, "SwPatch"), f.data));
  out->uptime_s = get_phys(sig(Msg::kHeartbeat, "Uptime"), f.data);
  if (protocol_version) {
    *protocol_version = static_cast<int>(get_raw(sig(Msg::kHeartbeat, "ProtocolVersion"), f.data));
  }
  return true;
}

// ---------------------------------------------------------------------- OdometryDecoder

const char* to_string(DecodeResult r) {
  switch (r) {
    case DecodeResult::kOk:
      return "ok";
    case DecodeResult::kNotOdometry:
      return "not-odometry";
    case DecodeResult::kBadLength:
      return "bad-length";
    case DecodeResult::kBadCrc:
      return "bad-crc";
    case DecodeResult::kRepeated:
      return "repeated";
    case DecodeResult::kCounterJump:
      return "counter-jump";
    case DecodeResult::kBadCounter:
      return "bad-counter";
    case DecodeResult::kStale:
      return "stale";
  }
  return "?";
}

namespace {

// The checks every input frame passes before its signals are read, in this order: ID and ID type,
// length, receive time (stale before E2E, so a replayed old frame does not move the counter
// reference), then CRC and alive counter when protected.
// On kOk *lost is the number of frames the E2E counter says were lost just before this one.
DecodeResult check_input(const hal::CanFrame& f, std::uint32_t id, bool ext, bool protected_e2e,
                         std::int64_t last_ok_ns, E2eChecker* checker, InputCounters* counters,
                         std::uint32_t* lost) {
  *lost = 0;
  if (f.id != id || f.extended != ext) return DecodeResult::kNotOdometry;
  if (f.len != kE2eFrameLen) {
    ++counters->bad_length;
    return DecodeResult::kBadLength;
  }
  if (last_ok_ns != INT64_MIN && f.t_ns < last_ok_ns) {
    ++counters->stale;
    return DecodeResult::kStale;
  }
  if (!protected_e2e) return DecodeResult::kOk;
  const std::uint64_t lost_before = checker->counters().lost_frames;
  switch (checker->check(f)) {
    case E2eStatus::kOk:
    case E2eStatus::kInitial:
      return DecodeResult::kOk;
    case E2eStatus::kOkSomeLost:
      *lost = static_cast<std::uint32_t>(checker->counters().lost_frames - lost_before);
      counters->lost_frames += *lost;
      return DecodeResult::kOk;
    case E2eStatus::kRepeated:
      ++counters->repeated;
      return DecodeResult::kRepeated;
    case E2eStatus::kWrongSequence:
      ++counters->counter_jump;
      return DecodeResult::kCounterJump;
    case E2eStatus::kBadCrc:
      ++counters->bad_crc;
      return DecodeResult::kBadCrc;
    case E2eStatus::kBadLength:
      ++counters->bad_length;
      return DecodeResult::kBadLength;
    case E2eStatus::kBadCounter:
      ++counters->bad_counter;
      return DecodeResult::kBadCounter;
  }
  return DecodeResult::kBadCrc;  // unreachable: every status is handled above
}

}  // namespace

OdometryDecoder::OdometryDecoder(const ProtocolConfig& cfg)
    : cfg_(cfg.odometry),
      id_(can_id_of(cfg, odom_msg(cfg.odometry))),
      ext_(cfg.odometry.extended_id),
      checker_(E2eCheckerConfig{odom_data_id(cfg.odometry), cfg.odometry.max_delta_counter}),
      last_ok_ns_(INT64_MIN) {}

DecodeResult OdometryDecoder::decode(const hal::CanFrame& f, OdomSample* out) {
  std::uint32_t lost = 0;
  const DecodeResult r =
      check_input(f, id_, ext_, cfg_.protected_e2e, last_ok_ns_, &checker_, &counters_, &lost);
  if (r != DecodeResult::kOk) return r;
  OdomSample s;
  s.t_ns = f.t_ns;
  s.lost_before = lost;
  const Msg m = odom_msg(cfg_);
  if (cfg_.mode == OdometryMode::kWheels) {
    s.left_mps = get_phys(sig(m, "LeftSpeed"), f.data) * cfg_.speed_scale;
    s.right_mps = get_phys(sig(m, "RightSpeed"), f.data) * cfg_.speed_scale;
    s.v_mps = 0.5 * (s.left_mps + s.right_mps);
    s.omega_radps = (s.right_mps - s.left_mps) / (cfg_.track_width_mm * 1e-3) * cfg_.omega_scale;
  } else {
    s.v_mps = get_phys(sig(m, "V"), f.data) * cfg_.speed_scale;
    s.omega_radps = get_phys(sig(m, "Omega"), f.data) * cfg_.omega_scale;
  }
  ++counters_.accepted;
  last_ok_ns_ = f.t_ns;
  *out = s;
  return DecodeResult::kOk;
}

void encode_odometry(const ProtocolConfig& cfg, double a, double b, std::uint8_t counter,
                     hal::CanFrame* out) {
  const Msg m = odom_msg(cfg.odometry);
  const MessageDef& d = message_def(m);
  *out = hal::CanFrame{};
  out->id = can_id_of(cfg, m);
  out->extended = cfg.odometry.extended_id;
  out->len = 8;
  put_phys(d.signals[2], a, out->data);
  put_phys(d.signals[3], b, out->data);
  e2e_protect(odom_data_id(cfg.odometry), static_cast<std::uint8_t>(counter % kE2eCounterModulo),
              out->data);
}

// --------------------------------------------------------------------------- GyroDecoder

GyroDecoder::GyroDecoder(const ProtocolConfig& cfg)
    : cfg_(cfg.gyro),
      id_(can_id_of(cfg, Msg::kGyro)),
      ext_(is_extended(cfg, Msg::kGyro)),
      checker_(E2eCheckerConfig{gyro_data_id(cfg.gyro), cfg.gyro.max_delta_counter}),
      last_ok_ns_(INT64_MIN) {}

DecodeResult GyroDecoder::decode(const hal::CanFrame& f, GyroSample* out) {
  std::uint32_t lost = 0;
  const DecodeResult r =
      check_input(f, id_, ext_, cfg_.protected_e2e, last_ok_ns_, &checker_, &counters_, &lost);
  if (r != DecodeResult::kOk) return r;
  GyroSample s;
  s.t_ns = f.t_ns;
  s.lost_before = lost;
  s.saturated = get_raw(sig(Msg::kGyro, "Saturated"), f.data) != 0;
  s.gyro_z_radps = get_phys(sig(Msg::kGyro, "GyroZ"), f.data);
  s.gyro_x_radps = get_phys(sig(Msg::kGyro, "GyroX"), f.data);
  s.gyro_y_radps = get_phys(sig(Msg::kGyro, "GyroY"), f.data);
  ++counters_.accepted;
  if (s.saturated) ++counters_.saturated;
  last_ok_ns_ = f.t_ns;
  *out = s;
  return DecodeResult::kOk;
}

void encode_gyro(const ProtocolConfig& cfg, const GyroSample& s, std::uint8_t counter,
                 hal::CanFrame* out) {
  *out = hal::CanFrame{};
  out->id = can_id_of(cfg, Msg::kGyro);
  out->extended = is_extended(cfg, Msg::kGyro);
  out->len = message_def(Msg::kGyro).dlc;
  put_raw(sig(Msg::kGyro, "Saturated"), s.saturated ? 1 : 0, out->data);
  put_phys(sig(Msg::kGyro, "GyroZ"), s.gyro_z_radps, out->data);
  put_phys(sig(Msg::kGyro, "GyroX"), s.gyro_x_radps, out->data);
  put_phys(sig(Msg::kGyro, "GyroY"), s.gyro_y_radps, out->data);
  e2e_protect(gyro_data_id(cfg.gyro), static_cast<std::uint8_t>(counter % kE2eCounterModulo),
              out->data);
}

}  // namespace agv::protocol
