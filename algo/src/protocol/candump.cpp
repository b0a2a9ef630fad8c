#include "agv/protocol/candump.hpp"

#include <cstdint>
#include <cstdio>

namespace agv::protocol {

namespace {

constexpr std::uint32_t kErrFlag = 0x20000000u;  // CAN_ERR_FLAG in linux/can.h

int hex_val(char c) {
  if (c >= '0' && c <= '9') return c - '0';
  if (c >= 'A' && c <= 'F') return c - 'A' + 10;
  if (c >= 'a' && c <= 'f') return c - 'a' + 10;
  return -1;
}

bool fail(std::string* error, const char* msg) {
  if (error) *error = msg;
  return false;
}

}  // namespace

bool parse_candump_line(std::string_view line, CandumpRecord* out, std::string* error) {
  while (!line.empty() && (line.back() == '\n' || line.back() == '\r')) line.remove_suffix(1);
  std::size_t p = 0;
  if (line.size() < 4 || line[0] != '(') return fail(error, "expected '(' timestamp");
  ++p;
  std::int64_t sec = 0;
  int sec_digits = 0;
  while (p < line.size() && line[p] >= '0' && line[p] <= '9') {
    if (++sec_digits > 12) return fail(error, "timestamp seconds too long");
    sec = sec * 10 + (line[p++] - '0');
  }
  if (sec_digits == 0 || p >= line.size() || line[p] != '.') {
    return fail(error, "timestamp must be seconds.microseconds");
  }
  ++p;
  std::int64_t frac_ns = 0;
  int frac_digits = 0;
  std::int64_t unit = 100'000'000;
  while (p < line.size() && line[p] >= '0' && line[p] <= '9') {
    if (++frac_digits > 9) return fail(error, "timestamp fraction too long");
    frac_ns += (line[p++] - '0') * unit;
    unit /= 10;
  }
  if (frac_digits == 0 || p >= line.size() || line[p] != ')') {
    return fail(error, "timestamp must end with ')'");
  }
  // 12 digits of seconds do not fit in int64 nanoseconds: bound before multiplying.
  if (sec > (INT64_MAX - frac_ns) / 1'000'000'000) {
    return fail(error, "timestamp above 9223372036.854775807 s (int64 nanoseconds)");
  }
  ++p;
  if (p >= line.size() || line[p] != ' ') return fail(error, "expected ' ' after timestamp");
  ++p;
  const std::size_t if_start = p;
  while (p < line.size() && line[p] != ' ') ++p;
  if (p == if_start || p >= line.size()) return fail(error, "missing interface name or frame");
  CandumpRecord rec;
  rec.iface = std::string(line.substr(if_start, p - if_start));
  ++p;
  const std::size_t hash = line.find('#', p);
  if (hash == std::string_view::npos) return fail(error, "missing '#'");
  const std::size_t id_digits = hash - p;
  if (id_digits != 3 && id_digits != 8) return fail(error, "ID must have 3 or 8 hex digits");
  std::uint32_t id = 0;
  for (std::size_t i = p; i < hash; ++i) {
    const int v = hex_val(line[i]);
    if (v < 0) return fail(error, "ID is not hexadecimal");
    id = (id << 4) | static_cast<std::uint32_t>(v);
  }
  if (id_digits == 3) {
    if (id > kCanStdIdMask) return fail(error, "standard ID above 0x7FF");
    rec.frame.id = id;
  } else {
    if (id & kErrFlag) {
      rec.error_frame = true;
      id &= ~kErrFlag;
    } else {
      rec.frame.extended = true;
    }
    if (id > kCanExtIdMask) return fail(error, "extended ID above 0x1FFFFFFF");
    rec.frame.id = id;
  }
  p = hash + 1;
  if (p < line.size() && line[p] == '#') return fail(error, "CAN FD frames are not supported");
  if (p < line.size() && (line[p] == 'R' || line[p] == 'r')) {
    rec.rtr = true;
    ++p;
    if (p < line.size() && line[p] != ' ') {
      const int v = hex_val(line[p]);
      if (v < 0 || v > 8) return fail(error, "bad remote frame length");
      rec.frame.len = static_cast<std::uint8_t>(v);
      ++p;
    }
  } else {
    int n = 0;
    while (p < line.size() && line[p] != '_' && line[p] != ' ') {
      if (p + 1 >= line.size() || line[p + 1] == '_')
        return fail(error, "odd number of hex digits");
      const int hi = hex_val(line[p]), lo = hex_val(line[p + 1]);
      if (hi < 0 || lo < 0) return fail(error, "data is not hexadecimal");
      if (n >= 8) return fail(error, "more than 8 data bytes");
      rec.frame.data[n++] = static_cast<std::uint8_t>(hi * 16 + lo);
      p += 2;
    }
    rec.frame.len = static_cast<std::uint8_t>(n);
    if (p < line.size() && line[p] == '_') {  // "_X": raw DLC 9..F of an 8-byte frame; ignored
      if (n != 8 || p + 1 >= line.size() || hex_val(line[p + 1]) < 9) {
        return fail(error, "bad '_' DLC suffix");
      }
      p += 2;
    }
  }
  // candump -x / asc2log append " R" or " T" (direction); other trailing text is an error.
  if (p < line.size()) {
    const std::string_view rest = line.substr(p);
    if (rest != " R" && rest != " T") return fail(error, "unexpected text after the frame");
  }
  rec.t_ns = sec * 1'000'000'000 + frac_ns;
  rec.frame.t_ns = rec.t_ns;
  *out = std::move(rec);
  return true;
}

std::string format_candump_line(const CandumpRecord& rec) {
  char buf[128];
  const std::int64_t t = rec.t_ns < 0 ? 0 : rec.t_ns;
  int n =
      std::snprintf(buf, sizeof buf, "(%010lld.%06lld) ", static_cast<long long>(t / 1'000'000'000),
                    static_cast<long long>((t % 1'000'000'000) / 1000));
  std::string s(buf, static_cast<std::size_t>(n));
  s += rec.iface;
  if (rec.error_frame) {
    n = std::snprintf(buf, sizeof buf, " %08X#", (rec.frame.id & kCanExtIdMask) | kErrFlag);
  } else if (rec.frame.extended) {
    n = std::snprintf(buf, sizeof buf, " %08X#", rec.frame.id & kCanExtIdMask);
  } else {
    n = std::snprintf(buf, sizeof buf, " %03X#", rec.frame.id & kCanStdIdMask);
  }
  s.append(buf, static_cast<std::size_t>(n));
  const int len = rec.frame.len > 8 ? 8 : rec.frame.len;
  if (rec.rtr) {
    s += 'R';
    if (len > 0) s += static_cast<char>('0' + len);
    return s;
  }
  static const char* kHex = "0123456789ABCDEF";
  for (int i = 0; i < len; ++i) {
    s += kHex[rec.frame.data[i] >> 4];
    s += kHex[rec.frame.data[i] & 0xF];
  }
  return s;
}

}  // namespace agv::protocol
