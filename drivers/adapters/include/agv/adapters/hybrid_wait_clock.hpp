// Hybrid wait for the output thread (loop.spin_before_deadline_us): sleep on the wrapped clock to
// (deadline - spin), then busy-poll it to the deadline. The kernel's wake-up latency (tens of
// microseconds on this class of machine, more under load) then lands inside the spin window
// instead of on the output period; the price is up to `spin` of busy CPU per period. Pure
// hal::Clock decorator: works on the monotonic clock, the replay's scaled clock and test fakes.
#pragma once

#include <cerrno>
#include <cstdint>

#include "agv/hal/clock.hpp"

namespace agv::adapters {

class HybridWaitClock final : public hal::Clock {
 public:
  // spin_ns in the wrapped clock's units; 0 = plain sleep_until_ns of the wrapped clock.
  HybridWaitClock(hal::Clock& base, std::int64_t spin_ns) : base_(base), spin_ns_(spin_ns) {}

  std::int64_t now_ns() const override { return base_.now_ns(); }
  std::int64_t to_monotonic_ns(std::int64_t t_ns) const override {
    return base_.to_monotonic_ns(t_ns);
  }

  // Never returns before t_ns (unless the wrapped sleep fails with an error other than EINTR).
  int sleep_until_ns(std::int64_t t_ns) override {
    if (spin_ns_ <= 0) return base_.sleep_until_ns(t_ns);
    const std::int64_t coarse_ns = t_ns - spin_ns_;
    // A signal must not turn the remaining sleep into a long spin: sleep again.
    while (base_.now_ns() < coarse_ns) {
      const int rc = base_.sleep_until_ns(coarse_ns);
      if (rc != 0 && rc != EINTR) return rc;
    }
    while (base_.now_ns() < t_ns) cpu_relax();
    return 0;
  }

  std::int64_t spin_ns() const { return spin_ns_; }

 private:
  static void cpu_relax() {
#if defined(__x86_64__) || defined(__i386__)
    __builtin_ia32_pause();
#elif defined(__aarch64__)
    __asm__ __volatile__("yield" ::: "memory");
#endif
  }

  hal::Clock& base_;
  std::int64_t spin_ns_;
};

}  // namespace agv::adapters
