// Key table rows of the vda5050 section (docs/guide/vda5050.md).
#include <string_view>

#include "agv/common/log_escape.hpp"
#include "key_builders.hpp"

namespace agv::config::detail {

void add_vda5050_keys(std::vector<Key>* k) {
  k->push_back(boolean("vda5050.enabled", AGV_AT(vda5050.enabled), false,
                       "publish the pose to a VDA 5050 fleet broker. Off: no MQTT thread, no "
                       "socket; the CAN output is the same either way"));
  k->push_back(
      text("vda5050.broker_host", AGV_AT(vda5050.broker_host), "localhost",
           "MQTT broker (host name or address). Unreachable: the publisher retries "
           "with backoff (0.1 s, doubling up to 1 s between attempts) and the loop runs on"));
  k->push_back(integer("vda5050.broker_port", AGV_AT(vda5050.broker_port), 1, 65535, 1883,
                       {"", "broker TCP port; 8883 is the usual TLS port"}));
  k->push_back(text("vda5050.interface_name", AGV_AT(vda5050.interface_name), "uagv",
                    "first topic level (`interfaceName/v2/manufacturer/serialNumber/topic`); "
                    "the fleet control's choice, `uagv` in the specification's examples"));
  k->push_back(choice("vda5050.version", AGV_AT(vda5050.version), {"2.0.0", "2.1.0", "3.0.0"},
                      "2.1.0",
                      "protocol version of every message and the topics' `v2` / `v3`; must be "
                      "the fleet control's (2.0.0's messages are 2.1.0's with another version; "
                      "3.0.0 renames agvPosition to mobileRobotPosition and initPosition to "
                      "initializePosition)"));
  k->push_back(text("vda5050.manufacturer", AGV_AT(vda5050.manufacturer), "agvloc",
                    "the vehicle's manufacturer as the fleet control knows it (topic level and "
                    "header); instant actions for another manufacturer are refused"));
  k->push_back(text("vda5050.serial_number", AGV_AT(vda5050.serial_number), "agv-0001",
                    "the vehicle's serial number (topic level, header, MQTT client id); must be "
                    "unique on the broker: a second client with it disconnects the first"));
  k->push_back(text("vda5050.map_id", AGV_AT(vda5050.map_id), "default",
                    "`mapId` of every position: the landmark map's name in the fleet control. "
                    "initPosition for another mapId is refused (agvloc knows one map)"));
  k->push_back(number("vda5050.rate_hz", AGV_AT(vda5050.rate_hz), 0.1, 100.0, 10.0,
                      {"Hz",
                       "visualization messages a second (the newest output tick each time). "
                       "Higher shows motion smoother in the fleet view at more broker load; "
                       "10 Hz is 1 m/s in 100 mm steps"}));
  k->push_back(
      text("vda5050.username", AGV_AT(vda5050.username), "", "MQTT user name; empty = anonymous"));
  k->push_back(text("vda5050.password_file", AGV_AT(vda5050.password_file), "",
                    "file whose first line is the MQTT password (kept out of the configuration, "
                    "mode 0600); relative to the configuration file; empty = none"));
  k->push_back(text("vda5050.tls_ca_file", AGV_AT(vda5050.tls_ca_file), "",
                    "CA certificate (PEM) that signed the broker's: set = TLS with the broker's "
                    "certificate and host name verified; relative to the configuration file; "
                    "empty = plain TCP"));
}

namespace {

// Ids compared with an instantAction's header are refused there beyond this many bytes
// (vda5050::kMaxIdChars): a longer one could never be matched.
constexpr std::size_t kMaxIdBytes = 256;
// A DNS name is at most 253 characters; 255 leaves room for a trailing dot and an IPv6 literal.
constexpr std::size_t kMaxHostBytes = 255;

bool has_control(std::string_view s) {
  for (const char ch : s) {
    const auto u = static_cast<unsigned char>(ch);
    if (u < 0x20 || u == 0x7F) return true;
  }
  return false;
}

// U+0080..U+009F as UTF-8 (C2 80..C2 9F): MQTT 3.1.1 section 1.5.3 says a topic should not
// carry these any more than U+0001..U+001F.
bool has_c1_control(std::string_view s) {
  for (std::size_t i = 0; i + 1 < s.size(); ++i) {
    if (static_cast<unsigned char>(s[i]) == 0xC2 && static_cast<unsigned char>(s[i + 1]) <= 0x9F)
      return true;
  }
  return false;
}

// A string carried in a JSON message (nlohmann-json refuses to write one that is not UTF-8).
bool json_text(const KeyError& error, const std::string& key, const std::string& v) {
  if (!is_valid_utf8(v)) {
    error(key, "'" + escape_for_log(v) +
                   "' is not valid UTF-8 (VDA 5050 messages are JSON; save the file as UTF-8)");
    return false;
  }
  if (v.size() > kMaxIdBytes) {
    error(key, std::to_string(v.size()) + " bytes; at most " + std::to_string(kMaxIdBytes) +
                   " (a longer id in an instantAction is refused as string_too_long)");
    return false;
  }
  return true;
}

// One level of interfaceName/vN/manufacturer/serialNumber/topic: MQTT forbids the wildcards in a
// topic that is published to, '/' would add a level, NUL ends the string in the client library.
// first: the topic's first level (interfaceName).
void topic_level(const KeyError& error, const std::string& key, const std::string& v,
                 bool first = false) {
  if (v.empty()) {
    error(key, "empty: it is a topic level (interfaceName/vN/manufacturer/serialNumber/topic)");
    return;
  }
  if (!json_text(error, key, v)) return;
  if (v.find_first_of(std::string_view("+#/\0", 4)) != std::string::npos || has_control(v) ||
      has_c1_control(v)) {
    error(key, "'" + escape_for_log(v) +
                   "' contains '+', '#', '/' or a control character, which an MQTT topic level "
                   "cannot carry (wildcards, level separator)");
    return;
  }
  if (first && v.front() == '$') {
    error(key, "'" + escape_for_log(v) +
                   "' begins with '$', which marks the broker's own topics ($SYS): the first "
                   "topic level cannot");
  }
}

}  // namespace

void check_vda5050_values(const Config& cfg, const KeyError& error) {
  const Vda5050Section& v = cfg.vda5050;
  topic_level(error, "vda5050.interface_name", v.interface_name, true);
  topic_level(error, "vda5050.manufacturer", v.manufacturer);
  topic_level(error, "vda5050.serial_number", v.serial_number);
  json_text(error, "vda5050.map_id", v.map_id);
  if (v.broker_host.empty()) {
    error("vda5050.broker_host", "empty: a host name or address is needed");
  } else if (v.broker_host.size() > kMaxHostBytes) {
    error("vda5050.broker_host", std::to_string(v.broker_host.size()) +
                                     " bytes; a host name has at most " +
                                     std::to_string(kMaxHostBytes));
  } else {
    for (const char ch : v.broker_host) {
      const auto u = static_cast<unsigned char>(ch);
      if (u <= 0x20 || u >= 0x7F) {
        error("vda5050.broker_host",
              "'" + escape_for_log(v.broker_host) +
                  "' is not a host name or address (ASCII without spaces or control characters; "
                  "an international name in its xn-- form)");
        break;
      }
    }
  }
  // MQTT strings are UTF-8 without U+0000 (MQTT 3.1.1, section 1.5.3).
  if (!is_valid_utf8(v.username) || has_control(v.username)) {
    error("vda5050.username", "'" + escape_for_log(v.username) +
                                  "' is not valid UTF-8 without control characters (MQTT "
                                  "strings are UTF-8)");
  }
}

}  // namespace agv::config::detail
