// agvloc-desk report's readers of a replay's poses.csv and fixes.csv (report.hpp): files a user
// hands the desk tool, possibly edited or from another version. The first byte picks the file
// (even: poses.csv, odd: fixes.csv), the rest is its text, written to a temporary file (the
// readers take a path). Property: accepted rows have finite poses, and a poses.csv row's
// time_since_fix_ns is -1 (no fix yet) or not negative; a rejected file says why.
#include <unistd.h>

#include <cmath>
#include <cstdio>
#include <string>

#include "fuzz_check.hpp"
#include "report.hpp"

extern "C" int LLVMFuzzerTestOneInput(const unsigned char* data, std::size_t size) {
  if (size == 0) return 0;
  static const std::string path = "/tmp/agv_fuzz_report_" + std::to_string(::getpid()) + ".csv";
  FILE* f = std::fopen(path.c_str(), "wb");
  if (!f) return 0;
  std::fwrite(data + 1, 1, size - 1, f);
  std::fclose(f);
  std::string error;
  if (data[0] % 2 == 0) {
    std::vector<agv::desk::PoseRow> rows;
    if (!agv::desk::read_poses_csv(path, &rows, &error)) {
      FUZZ_CHECK(!error.empty(), "a rejected poses.csv says why");
      return 0;
    }
    for (const auto& r : rows) {
      FUZZ_CHECK(std::isfinite(r.pose.x_mm) && std::isfinite(r.pose.y_mm) &&
                     std::isfinite(r.pose.theta_rad),
                 "non-finite pose");
      FUZZ_CHECK(r.time_since_fix_ns >= -1, "time_since_fix_ns %lld",
                 static_cast<long long>(r.time_since_fix_ns));
    }
  } else {
    std::vector<agv::desk::FixRow> rows;
    if (!agv::desk::read_fixes_csv(path, &rows, &error)) {
      FUZZ_CHECK(!error.empty(), "a rejected fixes.csv says why");
      return 0;
    }
    for (const auto& r : rows) {
      FUZZ_CHECK(std::isfinite(r.vehicle_in_world.x_mm) && std::isfinite(r.vehicle_in_world.y_mm) &&
                     std::isfinite(r.vehicle_in_world.theta_rad),
                 "non-finite fix pose");
    }
  }
  return 0;
}
