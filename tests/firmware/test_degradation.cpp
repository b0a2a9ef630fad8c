// Degradation, never silence: camera stall, odometry loss, CAN send failure and garbage on the
// bus, driven through fake drivers, checked on the frames the localizer actually sends.
#include <gtest/gtest.h>

#include <vector>

#include "../support/good_fix.hpp"
#include "agv/fakecamera/fake_camera.hpp"
#include "agv/posix/posix_clock.hpp"
#include "agv/protocol/codec.hpp"
#include "config.hpp"
#include "pipeline.hpp"
#include "test_loop_support.hpp"
#include "threaded_run_support.hpp"

using namespace agv;
namespace p = agv::protocol;

namespace {

config::Config test_config() {
  config::Config cfg;
  cfg.can.odometry_mode = agv::protocol::OdometryMode::kTwist;
  cfg.fusion.health.odom_timeout_ns = 100'000'000;
  return cfg;
}

// The last status frame the bus carried.
bool last_status(const config::Config& cfg, const test::StaticBus& bus, p::StatusOut* st) {
  const p::ProtocolConfig pc = config::protocol_config(cfg);
  for (std::size_t i = bus.sent_n; i-- > 0;) {
    const agv::hal::CanFrame f = bus.sent[i];
    if (p::identify(pc, f) == p::Msg::kStatus) return p::decode_status(pc, f, st);
  }
  return false;
}

bool last_pose_valid(const config::Config& cfg, const test::StaticBus& bus) {
  const p::ProtocolConfig pc = config::protocol_config(cfg);
  for (std::size_t i = bus.sent_n; i-- > 1;) {
    const agv::hal::CanFrame b = bus.sent[i];
    if (p::identify(pc, b) != p::Msg::kPoseHeading) continue;
    p::PoseOut pose;
    EXPECT_TRUE(p::decode_pose(pc, bus.sent[i - 1], b, &pose));
    return pose.valid;
  }
  ADD_FAILURE() << "no pose frame sent";
  return false;
}

hal::CanFrame odom(const config::Config& cfg, std::int64_t t_ns, double v, std::uint8_t counter,
                   bool corrupt = false) {
  agv::hal::CanFrame f;
  p::encode_odometry(config::protocol_config(cfg), v, 0.0, counter, &f);
  if (corrupt) f.data[3] ^= 0x10;
  f.t_ns = t_ns;
  return f;
}

// The core and its output step on the test configuration, ticked every 10 ms from t = 1 s, each
// tick after CAN odometry at 0.5 m/s stamped odom_lag_ns before it.
struct OdomTicks {
  explicit OdomTicks(std::int64_t lag_ns = 0) : odom_lag_ns(lag_ns) {}
  const config::Config cfg = test_config();
  test::StaticBus bus;
  test::CoreHarness out{cfg, &bus};
  std::int64_t odom_lag_ns;
  std::int64_t t = 1'000'000'000;
  std::uint8_t c = 0;

  void tick(bool with_odom = true) {
    t += 10'000'000;
    if (with_odom) bus.inject(odom(cfg, t - odom_lag_ns, 0.5, c++ % 15));
    out.poll_can();
    out.tick(t, nullptr);
  }
};

}  // namespace

TEST(Degradation, OdometryLossFlagsAndInvalidatesThePoseThenRecovers) {
  OdomTicks d(1'000'000);
  for (int i = 0; i < 20; ++i) d.tick();
  const std::int64_t t_fix0 = d.t;
  d.out.on_fix(test::good_fix(0.0, 3), d.t);
  for (int i = 0; i < 20; ++i) d.tick();
  p::StatusOut st;
  ASSERT_TRUE(last_status(d.cfg, d.bus, &st));
  EXPECT_EQ(st.faults & p::fault::kOdomTimeout, 0);
  EXPECT_TRUE(last_pose_valid(d.cfg, d.bus));
  EXPECT_EQ(st.health, p::Health::kOk);

  for (int i = 0; i < 15; ++i) d.tick(false);  // 150 ms without odometry > 100 ms timeout
  ASSERT_TRUE(last_status(d.cfg, d.bus, &st));
  EXPECT_NE(st.faults & p::fault::kOdomTimeout, 0);
  EXPECT_FALSE(last_pose_valid(d.cfg, d.bus));

  for (int i = 0; i < 5; ++i) d.tick();  // resumes (counter jump re-synchronises)
  ASSERT_TRUE(last_status(d.cfg, d.bus, &st));
  EXPECT_EQ(st.faults & p::fault::kOdomTimeout, 0);
  // What the vehicle did in the gap is unknown (it may have turned): the pose is valid again
  // once the covariance says so, at the latest with the next landmark (0.5 m/s along x).
  d.out.on_fix(test::good_fix(0.5e-6 * static_cast<double>(d.t - t_fix0), 3), d.t);
  for (int i = 0; i < 5; ++i) d.tick();
  ASSERT_TRUE(last_status(d.cfg, d.bus, &st));
  EXPECT_EQ(st.faults & p::fault::kOdomTimeout, 0);
  EXPECT_TRUE(last_pose_valid(d.cfg, d.bus));
  EXPECT_EQ(st.health, p::Health::kOk);
}

TEST(Degradation, GarbageOdometryFramesAreRejectedCountedAndFlagged) {
  OdomTicks d;
  for (int i = 0; i < 10; ++i) d.tick();
  const std::int64_t t = d.t + 10'000'000;
  const std::uint8_t c = d.c;
  d.bus.inject(odom(d.cfg, t, 3.0, c % 15, /*corrupt=*/true));
  hal::CanFrame short_frame = odom(d.cfg, t, 0.5, c % 15);
  short_frame.len = 5;
  d.bus.inject(short_frame);
  d.out.poll_can();
  d.out.tick(t, nullptr);
  EXPECT_EQ(d.out.odometry_decoder().counters().bad_crc, 1u);
  EXPECT_EQ(d.out.odometry_decoder().counters().bad_length, 1u);
  EXPECT_EQ(d.out.stats().odom_samples, 10u);  // neither reached fusion
  p::StatusOut st;
  ASSERT_TRUE(last_status(d.cfg, d.bus, &st));
  EXPECT_NE(st.faults & p::fault::kOdomE2E, 0);
}

TEST(Degradation, CanSendFailureIsCountedAndTheLoopKeepsRunning) {
  const config::Config cfg = test_config();
  test::StaticBus bus;
  test::CoreHarness out(cfg, &bus);
  std::int64_t t = 1'000'000'000;
  bus.fail_sends = true;
  for (int i = 0; i < 50; ++i) out.tick(t += 10'000'000, nullptr);
  EXPECT_EQ(out.stats().ticks, 50u);
  EXPECT_GE(out.stats().can_tx_failed, 250u);  // 5 frames per period, heartbeat extra
  EXPECT_EQ(out.stats().can_tx_ok, 0u);
  bus.fail_sends = false;
  out.tick(t += 10'000'000, nullptr);
  EXPECT_GE(out.stats().can_tx_ok, 5u);
  p::StatusOut st;
  ASSERT_TRUE(last_status(cfg, bus, &st));
}

TEST(Degradation, BusOffIsReportedInTheStatusFrame) {
  const config::Config cfg = test_config();
  test::StaticBus bus;
  test::CoreHarness out(cfg, &bus);
  bus.bus_state = hal::CanBusState::kErrorPassive;
  out.tick(1'000'000'000, nullptr);
  p::StatusOut st;
  ASSERT_TRUE(last_status(cfg, bus, &st));
  EXPECT_NE(st.faults & p::fault::kCanErrorPassive, 0);
}

TEST(Degradation, CameraStallIsFlaggedWhileTheLoopKeepsRunning) {
  // Real threads and clock: frames for 0.3 s, a 0.8 s stall, frames again, end of stream.
  config::Config cfg = test_config();
  cfg.camera.timeout_ms = 200.0;
  cfg.loop.log_period_s = 0.0;
  posix::PosixClock clock;
  fakecamera::FakeCamera cam(test::scripted_camera(&clock));
  const std::int64_t t0 = clock.now_ns() + 50'000'000;
  std::int64_t t = t0;
  for (int i = 0; i < 9; ++i)
    cam.push_frame(fakecamera::FakeCamera::solid(64, 48, 128), t += 33'000'000);
  cam.push_stall(800'000'000);
  for (int i = 0; i < 9; ++i)
    cam.push_frame(fakecamera::FakeCamera::solid(64, 48, 128), t + 800'000'000 + 33'000'000 * i);
  cam.push_end_of_stream();
  const std::vector<recording::OdomRow> odo =
      test::straight_odometry(t0 - 100'000'000, t0 + 2'000'000'000, 0.2);
  test::StaticBus bus;
  std::vector<app::TickRecord> ticks;
  ticks.reserve(1000);
  app::PipelineIo io = test::quiet_io(&cam, &bus, &clock, &odo);
  io.ticks = &ticks;
  app::RunResult r;
  ASSERT_EQ(app::run_threads(cfg, nullptr, io, &r), 0);
  int stalled = 0, not_stalled_before = 0;
  for (const auto& tr : ticks) {
    const bool s = tr.status.faults & p::fault::kCameraStalled;
    if (s) ++stalled;
    if (!s && stalled == 0) ++not_stalled_before;
  }
  EXPECT_GT(not_stalled_before, 10);
  EXPECT_GT(stalled, 30);  // ~0.6 s of 10 ms periods flagged (0.8 s stall - 0.2 s timeout)
  EXPECT_LT(stalled, 80);
  EXPECT_EQ(r.vision.frames_processed + r.frames_dropped_mailbox, 18u);
  EXPECT_GT(r.output.ticks, 100u);
}

TEST(OutputLoop, PoseOnFixSendsThePoseWithoutWaitingForThePeriod) {
  const config::Config cfg = test_config();
  test::StaticBus bus;
  test::CoreHarness out(cfg, &bus);
  std::int64_t t = 1'000'000'000;
  for (int i = 0; i < 10; ++i) {
    out.on_odometry(t += 10'000'000, 0.5, 0.0);
    out.tick(t, nullptr);
  }
  const std::size_t before = bus.sent_n;
  out.on_odometry(t + 2'000'000, 0.5, 0.0);
  ASSERT_TRUE(out.fix_arrives(test::good_fix(0.0, 3), t + 1'000'000, t + 3'000'000));
  ASSERT_EQ(bus.sent_n, before + 2);  // exactly the pose pair
  EXPECT_EQ(out.stats().fix_poses, 1u);
  // A failed fix wakes nothing and sends nothing.
  vision::LandmarkFix bad = test::good_fix(0.0, 3);
  bad.status = vision::FixStatus::kQrUnreadable;
  EXPECT_FALSE(out.fix_arrives(bad, t + 4'000'000, t + 5'000'000));
  EXPECT_EQ(bus.sent_n, before + 2);
  EXPECT_TRUE(last_pose_valid(cfg, bus));
  ASSERT_EQ(out.stats().end_to_end_ns.count(), 1u);
  EXPECT_EQ(out.stats().end_to_end_ns.max_ns(), 2'000'000);  // exposure -> send
}

TEST(Degradation, FixExposedAfterItArrivedIsRejectedNotFused) {
  // A camera clock that jumped ahead stamps frames in the future of the loop's clock.
  OdomTicks d;
  for (int i = 0; i < 10; ++i) d.tick();
  const std::int64_t t = d.t;
  d.out.on_fix(test::good_fix(0.0, 3), t + 5'000'000, t);
  EXPECT_EQ(d.out.stats().fixes_rejected_invalid, 1u);
  EXPECT_EQ(d.out.stats().fixes_fused, 0u);
  EXPECT_FALSE(d.out.ekf().initialised());
  d.out.on_fix(test::good_fix(0.0, 3), t - 5'000'000, t);
  EXPECT_EQ(d.out.stats().fixes_fused, 1u);
}
