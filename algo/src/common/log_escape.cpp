// Log escaping and UTF-8 validation (log_escape.hpp).
#include "agv/common/log_escape.hpp"

namespace agv {

std::size_t utf8_sequence_length(std::string_view s) {
  if (s.empty()) return 0;
  const auto b0 = static_cast<unsigned char>(s[0]);
  if (b0 < 0x80) return 1;
  std::size_t n = 0;
  // The second byte's range rules out overlong forms (E0, F0), surrogates (ED) and code points
  // beyond U+10FFFF (F4) without decoding (RFC 3629, section 4).
  unsigned char lo = 0x80, hi = 0xBF;
  if (b0 >= 0xC2 && b0 <= 0xDF) {
    n = 2;
  } else if (b0 >= 0xE0 && b0 <= 0xEF) {
    n = 3;
    if (b0 == 0xE0) lo = 0xA0;
    if (b0 == 0xED) hi = 0x9F;
  } else if (b0 >= 0xF0 && b0 <= 0xF4) {
    n = 4;
    if (b0 == 0xF0) lo = 0x90;
    if (b0 == 0xF4) hi = 0x8F;
  } else {
    return 0;  // a continuation byte, C0 / C1 (overlong) or F5..FF
  }
  if (s.size() < n) return 0;
  const auto b1 = static_cast<unsigned char>(s[1]);
  if (b1 < lo || b1 > hi) return 0;
  for (std::size_t i = 2; i < n; ++i) {
    const auto b = static_cast<unsigned char>(s[i]);
    if (b < 0x80 || b > 0xBF) return 0;
  }
  return n;
}

bool is_valid_utf8(std::string_view s) {
  while (!s.empty()) {
    const std::size_t n = utf8_sequence_length(s);
    if (n == 0) return false;
    s.remove_prefix(n);
  }
  return true;
}

std::string escape_for_log(std::string_view bytes, std::size_t max_bytes) {
  static const char kHex[] = "0123456789abcdef";
  const bool cut = bytes.size() > max_bytes;
  if (cut) bytes = bytes.substr(0, max_bytes);
  std::string out;
  out.reserve(bytes.size() + 8);
  auto hex = [&out](unsigned char b) {
    out += "\\x";
    out += kHex[b >> 4];
    out += kHex[b & 0xF];
  };
  while (!bytes.empty()) {
    const auto b0 = static_cast<unsigned char>(bytes[0]);
    std::size_t n = utf8_sequence_length(bytes);
    // C1 controls (U+0080..U+009F, C2 80..C2 9F) act as escape sequences on some terminals.
    if (n == 2 && b0 == 0xC2 && static_cast<unsigned char>(bytes[1]) < 0xA0) n = 0;
    if (n == 1 && (b0 < 0x20 || b0 == 0x7F)) n = 0;
    if (n == 0) {
      hex(b0);
      bytes.remove_prefix(1);
    } else if (b0 == '\\') {
      out += "\\\\";
      bytes.remove_prefix(1);
    } else {
      out.append(bytes.data(), n);
      bytes.remove_prefix(n);
    }
  }
  if (cut) out += "...";
  return out;
}

}  // namespace agv
