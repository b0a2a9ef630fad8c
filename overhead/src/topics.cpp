#include "topics.hpp"

#include "agv/common/log_escape.hpp"

namespace agv::overhead_app {

namespace {

constexpr const char* kDollar = "begins with '$', which marks the broker's own topics ($SYS)";

// U+0000..U+001F, U+007F..U+009F: MQTT 3.1.1 section 1.5.3 says a topic should not carry them,
// and a broker may close the connection of a client that sends one.
bool has_control(std::string_view s) {
  for (std::size_t i = 0; i < s.size(); ++i) {
    const auto u = static_cast<unsigned char>(s[i]);
    if (u < 0x20 || u == 0x7F) return true;
    if (u == 0xC2 && i + 1 < s.size() && static_cast<unsigned char>(s[i + 1]) <= 0x9F) return true;
  }
  return false;
}

}  // namespace

std::string topic_level_problem(std::string_view s) {
  if (s.empty()) return "empty";
  if (s.size() > kMaxTopicLevelBytes) {
    return std::to_string(s.size()) + " bytes, more than " + std::to_string(kMaxTopicLevelBytes);
  }
  if (s.find('+') != std::string_view::npos) return "contains the MQTT wildcard '+'";
  if (s.find('#') != std::string_view::npos) return "contains the MQTT wildcard '#'";
  if (s.find('/') != std::string_view::npos) return "contains '/', which would add a topic level";
  if (!is_valid_utf8(s)) return "not valid UTF-8 (MQTT topics are UTF-8; save the file as UTF-8)";
  if (has_control(s)) return "contains NUL or a control character";
  return "";
}

std::string topic_first_level_problem(std::string_view s) {
  std::string why = topic_level_problem(s);
  if (why.empty() && s.front() == '$') why = kDollar;
  return why;
}

std::string topic_prefix_problem(std::string_view s) {
  if (s.empty()) return "empty";
  if (s.size() > kMaxTopicPrefixBytes) {
    return std::to_string(s.size()) + " bytes, more than " + std::to_string(kMaxTopicPrefixBytes);
  }
  if (s.front() == '$') return kDollar;
  std::size_t begin = 0;
  while (true) {
    const std::size_t end = s.find('/', begin);
    const std::string_view level =
        s.substr(begin, end == std::string_view::npos ? s.npos : end - begin);
    if (level.empty()) return "has an empty topic level (a leading, trailing or doubled '/')";
    const std::string why = topic_level_problem(level);
    if (!why.empty()) return why;
    if (end == std::string_view::npos) return "";
    begin = end + 1;
  }
}

std::string topic_error(const std::string& key, std::string_view value, const std::string& why,
                        bool prefix) {
  if (why.empty()) return "";
  return key + ": '" + escape_for_log(value, 64) + "' cannot be " +
         (prefix ? "the start of an MQTT topic: " : "an MQTT topic level: ") + why;
}

}  // namespace agv::overhead_app
