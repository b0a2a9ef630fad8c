// Proves the steady-state output loop (CAN odometry in, fixes in, fusion, CAN out every period,
// fix-triggered poses) does not touch the heap once warmed up (tests/support/alloc_counter.cpp
// counts every allocation of this binary).
#include <gtest/gtest.h>

#include <atomic>
#include <cstdlib>
#include <new>

#include "../support/alloc_counter.hpp"
#include "agv/protocol/codec.hpp"
#include "config.hpp"
#include "test_loop_support.hpp"


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
  const long before = agv::test::allocations();
  run_ticks(1000);
  EXPECT_EQ(agv::test::allocations() - before, 0) << "heap allocations in 1000 steady-state periods";
  EXPECT_GT(out.stats().fixes_fused, 35u);
  EXPECT_GT(out.stats().fix_poses, 35u);
  EXPECT_EQ(out.odometry_decoder().counters().rejected(), 0u);
}

TEST(SteadyStateLoop, CounterDetectsAllocation) {
  // The harness itself must be able to fail.
  const long before = agv::test::allocations();
  auto* p = new int(3);
  const long after = agv::test::allocations();
  delete p;
  EXPECT_EQ(after - before, 1);
}
