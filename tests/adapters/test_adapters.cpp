// hal adapters (drivers/adapters): the hybrid sleep+spin wait of the output loop
// (loop.spin_before_deadline_us), the stepped clock of fast replay, the scaled replay clock.
#include <gtest/gtest.h>

#include <cerrno>
#include <vector>

#include "agv/adapters/hybrid_wait_clock.hpp"
#include "agv/adapters/scaled_clock.hpp"
#include "agv/adapters/stepped_clock.hpp"
#include "agv/can/fake_can.hpp"

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
  adapters::HybridWaitClock wait(fake, 100 * kUs);
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
  adapters::HybridWaitClock wait(fake, 0);
  const std::int64_t deadline = 10'000 * kUs;
  ASSERT_EQ(wait.sleep_until_ns(deadline), 0);
  ASSERT_EQ(fake.sleep_targets.size(), 1u);
  EXPECT_EQ(fake.sleep_targets[0], deadline);
  EXPECT_EQ(fake.peek(), deadline + 60 * kUs);
}

TEST(HybridWait, NeverWakesBeforeTheDeadline) {
  FakeClock fake;  // an exact kernel: the coarse sleep ends 100 us early, the poll covers it
  adapters::HybridWaitClock wait(fake, 100 * kUs);
  const std::int64_t deadline = 5'000 * kUs;
  ASSERT_EQ(wait.sleep_until_ns(deadline), 0);
  EXPECT_GE(fake.peek(), deadline);
  EXPECT_LE(fake.peek(), deadline + fake.poll_step_ns);
  EXPECT_GE(fake.polls, 100 * kUs / fake.poll_step_ns);  // it did poll through the window
}

TEST(HybridWait, SignalDoesNotTurnTheSleepIntoASpin) {
  FakeClock fake;
  fake.eintr_after_ns = 1'000 * kUs;
  adapters::HybridWaitClock wait(fake, 100 * kUs);
  const std::int64_t deadline = 10'000 * kUs;
  ASSERT_EQ(wait.sleep_until_ns(deadline), 0);
  EXPECT_EQ(fake.sleep_targets.size(), 2u);  // slept again after EINTR
  EXPECT_GE(fake.peek(), deadline);
  EXPECT_LT(fake.polls, 2 * 100 * kUs / fake.poll_step_ns);  // polled ~the spin window only
}

TEST(HybridWait, DeadlineAlreadyPassedReturnsAtOnce) {
  FakeClock fake;
  fake.t_ns_ = 20'000 * kUs;
  adapters::HybridWaitClock wait(fake, 100 * kUs);
  ASSERT_EQ(wait.sleep_until_ns(10'000 * kUs), 0);
  EXPECT_TRUE(fake.sleep_targets.empty());
  EXPECT_LE(fake.peek(), 20'000 * kUs + 2 * fake.poll_step_ns);
}

TEST(SteppedClock, StandsStillUntilSteppedAndNeverGoesBack) {
  adapters::SteppedClock c(1000);
  EXPECT_EQ(c.now_ns(), 1000);
  EXPECT_EQ(c.now_ns(), 1000);
  EXPECT_EQ(c.sleep_until_ns(5000), 0);
  EXPECT_EQ(c.now_ns(), 5000);
  EXPECT_EQ(c.sleep_until_ns(3000), 0);
  EXPECT_EQ(c.now_ns(), 5000);
}

TEST(ScaledClock, MapsItsTimeToTheMonotonicClock) {
  adapters::SteppedClock base(10'000);
  adapters::ScaledClock half(base, 1'000'000, 0.5, 10'000);  // t_first at base 10 us, half speed
  EXPECT_EQ(half.now_ns(), 1'000'000);
  EXPECT_EQ(half.to_monotonic_ns(1'000'000), 10'000);
  EXPECT_EQ(half.to_monotonic_ns(1'001'000), 12'000);  // 1 us of replay = 2 us of wall time
  base.sleep_until_ns(12'000);
  EXPECT_EQ(half.now_ns(), 1'001'000);
  adapters::HybridWaitClock wait(half, 0);
  EXPECT_EQ(wait.to_monotonic_ns(1'001'000), 12'000);
}

// replay --odom-from-can takes the first odometry frame from the bus to anchor its clock, then
// hands it back: fusion gets it first, on the replay clock, then the bus's frames in order.
TEST(TimeMappedBus, AnUnreadFrameComesFirstOnTheScaledClock) {
  can::FakeCanNetwork net;
  auto sender = net.create_endpoint(16);
  auto inner = net.create_endpoint(16);
  hal::CanFrame a, b, got;
  a.id = 0x311;
  a.len = 8;
  b = a;
  b.data[0] = 2;
  net.set_time_ns(10'000);
  ASSERT_EQ(sender->send(a), hal::CanStatus::kOk);
  net.set_time_ns(14'000);
  ASSERT_EQ(sender->send(b), hal::CanStatus::kOk);
  hal::CanFrame anchor;
  ASSERT_EQ(inner->receive(&anchor, 0), hal::CanStatus::kOk);
  ASSERT_EQ(anchor.t_ns, 10'000);

  adapters::SteppedClock base(10'000);
  adapters::ScaledClock half(base, 1'000'000, 0.5, anchor.t_ns);
  adapters::TimeMappedBus bus(*inner, &half);
  bus.unread(anchor);
  ASSERT_EQ(bus.receive(&got, 0), hal::CanStatus::kOk);
  EXPECT_EQ(got.data[0], 0);
  EXPECT_EQ(got.t_ns, 1'000'000);
  ASSERT_EQ(bus.receive(&got, 0), hal::CanStatus::kOk);
  EXPECT_EQ(got.data[0], 2);
  EXPECT_EQ(got.t_ns, 1'002'000);
  EXPECT_NE(bus.receive(&got, 0), hal::CanStatus::kOk);
}

// At half speed two frames received 1 ns apart (the least the SocketCAN driver leaves between
// them) map onto one nanosecond of the replay clock; fusion would drop the second as not after
// the first (hil_garbage under load). Delivered 1 ns apart instead, and in order.
TEST(TimeMappedBus, FramesAFewNanosecondsApartStayStrictlyInOrderAtHalfSpeed) {
  can::FakeCanNetwork net;
  auto sender = net.create_endpoint(16);
  auto inner = net.create_endpoint(16);
  hal::CanFrame a;
  a.id = 0x311;
  a.len = 8;
  for (std::int64_t t : {10'000, 10'001, 10'002, 10'004}) {
    net.set_time_ns(t);
    ASSERT_EQ(sender->send(a), hal::CanStatus::kOk);
  }
  adapters::SteppedClock base(10'000);
  adapters::ScaledClock half(base, 1'000'000, 0.5, 10'000);
  adapters::TimeMappedBus bus(*inner, &half);
  std::int64_t prev = INT64_MIN;
  hal::CanFrame got;
  for (int i = 0; i < 4; ++i) {
    ASSERT_EQ(bus.receive(&got, 0), hal::CanStatus::kOk);
    EXPECT_GT(got.t_ns, prev) << i;
    prev = got.t_ns;
  }
  // 10'001, 10'002 and 10'004 map onto or before the frame before them: each 1 ns later.
  EXPECT_EQ(prev, 1'000'003);
}
