// What may become part of an MQTT topic that agvloc-overhead publishes to or subscribes to
// (docs/guide/overhead.md "Configuration"): the configured interface name, manufacturer and
// detections prefix, and the site's vehicle and camera ids. MQTT forbids the wildcards '+' and
// '#' in a topic that is published to, and one of them in a subscription would receive other
// topics' messages; '/' adds a level, NUL ends the string in the client library, a topic is UTF-8
// of at most 65535 bytes, and a topic beginning with '$' belongs to the broker ($SYS).
#pragma once

#include <cstddef>
#include <string>
#include <string_view>

namespace agv::overhead_app {

// Every topic built from these stays far below MQTT's 65535 bytes: the longest,
// interface/vN/manufacturer/id/visualization, is at most 3 x 256 + 20 bytes, and
// PREFIX/detections/CAMERA at most 1024 + 12 + 256.
inline constexpr std::size_t kMaxTopicLevelBytes = 256;
inline constexpr std::size_t kMaxTopicPrefixBytes = 1024;

// "" when s can be one topic level (1..kMaxTopicLevelBytes bytes of UTF-8 without '/', '+',
// '#', NUL or a control character); otherwise what is wrong ("contains the MQTT wildcard '+'").
std::string topic_level_problem(std::string_view s);
inline bool topic_level_ok(std::string_view s) { return topic_level_problem(s).empty(); }

// The first level of a topic: as topic_level_problem, and not beginning with '$'.
std::string topic_first_level_problem(std::string_view s);

// "" when s can begin a topic: one or more levels as above joined by '/' (none empty, so no
// leading, trailing or doubled '/'), at most kMaxTopicPrefixBytes, not beginning with '$'.
std::string topic_prefix_problem(std::string_view s);

// "KEY: 'VALUE' cannot be ...: WHY" with VALUE escaped for a log line; "" when why is "".
std::string topic_error(const std::string& key, std::string_view value, const std::string& why,
                        bool prefix = false);

}  // namespace agv::overhead_app
