// Proves the steady-state output loop (CAN odometry in, fixes in, fusion, CAN out every period,
// fix-triggered poses) does not touch the heap once warmed up. Global operator new is replaced
// in this binary only.
#include <gtest/gtest.h>

#include <atomic>
#include <cstdlib>
#include <new>

#include "agv/protocol/codec.hpp"
#include "config.hpp"
#include "test_loop_support.hpp"

namespace {
std::atomic<long> g_allocs{0};
std::atomic<bool> g_counting{false};
}  // namespace

// The replacements pair malloc with free on purpose; GCC cannot see that through inlining.
#pragma GCC diagnostic ignored "-Wmismatched-new-delete"

void* operator new(std::size_t n) {
  if (g_counting.load(std::memory_order_relaxed)) g_allocs.fetch_add(1);
  if (void* p = std::malloc(n ? n : 1)) return p;
  throw std::bad_alloc();
}
void* operator new[](std::size_t n) { return operator new(n); }
void* operator new(std::size_t n, std::align_val_t al) {
  if (g_counting.load(std::memory_order_relaxed)) g_allocs.fetch_add(1);
  if (void* p =
          std::aligned_alloc(static_cast<std::size_t>(al), (n + static_cast<std::size_t>(al) - 1) &
                                                               ~(static_cast<std::size_t>(al) - 1)))
    return p;
  throw std::bad_alloc();
}
void operator delete(void* p) noexcept { std::free(p); }
void operator delete(void* p, std::size_t) noexcept { std::free(p); }
void operator delete[](void* p) noexcept { std::free(p); }
void operator delete[](void* p, std::size_t) noexcept { std::free(p); }
void operator delete(void* p, std::align_val_t) noexcept { std::free(p); }
void operator delete(void* p, std::size_t, std::align_val_t) noexcept { std::free(p); }

using namespace agv;

TEST(SteadyStateLoop, NoHeapAllocationAfterWarmUp) {
  config::Config cfg;
  cfg.can.odometry_mode = agv::protocol::OdometryMode::kTwist;
  const protocol::ProtocolConfig pc = config::protocol_config(cfg);
  test::StaticBus bus;
  test::CoreHarness out(cfg, &bus);

  // Motor-controller odometry frames, encoded with the same protocol (twist mode, E2E).
  std::uint8_t counter = 0;
  auto odom_frame = [&](std::int64_t t_ns, double v, double w) {
    agv::hal::CanFrame f;
    protocol::encode_odometry(pc, v, w, counter, &f);
    counter = static_cast<std::uint8_t>((counter + 1) % 15);
    f.t_ns = t_ns;
    return f;
  };

  vision::LandmarkFix fix;
  fix.status = vision::FixStatus::kOk;
  fix.landmark_id = 7;
  fix.cov_world = Eigen::Matrix3d::Identity() * 0.01;
  fix.cov_world(2, 2) = 1e-6;

  const std::int64_t period = 10'000'000;
  std::int64_t t = 1'000'000'000;
  auto run_ticks = [&](int n) {
    for (int i = 0; i < n; ++i) {
      t += period;
      bus.inject(odom_frame(t - 1'000'000, 1.0, 0.0));
      out.poll_can();
      if (i % 30 == 0) {
        const double x_mm = static_cast<double>(t - 1'000'000'000) * 1e-6;  // 1 m/s along x
        fix.vehicle_in_world = {x_mm - 5.0, 0.0, 0.0};
        // Through the vision -> output hand-off and the fix-triggered pose (pose_on_fix).
        ASSERT_TRUE(out.fix_arrives(fix, t - 5'000'000, t - 500'000));
      }
      app::TickRecord rec;
      out.tick(t, &rec);
      if (bus.sent_n > 3000) bus.clear_sent();
      if (bus.rx_n > 3000) bus.rx_n = bus.rx_head = 0;
    }
  };
  run_ticks(300);  // warm-up: filter initialised, history ring filled
  ASSERT_TRUE(out.ekf().initialised());
  ASSERT_GT(out.stats().fixes_fused, 5u);
  g_allocs = 0;
  g_counting = true;
  run_ticks(1000);
  g_counting = false;
  EXPECT_EQ(g_allocs.load(), 0) << "heap allocations in 1000 steady-state periods";
  EXPECT_GT(out.stats().fixes_fused, 35u);
  EXPECT_GT(out.stats().fix_poses, 35u);
  EXPECT_EQ(out.odometry_decoder().counters().rejected(), 0u);
}

TEST(SteadyStateLoop, CounterDetectsAllocation) {
  // The harness itself must be able to fail.
  g_allocs = 0;
  g_counting = true;
  auto* p = new int(3);
  g_counting = false;
  delete p;
  EXPECT_EQ(g_allocs.load(), 1);
}
