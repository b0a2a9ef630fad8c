// Baseline for the loop benchmark: a bare absolute-time periodic loop (clock_nanosleep
// TIMER_ABSTIME) that does nothing. Run beside `agvloc replay --realtime` for the same time, its
// wake-up jitter is what the machine itself gives; the localizer's jitter is compared to it.
//   timer_baseline RATE_HZ DURATION_S
#include <cinttypes>
#include <cstdio>
#include <cstdlib>

#include "agv/common/latency_histogram.hpp"
#include "agv/posix/posix_clock.hpp"

int main(int argc, char** argv) {
  const double rate_hz = argc > 1 ? std::atof(argv[1]) : 100.0;
  const double duration_s = argc > 2 ? std::atof(argv[2]) : 60.0;
  if (!(rate_hz > 0) || !(duration_s > 0)) {
    std::fprintf(stderr, "usage: timer_baseline RATE_HZ DURATION_S\n");
    return 2;
  }
  agv::posix::PosixClock clock;
  agv::LatencyHistogram jitter;
  const auto period = static_cast<std::int64_t>(1e9 / rate_hz);
  std::int64_t next = clock.now_ns() + period;
  const std::int64_t end = next + static_cast<std::int64_t>(duration_s * 1e9);
  while (next < end) {
    clock.sleep_until_ns(next);
    jitter.record_ns(clock.now_ns() - next);
    next += period;
  }
  std::printf("timer baseline: %" PRIu64 " wake-ups, jitter p50 %.3f ms p99 %.3f ms max %.3f ms\n",
              jitter.count(), static_cast<double>(jitter.percentile_ns(0.5)) / 1e6,
              static_cast<double>(jitter.percentile_ns(0.99)) / 1e6,
              static_cast<double>(jitter.max_ns()) / 1e6);
  return 0;
}
