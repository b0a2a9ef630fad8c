// Baseline for the loop benchmark: a bare absolute-time periodic loop (clock_nanosleep
// TIMER_ABSTIME) that does nothing. Run beside `agvloc replay --realtime` for the same time, its
// wake-up jitter is what the machine itself gives; the localizer's jitter is compared to it.
//   timer_baseline RATE_HZ DURATION_S [FIFO_PRIORITY [SPIN_US]]
// FIFO_PRIORITY (1..99) runs the loop at SCHED_FIFO like the localizer's output thread with
// loop.realtime_priority; 0 or absent = normal scheduling. SPIN_US > 0 waits like the output
// thread with loop.spin_before_deadline_us (sleep to deadline - spin, then poll the clock).
#include <cinttypes>
#include <cstdio>
#include <cstdlib>

#include "agv/adapters/hybrid_wait_clock.hpp"
#include "agv/common/latency_histogram.hpp"
#include "agv/posix/posix_clock.hpp"
#include "agv/posix/realtime.hpp"

int main(int argc, char** argv) {
  const double rate_hz = argc > 1 ? std::atof(argv[1]) : 100.0;
  const double duration_s = argc > 2 ? std::atof(argv[2]) : 60.0;
  const int fifo_priority = argc > 3 ? std::atoi(argv[3]) : 0;
  const int spin_us = argc > 4 ? std::atoi(argv[4]) : 0;
  if (!(rate_hz > 0) || !(duration_s > 0) || fifo_priority < 0 || fifo_priority > 99 ||
      spin_us < 0 || spin_us > 2000) {
    std::fprintf(stderr,
                 "usage: timer_baseline RATE_HZ DURATION_S [FIFO_PRIORITY 0..99 [SPIN_US "
                 "0..2000]]\n");
    return 2;
  }
  if (fifo_priority > 0) {
    const int err = agv::posix::set_fifo_priority(fifo_priority);
    if (err) {
      std::fprintf(stderr, "timer_baseline: %s\n",
                   agv::posix::explain_realtime_error("SCHED_FIFO", err).c_str());
      return 1;
    }
  }
  agv::posix::PosixClock mono;
  agv::adapters::HybridWaitClock clock(mono, std::int64_t{spin_us} * 1000);
  agv::LatencyHistogram jitter;
  const auto period = static_cast<std::int64_t>(1e9 / rate_hz);
  std::int64_t next = clock.now_ns() + period;
  const std::int64_t end = next + static_cast<std::int64_t>(duration_s * 1e9);
  std::uint64_t missed = 0;
  while (next < end) {
    clock.sleep_until_ns(next);
    const std::int64_t late = clock.now_ns() - next;
    jitter.record_ns(late);
    if (late > period) ++missed;
    next += period;
  }
  std::printf("timer baseline (%s, spin %d us): %" PRIu64
              " wake-ups, jitter p50 %.3f ms p99 %.3f ms max %.3f "
              "ms, late > 1 period %" PRIu64 "\n",
              fifo_priority > 0 ? "SCHED_FIFO" : "SCHED_OTHER", spin_us, jitter.count(),
              static_cast<double>(jitter.percentile_ns(0.5)) / 1e6,
              static_cast<double>(jitter.percentile_ns(0.99)) / 1e6,
              static_cast<double>(jitter.max_ns()) / 1e6, missed);
  return 0;
}
