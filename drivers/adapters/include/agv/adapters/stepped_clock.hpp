// Replay time for `agvloc replay --fast` (as ArduPilot's stop_clock / PX4's replay mode): time
// stands still until the scheduler steps it; sleep_until_ns jumps there at once. The same output
// step as live then runs in recording time, deterministically, as fast as the CPU allows.
#pragma once

#include <cstdint>

#include "agv/hal/clock.hpp"

namespace agv::adapters {

class SteppedClock final : public hal::Clock {
 public:
  explicit SteppedClock(std::int64_t t0_ns = 0) : t_ns_(t0_ns) {}
  std::int64_t now_ns() const override { return t_ns_; }
  // Never goes backwards: a time in the past leaves the clock where it is.
  int sleep_until_ns(std::int64_t t_ns) override {
    if (t_ns > t_ns_) t_ns_ = t_ns;
    return 0;
  }

 private:
  std::int64_t t_ns_;
};

}  // namespace agv::adapters
