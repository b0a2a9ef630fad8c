#pragma once

#include "agv/hal/clock.hpp"

namespace agv::posix {

// CLOCK_MONOTONIC; sleep_until_ns uses clock_nanosleep(TIMER_ABSTIME) so periodic loops do not
// accumulate drift from their own execution time.
class PosixClock final : public hal::Clock {
 public:
  std::int64_t now_ns() const override;
  int sleep_until_ns(std::int64_t t_ns) override;
};

// CLOCK_MONOTONIC now, without a clock object.
std::int64_t monotonic_now_ns();

}  // namespace agv::posix
