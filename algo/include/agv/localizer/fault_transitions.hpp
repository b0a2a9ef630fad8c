// Transitions of the status frame's fault bits, for the log (docs/guide/operation.md "Log lines"):
// which bit set or cleared, rate-limited per bit so that a flapping fault cannot flood the journal.
// Pure: the caller passes each status frame's faults and its time and prints what comes back
// (firmware/src/output_loop.cpp).
#pragma once

#include <array>
#include <cstdint>

namespace agv::localizer {

// One fault bit of AGV_Status (protocol::fault), with the DBC signal and the page's name.
struct FaultBitName {
  std::uint16_t bit;
  const char* signal;  // FaultCameraStalled, ...
  const char* name;    // camera_stalled, ... (the diagnostics page's)
};
inline constexpr int kFaultBitCount = 10;
const std::array<FaultBitName, kFaultBitCount>& fault_bit_names();

struct FaultTransition {
  std::uint16_t bit = 0;
  const char* signal = "";
  const char* name = "";
  bool set = false;  // the bit is now set (true) or cleared (false)
  // Changes of this bit since its last report, this one included: 1 normally; more when changes
  // within the hold were not reported (an even count: it changed and changed back).
  std::uint32_t changes = 0;
};

struct FaultTransitions {
  std::array<FaultTransition, kFaultBitCount> items{};
  int n = 0;
};

class FaultTransitionLog {
 public:
  // Per bit, the first kBurst transitions within a window of window_ns are reported at once (a
  // fault that sets and clears gives both lines when they happen); further ones are held to the
  // end of the window, when the bit's state then is reported with the number of changes in between.
  // So at most kBurst lines per bit per window, and every change is counted in some line.
  static constexpr std::int64_t kDefaultWindowNs = 10'000'000'000;
  static constexpr int kBurst = 2;
  explicit FaultTransitionLog(std::int64_t window_ns = kDefaultWindowNs) : window_ns_(window_ns) {}

  // One status frame's fault bits at now_ns (monotonic). Returns the transitions to report, in
  // bit order. Allocates nothing.
  FaultTransitions update(std::uint16_t faults, std::int64_t now_ns);

 private:
  struct Bit {
    bool now = false;                          // state in the previous update
    std::int64_t window_start_ns = INT64_MIN;  // of the current rate-limit window
    int lines_in_window = 0;
    std::uint32_t changes = 0;  // since the last report
  };
  std::int64_t window_ns_;
  std::array<Bit, kFaultBitCount> bits_{};
};

}  // namespace agv::localizer
