// The output loop hands each period's frames to the bus in one batch (one sendmmsg on SocketCAN),
// so a preemption of the loop cannot separate the pose's position from its heading.
#include <gtest/gtest.h>

#include <cstddef>
#include <cstdint>
#include <vector>

#include "agv/adapters/stepped_clock.hpp"
#include "agv/can/fake_can.hpp"
#include "output_loop.hpp"

namespace agv {
namespace {

constexpr std::int64_t kMs = 1'000'000;

TEST(OutputBatch, EachPeriodsFramesLeaveInOneBatch) {
  config::Config cfg;
  localizer::Localizer core(app::localizer_config(cfg));
  can::FakeCanNetwork net;
  auto ours = net.create_endpoint(256);
  auto controller = net.create_endpoint(4096);
  adapters::SteppedClock clock(1000 * kMs);
  app::FixRing fixes;
  app::OutputLoop loop(core, ours.get(), clock, nullptr, fixes, 0);
  app::CameraState camera;
  std::vector<std::size_t> wire_after;  // frames on the wire after each tick
  for (int i = 0; i < 50; ++i) {
    const std::int64_t t = (1000 + 10 * i) * kMs;
    net.set_time_ns(t);
    clock.sleep_until_ns(t);
    camera.last_frame_ns = t;
    const std::size_t batches_before = ours->batch_sizes().size();
    loop.tick(t, camera, nullptr);
    const std::size_t batches = ours->batch_sizes().size() - batches_before;
    const std::size_t sent = net.wire_log().size() - (wire_after.empty() ? 0 : wire_after.back());
    wire_after.push_back(net.wire_log().size());
    // At most one hand-over per tick, and every frame on the wire came in it.
    ASSERT_LE(batches, 1u) << "tick " << i;
    EXPECT_EQ(sent, batches ? ours->batch_sizes().back() : 0u) << "tick " << i;
  }
  ASSERT_FALSE(ours->batch_sizes().empty());
  std::size_t largest = 0;
  for (const std::size_t n : ours->batch_sizes()) largest = std::max(largest, n);
  // The pose pair at least: position and heading together.
  EXPECT_GE(largest, 2u);
  EXPECT_EQ(core.stats().can_tx_ok, net.wire_log().size());
  EXPECT_EQ(core.stats().can_tx_failed, 0u);
}

// A frame refused in a batch is counted failed; the others still leave.
TEST(OutputBatch, ARefusedFrameInABatchIsCountedAndTheOthersLeave) {
  can::FakeCanNetwork net;
  auto ep = net.create_endpoint();
  hal::CanFrame f[3] = {};
  f[0].id = 0x100;
  f[1].id = 0x800;  // beyond 11 bits: invalid
  f[2].id = 0x101;
  hal::CanStatus st[3];
  EXPECT_EQ(ep->send_batch(f, 3, st), 2u);
  EXPECT_EQ(st[0], hal::CanStatus::kOk);
  EXPECT_EQ(st[1], hal::CanStatus::kInvalidArgument);
  EXPECT_EQ(st[2], hal::CanStatus::kOk);
  ASSERT_EQ(net.wire_log().size(), 2u);
  EXPECT_EQ(net.wire_log()[1].id, 0x101u);
  EXPECT_EQ(ep->batch_sizes(), std::vector<std::size_t>{3});
}

}  // namespace
}  // namespace agv
