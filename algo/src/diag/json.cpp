// JSON of the diagnostics page (docs/guide/diagnostics.md). Written by hand, not with
// nlohmann-json: the documents are flat and fixed, and agv_algo stays free of that dependency.
#include <charconv>
#include <cmath>
#include <cstdio>

#include "agv/diag/diag.hpp"
#include "agv/protocol/codec.hpp"

namespace agv::diag {

namespace {

struct FlagName {
  std::uint16_t bit;
  const char* name;
};

// docs/guide/can.md names of AGV_Status's Fault* and Rej* signals.
constexpr FlagName kFaults[] = {
    {protocol::fault::kCameraStalled, "camera_stalled"},
    {protocol::fault::kCameraError, "camera_error"},
    {protocol::fault::kOdomTimeout, "odometry_timeout"},
    {protocol::fault::kOdomE2E, "odometry_e2e"},
    {protocol::fault::kCanErrorPassive, "can_error_passive"},
    {protocol::fault::kCanBusOff, "can_bus_off"},
    {protocol::fault::kNoMap, "no_map"},
    {protocol::fault::kLoopOverrun, "loop_overrun"},
    {protocol::fault::kImuTimeout, "imu_timeout"},
    {protocol::fault::kImuE2E, "imu_e2e"},
};
constexpr FlagName kRejections[] = {
    {protocol::reject::kGate, "gate"},
    {protocol::reject::kUnknownLandmark, "unknown_landmark"},
    {protocol::reject::kDecodeFailed, "decode_failed"},
    {protocol::reject::kGeometry, "geometry"},
    {protocol::reject::kFixTooOld, "fix_too_old"},
};

template <std::size_t N>
std::string names_json(const FlagName (&table)[N], unsigned bits) {
  std::string out = "[";
  for (const FlagName& f : table) {
    if ((bits & f.bit) == 0) continue;
    if (out.size() > 1) out += ',';
    append_json_string(&out, f.name);
  }
  return out + "]";
}

const char* health_name(protocol::Health h) {
  switch (h) {
    case protocol::Health::kOk:
      return "OK";
    case protocol::Health::kDegraded:
      return "DEGRADED";
    case protocol::Health::kLost:
      return "LOST";
    case protocol::Health::kFault:
      return "FAULT";
  }
  return "?";
}

// "key": value pieces; every call is followed by another or by the closing brace, so each
// appends its own leading comma except the first of an object (first = true).
void key(std::string* out, const char* k, bool first = false) {
  if (!first) *out += ',';
  append_json_string(out, k);
  *out += ':';
}
void num(std::string* out, const char* k, double v, bool first = false) {
  key(out, k, first);
  append_json_number(out, v);
}
void integer(std::string* out, const char* k, std::uint64_t v) {
  key(out, k);
  *out += std::to_string(v);
}
void boolean(std::string* out, const char* k, bool v) {
  key(out, k);
  *out += v ? "true" : "false";
}

double ms(std::int64_t ns) { return static_cast<double>(ns) / 1e6; }

void latency(std::string* out, const char* k, const LatencyHistogram& h, bool first = false) {
  key(out, k, first);
  *out += '{';
  key(out, "count", true);
  *out += std::to_string(h.count());
  num(out, "p50_ms", ms(h.percentile_ns(0.5)));
  num(out, "p99_ms", ms(h.percentile_ns(0.99)));
  num(out, "max_ms", ms(h.max_ns()));
  *out += '}';
}

}  // namespace

void append_json_number(std::string* out, double v) {
  if (!std::isfinite(v)) {
    *out += "null";
    return;
  }
  char buf[32];
  const auto r = std::to_chars(buf, buf + sizeof buf, v);
  out->append(buf, r.ptr);
}

void append_json_string(std::string* out, const char* s) {
  *out += '"';
  for (const char* p = s; *p; ++p) {
    const auto c = static_cast<unsigned char>(*p);
    if (c == '"' || c == '\\') {
      *out += '\\';
      *out += static_cast<char>(c);
    } else if (c < 0x20) {
      char buf[8];
      std::snprintf(buf, sizeof buf, "\\u%04x", static_cast<unsigned>(c));
      *out += buf;
    } else {
      *out += static_cast<char>(c);
    }
  }
  *out += '"';
}

FixEntry fix_entry(const vision::LandmarkMeasurement& fix, std::int64_t t_exposure_ns,
                   std::int64_t t_arrival_ns) {
  FixEntry e;
  e.t_exposure_ns = t_exposure_ns;
  e.t_arrival_ns = t_arrival_ns;
  e.status = fix.status;
  e.landmark_id = fix.landmark_id;
  e.map_verified = fix.map_verified;
  e.vehicle_in_world = fix.vehicle_in_world;
  e.sigma_mm = std::sqrt(std::max(0.0, std::max(fix.cov_world(0, 0), fix.cov_world(1, 1))));
  return e;
}

TrackPoint track_point(const localizer::TickRecord& tick) {
  return {tick.t_ns, tick.estimate.pose.x_mm, tick.estimate.pose.y_mm, tick.estimate.valid};
}

std::string fault_names_json(std::uint16_t faults) { return names_json(kFaults, faults); }
std::string rejection_names_json(std::uint8_t rejections) {
  return names_json(kRejections, rejections);
}

std::string status_json(const Snapshot& s, const ServerStats& server, const char* mode) {
  std::string o;
  o.reserve(4096);
  o += '{';
  key(&o, "mode", true);
  append_json_string(&o, mode);
  boolean(&o, "has_tick", s.has_tick);
  boolean(&o, "finished", s.finished);
  const fusion::PoseEstimate& e = s.tick.estimate;
  key(&o, "t_ns");
  o += std::to_string(s.tick.t_ns);
  key(&o, "pose");
  o += '{';
  // valid: the CAN PoseValid of this tick; initialised: the filter has a pose at all (also LOST).
  key(&o, "valid", true);
  o += s.tick.pose_valid ? "true" : "false";
  boolean(&o, "initialised", e.valid);
  num(&o, "x_mm", e.pose.x_mm);
  num(&o, "y_mm", e.pose.y_mm);
  num(&o, "theta_deg", e.pose.theta_rad * 180.0 / kPi);
  num(&o, "v_mps", e.v_mps);
  num(&o, "omega_radps", e.omega_radps);
  num(&o, "sigma_x_mm", std::sqrt(std::max(0.0, e.cov(0, 0))));
  num(&o, "sigma_y_mm", std::sqrt(std::max(0.0, e.cov(1, 1))));
  num(&o, "sigma_theta_deg", std::sqrt(std::max(0.0, e.cov(2, 2))) * 180.0 / kPi);
  num(&o, "position_sigma_mm", e.position_sigma_mm);
  num(&o, "time_since_fix_ms", e.time_since_fix_ns < 0 ? -1.0 : ms(e.time_since_fix_ns));
  o += '}';
  key(&o, "health");
  append_json_string(&o, health_name(s.tick.status.health));
  key(&o, "fusion_state");
  append_json_string(&o, fusion::to_string(e.health));
  integer(&o, "faults_bits", s.tick.status.faults);
  key(&o, "faults");
  o += fault_names_json(s.tick.status.faults);
  integer(&o, "rejections_bits", s.tick.status.rejections);
  key(&o, "rejections");
  o += rejection_names_json(s.tick.status.rejections);
  integer(&o, "last_landmark_id", s.tick.status.last_landmark_id);
  boolean(&o, "last_landmark_valid", s.tick.status.last_landmark_valid);

  const localizer::OutputStats& st = s.stats;
  key(&o, "counters");
  o += '{';
  key(&o, "ticks", true);
  o += std::to_string(st.ticks);
  integer(&o, "missed_periods", st.missed_periods);
  integer(&o, "odometry_samples", st.odom_samples);
  integer(&o, "odometry_rejected", st.odom_rejected);
  integer(&o, "gyro_samples", st.gyro_samples);
  integer(&o, "gyro_rejected", st.gyro_rejected);
  integer(&o, "fixes_received", st.fixes_received);
  integer(&o, "fixes_fused", st.fixes_fused);
  integer(&o, "fixes_rejected_gate", st.fixes_rejected_gate);
  integer(&o, "fixes_rejected_too_old", st.fixes_rejected_too_old);
  integer(&o, "fixes_rejected_invalid", st.fixes_rejected_invalid);
  integer(&o, "fixes_rejected_not_tracking", st.fixes_rejected_not_tracking);
  integer(&o, "reinitialisations", st.reinitialisations);
  integer(&o, "can_tx_ok", st.can_tx_ok);
  integer(&o, "can_tx_failed", st.can_tx_failed);
  integer(&o, "can_rx_frames", st.can_rx_frames);
  integer(&o, "frames_dropped", s.frames_dropped);
  o += '}';
  key(&o, "latency");
  o += '{';
  latency(&o, "end_to_end", st.end_to_end_ns, true);
  latency(&o, "period_jitter", st.period_jitter_ns);
  latency(&o, "fusion", st.fusion_ns);
  latency(&o, "can_send", st.can_send_ns);
  o += '}';

  key(&o, "fixes");
  o += '[';
  for (std::size_t i = s.fixes.size(); i-- > 0;) {  // newest first
    const FixEntry& f = s.fixes.at(i);
    if (o.back() != '[') o += ',';
    o += '{';
    key(&o, "t_exposure_ns", true);
    o += std::to_string(f.t_exposure_ns);
    key(&o, "status");
    append_json_string(&o, vision::to_string(f.status));
    integer(&o, "landmark_id", f.landmark_id);
    boolean(&o, "map_verified", f.map_verified);
    num(&o, "x_mm", f.vehicle_in_world.x_mm);
    num(&o, "y_mm", f.vehicle_in_world.y_mm);
    num(&o, "theta_deg", f.vehicle_in_world.theta_rad * 180.0 / kPi);
    num(&o, "sigma_mm", f.sigma_mm);
    num(&o, "latency_ms", ms(f.t_arrival_ns - f.t_exposure_ns));
    o += '}';
  }
  o += ']';

  key(&o, "server");
  o += '{';
  key(&o, "requests", true);
  o += std::to_string(server.requests);
  integer(&o, "refused_busy", server.refused_busy);
  integer(&o, "refused_bad", server.refused_bad);
  integer(&o, "frames_encoded", server.frames_encoded);
  integer(&o, "snapshots_taken", server.snapshots_taken);
  integer(&o, "loop_busy_skips", server.loop_busy_skips);
  o += '}';
  o += '}';
  return o;
}

std::string map_json(const LandmarkMap* map, const Snapshot& s) {
  std::string o;
  o.reserve(64 * (map ? map->entries.size() : 0) + 48 * s.track.size() + 64);
  o += "{\"landmarks\":[";
  if (map) {
    for (const auto& [id, entry] : map->entries) {
      if (o.back() != '[') o += ',';
      o += "{\"id\":" + std::to_string(id);
      num(&o, "x_mm", entry.pose.x_mm);
      num(&o, "y_mm", entry.pose.y_mm);
      num(&o, "heading_deg", entry.pose.theta_rad * 180.0 / kPi);
      o += '}';
    }
  }
  o += "],\"track\":[";
  // [t_ms, x_mm, y_mm] of valid poses only: an uninitialised filter sits at the origin.
  for (std::size_t i = 0; i < s.track.size(); ++i) {
    const TrackPoint& p = s.track.at(i);
    if (!p.valid) continue;
    if (o.back() != '[') o += ',';
    o += '[';
    append_json_number(&o, ms(p.t_ns));
    o += ',';
    append_json_number(&o, p.x_mm);
    o += ',';
    append_json_number(&o, p.y_mm);
    o += ']';
  }
  o += "],\"pose\":";
  if (s.has_tick && s.tick.estimate.valid) {
    o += '{';
    num(&o, "x_mm", s.tick.estimate.pose.x_mm, true);
    num(&o, "y_mm", s.tick.estimate.pose.y_mm);
    num(&o, "theta_deg", s.tick.estimate.pose.theta_rad * 180.0 / kPi);
    num(&o, "position_sigma_mm", s.tick.estimate.position_sigma_mm);
    o += '}';
  } else {
    o += "null";
  }
  o += '}';
  return o;
}

}  // namespace agv::diag
