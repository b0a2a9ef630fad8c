// candump -l log lines (drivers/candump, algo/protocol/candump). Properties: an accepted line has
// a timestamp >= 0 (no overflow), at most 8 data bytes and an ID in range; formatting it gives a
// line that parses back to the same record (timestamps to the microsecond, as candump writes).
#include <cstring>
#include <string>

#include "agv/protocol/candump.hpp"
#include "fuzz_check.hpp"

namespace p = agv::protocol;

extern "C" int LLVMFuzzerTestOneInput(const unsigned char* data, std::size_t size) {
  p::CandumpRecord r;
  std::string error;
  if (!p::parse_candump_line(agv::fuzz::as_text(data, size), &r, &error)) {
    FUZZ_CHECK(!error.empty(), "a rejected line says why");
    return 0;
  }
  FUZZ_CHECK(r.t_ns >= 0 && r.frame.t_ns == r.t_ns, "t_ns %lld", static_cast<long long>(r.t_ns));
  FUZZ_CHECK(r.frame.len <= 8, "len %d", r.frame.len);
  FUZZ_CHECK(
      r.frame.id <= (r.frame.extended || r.error_frame ? p::kCanExtIdMask : p::kCanStdIdMask),
      "id %x", r.frame.id);
  FUZZ_CHECK(!r.iface.empty() && r.iface.find(' ') == std::string::npos, "iface");
  const std::string line = p::format_candump_line(r);
  p::CandumpRecord b;
  FUZZ_CHECK(p::parse_candump_line(line, &b, &error), "formatted line '%s' rejected: %s",
             line.c_str(), error.c_str());
  FUZZ_CHECK(b.t_ns == r.t_ns / 1000 * 1000, "t_ns %lld -> %lld", static_cast<long long>(r.t_ns),
             static_cast<long long>(b.t_ns));
  FUZZ_CHECK(b.iface == r.iface && b.frame.id == r.frame.id &&
                 b.frame.extended == r.frame.extended && b.frame.len == r.frame.len &&
                 b.rtr == r.rtr && b.error_frame == r.error_frame,
             "'%s' changed the frame", line.c_str());
  FUZZ_CHECK(r.rtr || std::memcmp(b.frame.data, r.frame.data, r.frame.len) == 0, "data");
  return 0;
}
