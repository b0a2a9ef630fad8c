// hal::Wakeup on a futex (drivers/posix): the output thread's timed wait that the vision worker
// can cut short (loop.pose_on_fix).
#include <gtest/gtest.h>

#include <thread>

#include "agv/posix/futex_wakeup.hpp"
#include "agv/posix/posix_clock.hpp"

using namespace agv;

TEST(FutexWakeup, ReturnsDeadlineWhenNobodyWakes) {
  posix::PosixClock clock;
  posix::FutexWakeup w(clock);
  const std::int64_t t0 = clock.now_ns();
  EXPECT_EQ(w.wait_until_ns(t0 + 20'000'000), hal::WaitResult::kDeadline);
  EXPECT_GE(clock.now_ns(), t0 + 20'000'000);
  EXPECT_EQ(w.wait_until_ns(t0), hal::WaitResult::kDeadline);  // already passed: at once
}

TEST(FutexWakeup, AWakeBeforeTheWaitIsKeptOnce) {
  posix::PosixClock clock;
  posix::FutexWakeup w(clock);
  w.wake();
  w.wake();  // several wakes before one wait count as one
  const std::int64_t t0 = clock.now_ns();
  EXPECT_EQ(w.wait_until_ns(t0 + 1'000'000'000), hal::WaitResult::kWoken);
  EXPECT_LT(clock.now_ns() - t0, 100'000'000);
  EXPECT_EQ(w.wait_until_ns(clock.now_ns() + 5'000'000), hal::WaitResult::kDeadline);
}

TEST(FutexWakeup, AnotherThreadCutsTheWaitShort) {
  posix::PosixClock clock;
  posix::FutexWakeup w(clock);
  const std::int64_t t0 = clock.now_ns();
  std::thread waker([&] {
    clock.sleep_until_ns(t0 + 20'000'000);
    w.wake();
  });
  EXPECT_EQ(w.wait_until_ns(t0 + 5'000'000'000), hal::WaitResult::kWoken);
  const std::int64_t waited = clock.now_ns() - t0;
  waker.join();
  EXPECT_GE(waited, 20'000'000);
  EXPECT_LT(waited, 1'000'000'000);  // woken, not timed out
}
