// QR payload text (docs/design/landmark.md). Property: whatever parse_payload accepts,
// format_payload writes back as the same text (the format is canonical and fixed width; only a
// negative zero comes back with '+'), and that re-parses to the same fields.
#include <cstdint>
#include <string>

#include "agv/common/landmark.hpp"
#include "fuzz_check.hpp"

extern "C" int LLVMFuzzerTestOneInput(const unsigned char* data, std::size_t size) {
  const std::string_view text = agv::fuzz::as_text(data, size);
  agv::LandmarkPayload p;
  const agv::PayloadError e = agv::parse_payload(text, &p);
  FUZZ_CHECK(agv::to_string(e) != nullptr, "every error has a name");
  if (e != agv::PayloadError::kOk) return 0;
  FUZZ_CHECK(p.id >= 1 && p.id <= 65535, "id %u", p.id);
  const std::string back = agv::format_payload(p);
  // The one allowed difference: a negative zero ("-000000.0", "-000.00") is written with '+'.
  std::string expected(text);
  for (std::size_t at : {std::size_t{11}, std::size_t{21}, std::size_t{31}}) {
    if (expected.size() == 38 && expected[at] == '-' &&
        expected.find_first_not_of("0.", at + 1) >= (at == 31 ? 38 : at + 9)) {
      expected[at] = '+';
    }
  }
  FUZZ_CHECK(back == expected, "round trip: '%s' -> '%s'", expected.c_str(), back.c_str());
  agv::LandmarkPayload q;
  FUZZ_CHECK(agv::parse_payload(back, &q) == agv::PayloadError::kOk, "re-parse");
  FUZZ_CHECK(q.id == p.id && q.has_pose == p.has_pose && q.x_mm == p.x_mm && q.y_mm == p.y_mm &&
                 q.heading_deg == p.heading_deg,
             "fields differ after the round trip");
  return 0;
}
