// Mapping and encoding (vda5050.hpp). Versions differ in: the position object's name
// (agvPosition / mobileRobotPosition) and its flag (positionInitialized / localized), the
// connection state CONNECTIONBROKEN / CONNECTION_BROKEN, and 3.0.0's referenceStateHeaderId.
// 2.0.0 and 2.1.0 differ only in the version string here: what 2.1.0 added to these messages
// (state.maps, errors[].errorHint, wider batteryState.reach / batteryHealth types) is not sent.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <nlohmann/json.hpp>

#include "agv/vda5050/vda5050.hpp"

namespace agv::vda5050 {

using nlohmann::json;

bool parse_version(std::string_view text, Version* out) {
  if (text == "2.0.0") {
    *out = Version::k2_0_0;
  } else if (text == "2.1.0") {
    *out = Version::k2_1_0;
  } else if (text == "3.0.0") {
    *out = Version::k3_0_0;
  } else {
    return false;
  }
  return true;
}

const char* version_string(Version v) {
  switch (v) {
    case Version::k2_0_0:
      return "2.0.0";
    case Version::k2_1_0:
      return "2.1.0";
    case Version::k3_0_0:
      return "3.0.0";
  }
  return "2.1.0";
}

std::string topic(const Identity& id, std::string_view leaf) {
  std::string t = id.interface_name;
  t += id.version == Version::k3_0_0 ? "/v3/" : "/v2/";
  t += id.manufacturer;
  t += '/';
  t += id.serial_number;
  t += '/';
  t += leaf;
  return t;
}

namespace {

double wrap_pi(double a) {
  if (!std::isfinite(a)) return 0.0;
  a = std::remainder(a, 2.0 * M_PI);  // [-pi, pi]
  return a;
}

json header(const Identity& id, std::uint32_t header_id, std::int64_t t_ns) {
  return json{{"headerId", header_id},
              {"timestamp", iso8601_utc_ms(t_ns)},
              {"version", version_string(id.version)},
              {"manufacturer", id.manufacturer},
              {"serialNumber", id.serial_number}};
}

// The configuration checker refuses strings that are not UTF-8; should one reach here all the same
// (a caller that skipped the checker), a replaced byte beats an exception that would end the
// process and take the CAN output with it.
std::string dump(const json& m) { return m.dump(-1, ' ', false, json::error_handler_t::replace); }

// Non-finite numbers cannot be JSON: 0 (the flag beside them says the value is not trusted).
double finite_or_zero(double v) { return std::isfinite(v) ? v : 0.0; }

json position_object(const Identity& id, const Position& p) {
  json o{{"x", finite_or_zero(p.x_m)},
         {"y", finite_or_zero(p.y_m)},
         {"theta", wrap_pi(p.theta_rad)},
         {"mapId", id.map_id},
         {id.version == Version::k3_0_0 ? "localized" : "positionInitialized", p.initialized},
         {"localizationScore", std::clamp(finite_or_zero(p.localization_score), 0.0, 1.0)}};
  if (std::isfinite(p.deviation_range_m) && p.deviation_range_m >= 0.0) {
    o["deviationRange"] = p.deviation_range_m;
  }
  return o;
}

const char* position_key(const Identity& id) {
  return id.version == Version::k3_0_0 ? "mobileRobotPosition" : "agvPosition";
}

json velocity_object(const Position& p) {
  return json{{"vx", finite_or_zero(p.vx_mps)},
              {"vy", finite_or_zero(p.vy_mps)},
              {"omega", finite_or_zero(p.omega_radps)}};
}

}  // namespace

Position map_tick(const localizer::TickRecord& tick) {
  const fusion::PoseEstimate& e = tick.estimate;
  Position p;
  p.x_m = e.pose.x_mm / 1000.0;
  p.y_m = e.pose.y_mm / 1000.0;
  p.theta_rad = wrap_pi(e.pose.theta_rad);
  const bool tracking = e.health == fusion::HealthState::kLocalized ||
                        e.health == fusion::HealthState::kDeadReckoning;
  const bool status_ok = tick.status.health == protocol::Health::kOk ||
                         tick.status.health == protocol::Health::kDegraded;
  const double sigma_mm = e.position_sigma_mm;
  p.initialized = e.valid && tracking && status_ok && std::isfinite(sigma_mm);
  p.deviation_range_m = p.initialized ? 3.0 * sigma_mm / 1000.0 : -1.0;
  if (p.initialized) {
    double s = std::clamp(1.0 - 3.0 * sigma_mm / kScoreZeroAtDeviationMm, 0.0, 1.0);
    if (e.health == fusion::HealthState::kDeadReckoning) s = std::min(s, kDeadReckoningScoreCap);
    p.localization_score = s;
  }
  p.vx_mps = finite_or_zero(e.v_mps);
  p.omega_radps = finite_or_zero(e.omega_radps);
  return p;
}

std::string iso8601_utc_ms(std::int64_t t_ns) {
  if (t_ns < 0) t_ns = 0;
  const std::int64_t ms_total = t_ns / 1'000'000;
  const std::int64_t secs = ms_total / 1000;
  const int ms = static_cast<int>(ms_total % 1000);
  std::int64_t days = secs / 86400;
  const int sod = static_cast<int>(secs % 86400);
  // Civil date from days since 1970-01-01 (H. Hinnant's algorithm), no time zone database.
  days += 719468;
  const std::int64_t era = days / 146097;
  const std::int64_t doe = days - era * 146097;
  const std::int64_t yoe = (doe - doe / 1460 + doe / 36524 - doe / 146096) / 365;
  const std::int64_t doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
  const std::int64_t mp = (5 * doy + 2) / 153;
  const int day = static_cast<int>(doy - (153 * mp + 2) / 5 + 1);
  const int month = static_cast<int>(mp < 10 ? mp + 3 : mp - 9);
  const std::int64_t year = yoe + era * 400 + (month <= 2 ? 1 : 0);
  char buf[40];
  std::snprintf(buf, sizeof buf, "%04lld-%02d-%02dT%02d:%02d:%02d.%03dZ",
                static_cast<long long>(year), month, day, sod / 3600, (sod / 60) % 60, sod % 60,
                ms);
  return buf;
}

std::string encode_visualization(const Identity& id, std::uint32_t header_id, std::int64_t t_ns,
                                 const Position& p, std::uint32_t reference_state_header_id) {
  json m = header(id, header_id, t_ns);
  if (id.version == Version::k3_0_0) m["referenceStateHeaderId"] = reference_state_header_id;
  m[position_key(id)] = position_object(id, p);
  m["velocity"] = velocity_object(p);
  return dump(m);
}

std::string encode_connection(const Identity& id, std::uint32_t header_id, std::int64_t t_ns,
                              ConnectionState s) {
  json m = header(id, header_id, t_ns);
  switch (s) {
    case ConnectionState::kOnline:
      m["connectionState"] = "ONLINE";
      break;
    case ConnectionState::kOffline:
      m["connectionState"] = "OFFLINE";
      break;
    case ConnectionState::kConnectionBroken:
      m["connectionState"] =
          id.version == Version::k3_0_0 ? "CONNECTION_BROKEN" : "CONNECTIONBROKEN";
      break;
  }
  return dump(m);
}

std::string encode_state(const Identity& id, std::uint32_t header_id, std::int64_t t_ns,
                         const Position& p, const std::vector<ActionResult>& actions,
                         const std::vector<StateError>& errors) {
  json m = header(id, header_id, t_ns);
  json states = json::array();
  for (const ActionResult& a : actions) {
    json s{{"actionId", a.action_id},
           {"actionType", a.action_type},
           {"actionStatus", a.status == ActionStatus::kFinished ? "FINISHED" : "FAILED"}};
    if (!a.result_description.empty()) s["resultDescription"] = a.result_description;
    states.push_back(std::move(s));
  }
  // Neutral values for what the vehicle controller owns (docs/guide/vda5050.md).
  m["orderId"] = "";
  m["orderUpdateId"] = 0;
  m["lastNodeId"] = "";
  m["lastNodeSequenceId"] = 0;
  m["nodeStates"] = json::array();
  m["edgeStates"] = json::array();
  m["driving"] = std::fabs(p.vx_mps) > 0.0 || std::fabs(p.omega_radps) > 0.0;
  m["operatingMode"] = "AUTOMATIC";
  m["errors"] = json::array();
  for (const StateError& e : errors) {
    json refs = json::array();
    for (const auto& [key, value] : e.references) {
      refs.push_back(json{{"referenceKey", key}, {"referenceValue", value}});
    }
    json j{{"errorType", e.type}, {"errorLevel", e.level}, {"errorReferences", std::move(refs)}};
    if (!e.description.empty()) j["errorDescription"] = e.description;
    m["errors"].push_back(std::move(j));
  }
  if (id.version == Version::k3_0_0) {
    // 3.0.0 answers instant actions in instantActionStates; actionStates are the order's.
    m["actionStates"] = json::array();
    m["instantActionStates"] = std::move(states);
    m["powerSupply"] = json{{"stateOfCharge", 0}, {"charging", false}};
    m["safetyState"] = json{{"activeEmergencyStop", "NONE"}, {"fieldViolation", false}};
  } else {
    m["actionStates"] = std::move(states);
    m["batteryState"] = json{{"batteryCharge", 0}, {"charging", false}};
    m["safetyState"] = json{{"eStop", "NONE"}, {"fieldViolation", false}};
  }
  m[position_key(id)] = position_object(id, p);
  m["velocity"] = velocity_object(p);
  return dump(m);
}

}  // namespace agv::vda5050
