// A timed wait that another thread can cut short. The output thread sleeps to its next period
// with it; the vision worker calls wake() when a fix is ready (loop.pose_on_fix), so the fix is
// fused and its pose sent by the output thread, the only CAN writer, at once.
// Backend: drivers/posix (futex on CLOCK_MONOTONIC).
#pragma once

#include <cstdint>

namespace agv::hal {

enum class WaitResult : int {
  kDeadline = 0,  // the deadline passed without a wake()
  kWoken = 1,     // wake() was called (before or during the wait)
  kError = 2,     // the kernel wait failed (not EINTR, which is retried)
};

class Wakeup {
 public:
  virtual ~Wakeup() = default;
  // Blocks until t_ns (absolute, nanoseconds on the clock the backend was built with) or until
  // wake(). A wake() that came while nobody waited is kept for the next wait: it returns kWoken
  // at once. Several wakes before one wait count as one.
  virtual WaitResult wait_until_ns(std::int64_t t_ns) = 0;
  // From any thread; never blocks, takes no lock.
  virtual void wake() = 0;
};

}  // namespace agv::hal
