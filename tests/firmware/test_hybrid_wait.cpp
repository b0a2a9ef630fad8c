// The threaded loop with the hybrid wait (loop.spin_before_deadline_us): the kernel's wake-up
// latency does not reach the output period. The wait itself: tests/adapters/test_adapters.cpp.
#include <gtest/gtest.h>

#include <atomic>
#include <string>
#include <vector>

#include "agv/fakecamera/fake_camera.hpp"
#include "agv/posix/posix_clock.hpp"
#include "config.hpp"
#include "pipeline.hpp"
#include "test_loop_support.hpp"
#include "threaded_run_support.hpp"

using namespace agv;

namespace {

// A virtual clock on which every sleep wakes 2 ms late: a deterministic stand-in for a machine
// with a large wake-up latency. Time moves only when a thread sleeps (to the target + 2 ms) or
// reads the clock (1 us per read, so a busy-poll reaches its deadline). No real time passes, so
// the result does not depend on how busy the machine is: a real clock here made the test fail
// whenever the spinning thread was preempted (parallel ctest on 2 cores).
class LateWakeClock final : public hal::Clock {
 public:
  std::int64_t now_ns() const override { return t_ns_.fetch_add(kReadStepNs) + kReadStepNs; }
  int sleep_until_ns(std::int64_t t_ns) override {
    std::int64_t cur = t_ns_.load();
    while (cur < t_ns + kLateNs && !t_ns_.compare_exchange_weak(cur, t_ns + kLateNs)) {
    }
    return 0;
  }
  // Waits that need the monotonic clock (the fix wake-up) time out at once: the virtual
  // deadline is always "now" for the kernel.
  std::int64_t to_monotonic_ns(std::int64_t) const override { return mono_.now_ns(); }
  static constexpr std::int64_t kLateNs = 2'000'000;
  static constexpr std::int64_t kReadStepNs = 1'000;

 private:
  mutable std::atomic<std::int64_t> t_ns_{1'000'000'000};
  posix::PosixClock mono_;
};

// Runs the threaded loop for ~0.4 s (no frames, replay odometry) and returns its jitter.
LatencyHistogram loop_jitter(int spin_us) {
  config::Config cfg;
  cfg.loop.log_period_s = 0.0;
  cfg.loop.spin_before_deadline_us = spin_us;
  LateWakeClock clock;
  fakecamera::FakeCamera cam(test::scripted_camera(&clock));
  cam.push_end_of_stream();
  const std::int64_t t0 = clock.now_ns();
  const std::vector<recording::OdomRow> odo = test::straight_odometry(t0, t0 + 400'000'000, 0.2);
  test::StaticBus bus;
  app::RunResult r;
  app::PipelineIo io = test::quiet_io(&cam, &bus, &clock, &odo);
  EXPECT_EQ(app::run_threads(cfg, nullptr, io, &r), 0);
  EXPECT_GT(r.output.ticks, 20u);
  return r.output.period_jitter_ns;
}

}  // namespace

TEST(HybridWait, OutputLoopWakesAtTheDeadlineWithSpin) {
  // Without the spin every period is >= 2 ms late; with 3 ms of spin the loop polls to the
  // deadline and is never early.
  const LatencyHistogram plain = loop_jitter(0);
  EXPECT_GE(plain.percentile_ns(0.5), LateWakeClock::kLateNs);
  const LatencyHistogram spun = loop_jitter(3000);
  EXPECT_LT(spun.percentile_ns(0.5), LateWakeClock::kLateNs / 2);
  EXPECT_EQ(spun.negative_count(), 0u);
}
