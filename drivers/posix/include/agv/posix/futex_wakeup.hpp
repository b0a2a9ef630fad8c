// hal::Wakeup on a Linux futex: wake() is one atomic exchange plus, when the waiter sleeps, one
// FUTEX_WAKE syscall; no lock is shared between the waker (vision) and the waiter (output), so
// no priority inversion. The wait is absolute on CLOCK_MONOTONIC (FUTEX_WAIT_BITSET), mapped from
// the given clock's time by hal::Clock::to_monotonic_ns.
#pragma once

#include <atomic>
#include <cstdint>

#include "agv/hal/clock.hpp"
#include "agv/hal/wakeup.hpp"

namespace agv::posix {

class FutexWakeup final : public hal::Wakeup {
 public:
  explicit FutexWakeup(const hal::Clock& clock) : clock_(clock) {}
  hal::WaitResult wait_until_ns(std::int64_t t_ns) override;
  void wake() override;

 private:
  const hal::Clock& clock_;
  std::atomic<std::uint32_t> word_{0};  // 1 = a wake is pending
};

}  // namespace agv::posix
