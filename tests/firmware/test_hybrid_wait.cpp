// Hybrid wait of the output loop (loop.spin_before_deadline_us): sleep to (deadline - spin), then
// poll the clock to the deadline, so the kernel's wake-up latency does not reach the period.
#include <gtest/gtest.h>

#include <cerrno>
#include <string>
#include <vector>

#include "agv/fakecamera/fake_camera.hpp"
#include "agv/posix/posix_clock.hpp"
#include "config.hpp"
#include "hybrid_wait_clock.hpp"
#include "pipeline.hpp"
#include "test_loop_support.hpp"

using namespace agv;

namespace {

constexpr std::int64_t kUs = 1000;

// Simulated time. A sleep wakes `wake_latency_ns` after its target (the kernel's wake-up
// latency); every now_ns() call takes `poll_step_ns`, so a busy-poll makes time pass.
class FakeClock final : public hal::Clock {
 public:
  std::int64_t now_ns() const override {
    t_ns_ += poll_step_ns;
    ++polls;
    return t_ns_;
  }
  int sleep_until_ns(std::int64_t t_ns) override {
    sleep_targets.push_back(t_ns);
    if (eintr_after_ns > 0) {  // a signal arrives before the target
      t_ns_ += eintr_after_ns;
      eintr_after_ns = 0;
      return EINTR;
    }
    if (t_ns + wake_latency_ns > t_ns_) t_ns_ = t_ns + wake_latency_ns;
    return 0;
  }
  std::int64_t peek() const { return t_ns_; }

  mutable std::int64_t t_ns_ = 0;
  mutable int polls = 0;
  std::int64_t poll_step_ns = 100;
  std::int64_t wake_latency_ns = 0;
  std::int64_t eintr_after_ns = 0;
  std::vector<std::int64_t> sleep_targets;
};

}  // namespace

TEST(HybridWait, SpinHidesTheWakeUpLatency) {
  FakeClock fake;
  fake.wake_latency_ns = 60 * kUs;
  app::HybridWaitClock wait(fake, 100 * kUs);
  const std::int64_t deadline = 10'000 * kUs;
  ASSERT_EQ(wait.sleep_until_ns(deadline), 0);
  ASSERT_EQ(fake.sleep_targets.size(), 1u);
  EXPECT_EQ(fake.sleep_targets[0], deadline - 100 * kUs);  // the kernel sleep ends early
  EXPECT_GE(fake.peek(), deadline);                        // never before the deadline
  EXPECT_LE(fake.peek(), deadline + fake.poll_step_ns);    // and at it, not 60 us late
}

TEST(HybridWait, PlainSleepCarriesTheWakeUpLatency) {
  // The behaviour the spin removes: without it the wake-up is late by the kernel's latency.
  FakeClock fake;
  fake.wake_latency_ns = 60 * kUs;
  app::HybridWaitClock wait(fake, 0);
  const std::int64_t deadline = 10'000 * kUs;
  ASSERT_EQ(wait.sleep_until_ns(deadline), 0);
  ASSERT_EQ(fake.sleep_targets.size(), 1u);
  EXPECT_EQ(fake.sleep_targets[0], deadline);
  EXPECT_EQ(fake.peek(), deadline + 60 * kUs);
}

TEST(HybridWait, NeverWakesBeforeTheDeadline) {
  FakeClock fake;  // an exact kernel: the coarse sleep ends 100 us early, the poll covers it
  app::HybridWaitClock wait(fake, 100 * kUs);
  const std::int64_t deadline = 5'000 * kUs;
  ASSERT_EQ(wait.sleep_until_ns(deadline), 0);
  EXPECT_GE(fake.peek(), deadline);
  EXPECT_LE(fake.peek(), deadline + fake.poll_step_ns);
  EXPECT_GE(fake.polls, 100 * kUs / fake.poll_step_ns);  // it did poll through the window
}

TEST(HybridWait, SignalDoesNotTurnTheSleepIntoASpin) {
  FakeClock fake;
  fake.eintr_after_ns = 1'000 * kUs;
  app::HybridWaitClock wait(fake, 100 * kUs);
  const std::int64_t deadline = 10'000 * kUs;
  ASSERT_EQ(wait.sleep_until_ns(deadline), 0);
  EXPECT_EQ(fake.sleep_targets.size(), 2u);  // slept again after EINTR
  EXPECT_GE(fake.peek(), deadline);
  EXPECT_LT(fake.polls, 2 * 100 * kUs / fake.poll_step_ns);  // polled ~the spin window only
}

TEST(HybridWait, DeadlineAlreadyPassedReturnsAtOnce) {
  FakeClock fake;
  fake.t_ns_ = 20'000 * kUs;
  app::HybridWaitClock wait(fake, 100 * kUs);
  ASSERT_EQ(wait.sleep_until_ns(10'000 * kUs), 0);
  EXPECT_TRUE(fake.sleep_targets.empty());
  EXPECT_LE(fake.peek(), 20'000 * kUs + 2 * fake.poll_step_ns);
}

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
