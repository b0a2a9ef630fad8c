// The threaded loop with the hybrid wait (loop.spin_before_deadline_us): the kernel's wake-up
// latency does not reach the output period. The wait itself: tests/adapters/test_adapters.cpp.
#include <gtest/gtest.h>

#include <string>
#include <vector>

#include "agv/fakecamera/fake_camera.hpp"
#include "agv/posix/posix_clock.hpp"
#include "config.hpp"
#include "pipeline.hpp"
#include "test_loop_support.hpp"

using namespace agv;

namespace {

// The real monotonic clock, but every sleep wakes 2 ms late: a deterministic stand-in for a
// machine with a large wake-up latency.
class LateWakeClock final : public hal::Clock {
 public:
  std::int64_t now_ns() const override { return mono_.now_ns(); }
  int sleep_until_ns(std::int64_t t_ns) override { return mono_.sleep_until_ns(t_ns + kLateNs); }
  static constexpr std::int64_t kLateNs = 2'000'000;

 private:
  posix::PosixClock mono_;
};

// Runs the threaded loop for ~0.4 s (no frames, replay odometry) and returns its jitter.
LatencyHistogram loop_jitter(int spin_us) {
  config::Config cfg;
  cfg.loop.log_period_s = 0.0;
  cfg.loop.spin_before_deadline_us = spin_us;
  LateWakeClock clock;
  fakecamera::FakeCamera::Options o;
  o.clock = &clock;
  o.end_of_stream_when_empty = true;
  fakecamera::FakeCamera cam(o);
  cam.push_end_of_stream();
  std::vector<recording::OdomRow> odo;
  const std::int64_t t0 = clock.now_ns();
  for (std::int64_t t = t0; t < t0 + 400'000'000; t += 10'000'000) odo.push_back({t, 0.2, 0.0});
  test::StaticBus bus;
  app::PipelineIo io;
  io.camera = &cam;
  io.bus = &bus;
  io.clock = &clock;
  io.odometry = &odo;
  io.quiet = true;
  app::RunResult r;
  EXPECT_EQ(app::run_threads(cfg, nullptr, io, &r), 0);
  EXPECT_GT(r.output.ticks, 20u);
  return r.output.period_jitter_ns;
}

}  // namespace

TEST(HybridWait, OutputLoopWakesAtTheDeadlineWithSpin) {
  // Without the spin every period is >= 2 ms late; with 3 ms of spin the loop polls to the
  // deadline (a preempted poll can still be late, hence the median) and is never early.
  const LatencyHistogram plain = loop_jitter(0);
  EXPECT_GE(plain.percentile_ns(0.5), LateWakeClock::kLateNs);
  const LatencyHistogram spun = loop_jitter(3000);
  EXPECT_LT(spun.percentile_ns(0.5), LateWakeClock::kLateNs / 2);
  EXPECT_EQ(spun.negative_count(), 0u);
}
