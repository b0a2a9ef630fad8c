// Time source. The real backend reads CLOCK_MONOTONIC; replay and tests use a simulated clock.
#pragma once

#include <cstdint>

namespace agv::hal {

// Nanoseconds per millisecond, for the `_ms` quantities of configurations and timeouts.
inline constexpr std::int64_t kNsPerMs = 1'000'000;

class Clock {
 public:
  virtual ~Clock() = default;
  // Monotonic time in nanoseconds (same clock as frame and CAN timestamps).
  virtual std::int64_t now_ns() const = 0;
  // Sleeps until the absolute monotonic time t_ns (returns at once if it has passed).
  // Returns 0, or an errno value when the sleep was interrupted (EINTR) or failed.
  virtual int sleep_until_ns(std::int64_t t_ns) = 0;
  // The CLOCK_MONOTONIC time (ns) at which this clock reads t_ns, so a kernel wait on the
  // monotonic clock can end at a time of this clock (hal::Wakeup). Identity for the monotonic
  // clock; a scaled replay clock maps it.
  virtual std::int64_t to_monotonic_ns(std::int64_t t_ns) const { return t_ns; }
};

}  // namespace agv::hal
