// Nesting depth of JSON text, counted before nlohmann's parser sees it: its recursion has no
// depth limit of its own, so a hostile payload of nested brackets would exhaust the stack.
#pragma once

#include <string_view>

namespace agv::vda5050::detail {

// Deepest nesting of arrays and objects outside strings is at most `limit`; stops counting past
// the limit.
inline bool nesting_within(std::string_view text, int limit) {
  int depth = 0;
  bool in_string = false, escaped = false;
  for (const char c : text) {
    if (in_string) {
      if (escaped) {
        escaped = false;
      } else if (c == '\\') {
        escaped = true;
      } else if (c == '"') {
        in_string = false;
      }
    } else if (c == '"') {
      in_string = true;
    } else if (c == '{' || c == '[') {
      if (++depth > limit) return false;
    } else if (c == '}' || c == ']') {
      --depth;
    }
  }
  return true;
}

}  // namespace agv::vda5050::detail
