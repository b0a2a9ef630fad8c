// Proves the real-time contract of agv::fusion::Ekf: after construction, add_odometry, add_fix
// (fused, delayed, gated, too old, invalid, kidnap re-initialisation), estimate_at and take_flags
// never touch the heap (allocations counted by tests/support/alloc_counter.cpp).
#include <gtest/gtest.h>

#include <cstdint>
#include <cstdlib>
#include <limits>
#include <new>

#include "../support/alloc_counter.hpp"
#include "agv/fusion/ekf.hpp"


using namespace agv;
using namespace agv::fusion;

TEST(FusionEkfAlloc, CounterSeesAllocations) {
  const long before = agv::test::allocations();
  auto* p = new int(3);
  EXPECT_GT(agv::test::allocations(), before);  // the counting hook is active
  delete p;
}

TEST(FusionEkfAlloc, NoHeapAllocationAfterConstruction) {
  constexpr std::int64_t kMs = 1'000'000;
  Eigen::Matrix3d R = Eigen::Matrix3d::Zero();
  R(0, 0) = R(1, 1) = 0.04;
  R(2, 2) = 1e-7;
  Eigen::Matrix3d bad = R;
  bad(0, 0) = -1.0;
  EkfConfig c;
  c.core.history_capacity = 64;  // small, so the ring wraps many times below
  Ekf ekf{c};

  const long before = agv::test::allocations();
  std::uint64_t outcomes[6] = {};
  double checksum = 0.0;
  for (int i = 0; i <= 3000; ++i) {  // 30 s at 100 Hz
    const std::int64_t t = i * 10 * kMs;
    const double x_mm = static_cast<double>(i) * 10.0;
    ekf.add_odometry(t, 1.0, 0.0);
    if (i == 1500) ekf.add_odometry(t, 1.0, 0.0);  // duplicate time: rejected
    if (i == 1600) ekf.add_odometry(t + 1, std::numeric_limits<double>::quiet_NaN(), 0.0);
    if (i % 20 == 5 && i < 2000) {  // fixes delayed by 50 ms
      const std::int64_t te = t - 50 * kMs;
      const double xe = x_mm - 50.0;
      outcomes[static_cast<int>(ekf.add_fix(te, {xe, 0.0, 0.0}, R))]++;
      outcomes[static_cast<int>(ekf.add_fix(te, {xe + 1000.0, 0.0, 0.0}, R))]++;    // gated
      outcomes[static_cast<int>(ekf.add_fix(te, {xe, 0.0, 0.0}, bad))]++;           // invalid
      outcomes[static_cast<int>(ekf.add_fix(t - 900 * kMs, {xe, 0.0, 0.0}, R))]++;  // too old
    }
    if (i >= 2000 && i % 50 == 0) {  // kidnapped: 3 m to the side
      outcomes[static_cast<int>(ekf.add_fix(t, {x_mm, 3000.0, 0.0}, R))]++;
    }
    const PoseEstimate e = ekf.estimate_at(t + 5 * kMs);
    checksum += e.pose.x_mm + static_cast<double>(ekf.take_flags());
  }
  const long during = agv::test::allocations() - before;

  EXPECT_EQ(during, 0);
  EXPECT_GT(outcomes[static_cast<int>(FixOutcome::kInitialised)], 0u);
  EXPECT_GT(outcomes[static_cast<int>(FixOutcome::kFused)], 50u);
  EXPECT_GT(outcomes[static_cast<int>(FixOutcome::kRejectedGate)], 50u);
  EXPECT_GT(outcomes[static_cast<int>(FixOutcome::kRejectedInvalid)], 50u);
  EXPECT_GT(outcomes[static_cast<int>(FixOutcome::kRejectedTooOld)], 50u);
  EXPECT_GT(outcomes[static_cast<int>(FixOutcome::kReinitialised)], 0u);
  EXPECT_GT(ekf.counters().history_overwrites, 0u);
  EXPECT_GT(ekf.counters().fixes_delayed, 0u);
  EXPECT_TRUE(std::isfinite(checksum));
}
