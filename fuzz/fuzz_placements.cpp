// The --placements CSV of agvloc-desk calibrate check (calib_check.hpp, parse_placements_csv).
// Property: an accepted text gives at least one placement, each with a finite taped pose and at
// least one frame path that is not empty and holds no control character (NUL, a lone CR: a path
// the command would open as something else); a rejected text says why, naming the file.
#include <cmath>

#include "calib_check.hpp"
#include "fuzz_check.hpp"

extern "C" int LLVMFuzzerTestOneInput(const unsigned char* data, std::size_t size) {
  const std::string text(agv::fuzz::as_text(data, size));
  std::vector<agv::desk::calib::PlacementRows> rows;
  std::string error;
  if (!agv::desk::calib::parse_placements_csv(text, "p.csv", &rows, &error)) {
    FUZZ_CHECK(error.rfind("p.csv", 0) == 0, "a rejected text names the file: '%s'", error.c_str());
    return 0;
  }
  FUZZ_CHECK(!rows.empty(), "an accepted text has a placement");
  for (const auto& r : rows) {
    FUZZ_CHECK(std::isfinite(r.taped.x_mm) && std::isfinite(r.taped.y_mm) &&
                   std::isfinite(r.taped.theta_rad),
               "non-finite taped pose");
    FUZZ_CHECK(!r.frames.empty(), "a placement without frames");
    for (const std::string& f : r.frames) {
      FUZZ_CHECK(!f.empty(), "an empty frame path");
      FUZZ_CHECK(f.find('\0') == std::string::npos, "a frame path with a NUL");
      for (const char ch : f) {
        FUZZ_CHECK(static_cast<unsigned char>(ch) >= 0x20 && ch != 0x7f,
                   "a frame path with control character 0x%02x", static_cast<unsigned>(ch));
      }
    }
  }
  return 0;
}
