// instantActions parser (vda5050.hpp). Hostile input is expected on a shared broker: size and
// nesting are bounded before the JSON parser sees the text, nothing throws, and every refusal
// carries a Reason.
#include <cmath>
#include <nlohmann/json.hpp>

#include "agv/vda5050/vda5050.hpp"
#include "json_nesting.hpp"

namespace agv::vda5050 {

using nlohmann::json;

const char* reason_name(Reason r) {
  switch (r) {
    case Reason::kNone:
      return "none";
    case Reason::kTooLarge:
      return "too_large";
    case Reason::kTooDeep:
      return "too_deep";
    case Reason::kNotJson:
      return "not_json";
    case Reason::kNotObject:
      return "not_object";
    case Reason::kMissingField:
      return "missing_field";
    case Reason::kWrongType:
      return "wrong_type";
    case Reason::kWrongVersion:
      return "wrong_version";
    case Reason::kWrongTarget:
      return "wrong_target";
    case Reason::kTooManyActions:
      return "too_many_actions";
    case Reason::kMissingParameter:
      return "missing_parameter";
    case Reason::kDuplicateParameter:
      return "duplicate_parameter";
    case Reason::kNonFinite:
      return "non_finite";
    case Reason::kOutOfRange:
      return "out_of_range";
    case Reason::kUnknownMap:
      return "unknown_map";
    case Reason::kStringTooLong:
      return "string_too_long";
  }
  return "unknown";
}

namespace {

using detail::nesting_within;

// A required string member: kMissingField, kWrongType or kStringTooLong.
Reason get_string(const json& o, const char* key, std::string* out) {
  const auto it = o.find(key);
  if (it == o.end()) return Reason::kMissingField;
  if (!it->is_string()) return Reason::kWrongType;
  const auto& s = it->get_ref<const std::string&>();
  if (s.size() > kMaxIdChars) return Reason::kStringTooLong;
  *out = s;
  return Reason::kNone;
}

const char* our_action_type(Version v) {
  return v == Version::k3_0_0 ? "initializePosition" : "initPosition";
}

// The parameters of one initPosition; kNone when a, all set, passes every check.
Reason parse_init(const Identity& id, const json& params, InitPosition* a) {
  if (!params.is_array()) return Reason::kWrongType;
  bool have_x = false, have_y = false, have_theta = false, have_map = false, have_node = false;
  for (const json& p : params) {
    if (!p.is_object()) return Reason::kWrongType;
    std::string key;
    if (const Reason r = get_string(p, "key", &key); r != Reason::kNone) return r;
    const auto v = p.find("value");
    if (v == p.end()) return Reason::kMissingField;
    auto number = [&](bool* seen, double* out) {
      if (*seen) return Reason::kDuplicateParameter;
      *seen = true;
      if (!v->is_number()) return Reason::kWrongType;
      *out = v->get<double>();
      return std::isfinite(*out) ? Reason::kNone : Reason::kNonFinite;
    };
    auto text = [&](bool* seen, std::string* out) {
      if (*seen) return Reason::kDuplicateParameter;
      *seen = true;
      if (!v->is_string()) return Reason::kWrongType;
      if (v->get_ref<const std::string&>().size() > kMaxIdChars) return Reason::kStringTooLong;
      *out = v->get<std::string>();
      return Reason::kNone;
    };
    Reason r = Reason::kNone;
    if (key == "x") {
      r = number(&have_x, &a->x_m);
    } else if (key == "y") {
      r = number(&have_y, &a->y_m);
    } else if (key == "theta") {
      r = number(&have_theta, &a->theta_rad);
    } else if (key == "mapId") {
      r = text(&have_map, &a->map_id);
    } else if (key == "lastNodeId") {
      r = text(&have_node, &a->last_node_id);
    }  // other keys: ignored (the spec lets fleet controls add parameters)
    if (r != Reason::kNone) return r;
  }
  if (!have_x || !have_y || !have_theta || !have_map) return Reason::kMissingParameter;
  if (std::fabs(a->x_m) > kMaxCoordinateM || std::fabs(a->y_m) > kMaxCoordinateM ||
      std::fabs(a->theta_rad) > M_PI + 1e-9) {
    return Reason::kOutOfRange;
  }
  if (a->map_id != id.map_id) return Reason::kUnknownMap;
  return Reason::kNone;
}

Reason check_header(const Identity& id, const json& m) {
  const auto hid = m.find("headerId");
  if (hid == m.end()) return Reason::kMissingField;
  if (!hid->is_number_integer()) return Reason::kWrongType;
  std::string s;
  if (const Reason r = get_string(m, "timestamp", &s); r != Reason::kNone) return r;
  if (const Reason r = get_string(m, "version", &s); r != Reason::kNone) return r;
  const char major = id.version == Version::k3_0_0 ? '3' : '2';
  if (s.empty() || s[0] != major || (s.size() > 1 && s[1] != '.')) return Reason::kWrongVersion;
  if (const Reason r = get_string(m, "manufacturer", &s); r != Reason::kNone) return r;
  if (s != id.manufacturer) return Reason::kWrongTarget;
  if (const Reason r = get_string(m, "serialNumber", &s); r != Reason::kNone) return r;
  if (s != id.serial_number) return Reason::kWrongTarget;
  return Reason::kNone;
}

}  // namespace

ParsedActions parse_instant_actions(const Identity& id, std::string_view text) {
  ParsedActions out;
  if (text.size() > kMaxMessageBytes) {
    out.message_reason = Reason::kTooLarge;
    return out;
  }
  if (!nesting_within(text, kMaxDepth)) {
    out.message_reason = Reason::kTooDeep;
    return out;
  }
  const json m = json::parse(text.begin(), text.end(), nullptr, /*allow_exceptions=*/false);
  if (m.is_discarded()) {
    out.message_reason = Reason::kNotJson;
    return out;
  }
  if (!m.is_object()) {
    out.message_reason = Reason::kNotObject;
    return out;
  }
  if (const Reason r = check_header(id, m); r != Reason::kNone) {
    out.message_reason = r;
    return out;
  }
  auto actions = m.find("actions");
  // 2.0.0's document names the array `actions`, but vda-5050-lib 1.4.0 (a master control library
  // for 2.0.0) still sends it under 1.1's key `instantActions`: both are read for 2.0.0.
  if (actions == m.end() && id.version == Version::k2_0_0) actions = m.find("instantActions");
  if (actions == m.end()) {
    out.message_reason = Reason::kMissingField;
    return out;
  }
  if (!actions->is_array()) {
    out.message_reason = Reason::kWrongType;
    return out;
  }
  if (actions->size() > kMaxActions) {
    out.message_reason = Reason::kTooManyActions;
    return out;
  }
  const char* ours = our_action_type(id.version);
  for (const json& a : *actions) {
    if (!a.is_object()) {
      out.message_reason = Reason::kWrongType;
      out.accepted.clear();
      out.refused.clear();
      return out;
    }
    std::string type;
    if (get_string(a, "actionType", &type) != Reason::kNone || type != ours) {
      ++out.not_ours;
      continue;
    }
    InitPosition init;
    init.action_type = type;
    Reason r = get_string(a, "actionId", &init.action_id);
    if (r == Reason::kNone) {
      std::string blocking;
      r = get_string(a, "blockingType", &blocking);
    }
    if (r == Reason::kNone) {
      const auto params = a.find("actionParameters");
      r = params == a.end() ? Reason::kMissingParameter : parse_init(id, *params, &init);
    }
    if (r == Reason::kNone) {
      out.accepted.push_back(std::move(init));
    } else {
      out.refused.push_back({init.action_id, type, ActionStatus::kFailed, reason_name(r)});
    }
  }
  return out;
}

}  // namespace agv::vda5050
