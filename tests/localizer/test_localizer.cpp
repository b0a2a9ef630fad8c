// The pure localizer core (algo/localizer): inputs and a time in, the transport-neutral record
// out, encoded to frames by CanOutput. No bus, no clock: every test drives it with plain values.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <vector>

#include "agv/localizer/can_output.hpp"
#include "agv/localizer/fault_transitions.hpp"
#include "agv/localizer/localizer.hpp"
#include "localizer_test_support.hpp"

using namespace agv;
namespace p = agv::protocol;

using localizer_test::good_fix;
using localizer_test::kMs;
using localizer_test::test_config;

namespace {

p::Msg msg_of(const localizer::LocalizerConfig& c, const hal::CanFrame& f) {
  return p::identify(c.protocol, f);
}

// A localizer and its CAN output on one configuration, and the time the tests drive them from.
struct Rig {
  explicit Rig(localizer::LocalizerConfig config = test_config())
      : c(std::move(config)), loc(c), can(c.protocol) {}
  localizer::LocalizerConfig c;
  localizer::Localizer loc;
  localizer::CanOutput can;
  localizer::OutFrames out;
  std::int64_t t = 1000 * kMs;
};

// The first frame of `kind` in a tick's output, decoded.
template <typename Out, typename Decode>
Out decoded(const localizer::LocalizerConfig& c, const localizer::OutFrames& out, p::Msg kind,
            Decode decode) {
  Out v;
  for (int i = 0; i < out.n; ++i) {
    if (p::identify(c.protocol, out.frame[i]) == kind) {
      EXPECT_TRUE(decode(c.protocol, out.frame[i], &v));
      return v;
    }
  }
  ADD_FAILURE() << "no frame of kind " << static_cast<int>(kind);
  return v;
}

p::StatusOut status_of(const localizer::LocalizerConfig& c, const localizer::OutFrames& out) {
  return decoded<p::StatusOut>(c, out, p::Msg::kStatus,
                               [](auto&&... a) { return p::decode_status(a...); });
}

bool pose_valid(const localizer::LocalizerConfig& c, const localizer::OutFrames& out) {
  p::PoseOut pose;
  EXPECT_TRUE(p::decode_pose(c.protocol, out.frame[0], out.frame[1], &pose));
  return pose.valid;
}

}  // namespace

TEST(Localizer, TickProducesThePosePairFirstAndTheHeartbeatWhenDue) {
  Rig r;
  auto& [c, loc, can, out, t] = r;
  can.tick(loc, 1000 * kMs, &out, nullptr);
  ASSERT_EQ(out.n, 6);
  const p::Msg order[] = {p::Msg::kPoseXY,  p::Msg::kPoseHeading, p::Msg::kVelocity,
                          p::Msg::kQuality, p::Msg::kStatus,      p::Msg::kHeartbeat};
  for (int i = 0; i < 6; ++i) EXPECT_EQ(msg_of(c, out.frame[i]), order[i]) << i;
  can.tick(loc, 1010 * kMs, &out, nullptr);
  EXPECT_EQ(out.n, 5);  // heartbeat once per heartbeat period
  can.tick(loc, 2000 * kMs, &out, nullptr);
  EXPECT_EQ(out.n, 6);
  localizer::OutFrames pose;
  can.pose_now(loc, 2005 * kMs, &pose);
  EXPECT_EQ(pose.n, 2);
  EXPECT_EQ(msg_of(c, pose.frame[0]), p::Msg::kPoseXY);
  EXPECT_EQ(loc.stats().fix_poses, 1u);
}

TEST(Localizer, OneOdometryTimeoutDrivesPoseValidityAndTheEkfFlag) {
  Rig r;
  auto& [c, loc, can, out, t] = r;
  localizer::TickRecord rec;
  for (int i = 0; i < 10; ++i) {
    loc.on_odometry(t, 0.5, 0.0);
    can.tick(loc, t += 10 * kMs, &out, &rec);
  }
  loc.on_fix(good_fix(0.0), t - 5 * kMs, t);
  loc.on_odometry(t, 0.5, 0.0);
  can.tick(loc, t += 10 * kMs, &out, &rec);
  EXPECT_TRUE(pose_valid(c, out));
  EXPECT_EQ(status_of(c, out).faults & p::fault::kOdomTimeout, 0);
  // 40 ms without odometry: within the 50 ms timeout.
  can.tick(loc, t += 30 * kMs, &out, &rec);
  EXPECT_TRUE(pose_valid(c, out));
  // 60 ms: the pose is invalid, the status flags it, and the EKF says so too (not at 10 s).
  can.tick(loc, t += 20 * kMs, &out, &rec);
  EXPECT_FALSE(pose_valid(c, out));
  EXPECT_NE(status_of(c, out).faults & p::fault::kOdomTimeout, 0);
  EXPECT_NE(rec.estimate.flags & fusion::flags::kOdomTimeout, 0);
  EXPECT_TRUE(loc.odometry_timed_out(t));
}

TEST(Localizer, FusedFixIsCarriedByTheNextPosePairOnlyForEndToEndLatency) {
  Rig r;
  auto& [c, loc, can, out, t] = r;
  for (int i = 0; i < 5; ++i) {
    loc.on_odometry(t, 0.5, 0.0);
    can.tick(loc, t += 10 * kMs, &out, nullptr);
    EXPECT_EQ(out.e2e_exposure_ns, INT64_MIN);
  }
  loc.on_odometry(t, 0.5, 0.0);
  loc.on_fix(good_fix(0.0), t - 3 * kMs, t);
  EXPECT_EQ(loc.stats().fixes_fused, 1u);
  can.pose_now(loc, t + 1 * kMs, &out);
  EXPECT_EQ(out.e2e_exposure_ns, t - 3 * kMs);
  can.tick(loc, t += 10 * kMs, &out, nullptr);
  EXPECT_EQ(out.e2e_exposure_ns, INT64_MIN);  // already sent with the fix-triggered pose
}

// A fix on tag36h11's tag 0: the status says "a landmark, id 0", not "none yet", by
// LastLandmarkValid, which stays 1 from the first accepted fix on.
TEST(Localizer, StatusTellsAFixOnLandmarkZeroFromNoFixYet) {
  Rig r;
  auto& [c, loc, can, out, t] = r;
  loc.on_odometry(t, 0.5, 0.0);
  can.tick(loc, t += 10 * kMs, &out, nullptr);
  p::StatusOut st = status_of(c, out);
  EXPECT_FALSE(st.last_landmark_valid);
  EXPECT_EQ(st.last_landmark_id, 0);
  vision::LandmarkFix tag0 = good_fix(0.0);
  tag0.landmark_id = 0;
  loc.on_odometry(t, 0.5, 0.0);
  loc.on_fix(tag0, t - 3 * kMs, t);
  ASSERT_EQ(loc.stats().fixes_fused, 1u);
  can.tick(loc, t += 10 * kMs, &out, nullptr);
  st = status_of(c, out);
  EXPECT_TRUE(st.last_landmark_valid);
  EXPECT_EQ(st.last_landmark_id, 0);
  for (int i = 0; i < 5; ++i) {  // no further fix: still valid, still landmark 0
    loc.on_odometry(t, 0.5, 0.0);
    can.tick(loc, t += 10 * kMs, &out, nullptr);
  }
  st = status_of(c, out);
  EXPECT_TRUE(st.last_landmark_valid);
  EXPECT_EQ(st.last_landmark_id, 0);
}

TEST(Localizer, CanFaultsAreLatchedFromTheBusStateItIsGiven) {
  Rig r;
  auto& [c, loc, can, out, t] = r;
  can.tick(loc, 1000 * kMs, &out, nullptr);
  EXPECT_EQ(status_of(c, out).faults & (p::fault::kCanBusOff | p::fault::kCanErrorPassive), 0);
  hal::CanStats s;
  s.bus_off_count = 1;
  s.restarts = 1;  // went bus-off and came back between two status frames
  loc.set_can_state(hal::CanBusState::kErrorActive, s);
  can.tick(loc, 1010 * kMs, &out, nullptr);
  EXPECT_NE(status_of(c, out).faults & p::fault::kCanBusOff, 0);
  can.tick(loc, 1020 * kMs, &out, nullptr);  // latched once, then clear
  EXPECT_EQ(status_of(c, out).faults & p::fault::kCanBusOff, 0);
  loc.set_can_state(hal::CanBusState::kErrorPassive, s);
  can.tick(loc, 1030 * kMs, &out, nullptr);
  EXPECT_NE(status_of(c, out).faults & p::fault::kCanErrorPassive, 0);
}

TEST(Localizer, CameraStallNeedsTheTimeoutAndNotTheEndOfTheStream) {
  Rig r;
  auto& [c, loc, can, out, t] = r;
  loc.set_camera_state(1000 * kMs, false, false);
  can.tick(loc, 1200 * kMs, &out, nullptr);
  EXPECT_EQ(status_of(c, out).faults & p::fault::kCameraStalled, 0);
  can.tick(loc, 1201 * kMs, &out, nullptr);
  EXPECT_NE(status_of(c, out).faults & p::fault::kCameraStalled, 0);
  loc.set_camera_state(1000 * kMs, true, false);  // replay ran out of frames: not a stall
  can.tick(loc, 1300 * kMs, &out, nullptr);
  EXPECT_EQ(status_of(c, out).faults & p::fault::kCameraStalled, 0);
  loc.set_camera_state(1000 * kMs, false, true);
  can.tick(loc, 1310 * kMs, &out, nullptr);
  EXPECT_NE(status_of(c, out).faults & p::fault::kCameraError, 0);
}

TEST(Localizer, ReceivedFramesAreDecodedAsOdometryOrCounted) {
  const auto c = test_config();
  localizer::Localizer loc(c);
  hal::CanFrame f;
  p::encode_odometry(c.protocol, 0.5, 0.5, 0, &f);
  f.t_ns = 1000 * kMs;
  p::OdomSample s;
  EXPECT_TRUE(loc.on_can_frame(f, &s));
  EXPECT_EQ(s.t_ns, f.t_ns);
  EXPECT_DOUBLE_EQ(s.v_mps, 0.5);
  EXPECT_DOUBLE_EQ(s.omega_radps, 0.0);  // test_config: wheel speeds, both 0.5 m/s
  hal::CanFrame other;
  other.id = 0x123;
  other.len = 8;
  EXPECT_FALSE(loc.on_can_frame(other, &s));
  EXPECT_EQ(loc.stats().can_rx_frames, 2u);
  EXPECT_EQ(loc.stats().can_rx_other, 1u);
  EXPECT_EQ(loc.stats().odom_samples, 1u);
  hal::CanFilter filt[2];
  ASSERT_EQ(loc.receive_filters(filt, 2), 1);  // gyro not enabled: odometry only
  EXPECT_EQ(filt[0].id, loc.odometry_decoder().can_id());
  EXPECT_EQ(filt[0].mask, p::kCanStdIdMask);
  EXPECT_FALSE(filt[0].extended);
}

// --- Gyro over CAN (AGV_Gyro, protocol::GyroDecoder, can.gyro.*) ---

namespace {

localizer::LocalizerConfig gyro_config() {
  auto c = test_config();
  c.protocol.gyro.enabled = true;
  c.gyro_timeout_ns = 50 * kMs;
  return c;
}

hal::CanFrame gyro_can(const localizer::LocalizerConfig& c, double z, int counter,
                       std::int64_t t_ns, bool saturated = false) {
  p::GyroSample g;
  g.gyro_z_radps = z;
  g.saturated = saturated;
  hal::CanFrame f;
  p::encode_gyro(c.protocol, g, static_cast<std::uint8_t>(counter % 15), &f);
  f.t_ns = t_ns;
  return f;
}

hal::CanFrame odom_can(const localizer::LocalizerConfig& c, int counter, std::int64_t t_ns) {
  hal::CanFrame f;
  p::encode_odometry(c.protocol, 0.5, 0.5, static_cast<std::uint8_t>(counter % 15), &f);
  f.t_ns = t_ns;
  return f;
}

}  // namespace

TEST(Localizer, CanFramesAreDispatchedByIdToOdometryAndGyro) {
  const auto c = gyro_config();
  localizer::Localizer loc(c);
  p::OdomSample o;
  p::GyroSample g;
  EXPECT_EQ(loc.on_can_frame(odom_can(c, 0, 1000 * kMs), &o, &g), localizer::CanRx::kOdometry);
  EXPECT_EQ(o.t_ns, 1000 * kMs);
  EXPECT_EQ(loc.stats().odom_samples, 1u);
  EXPECT_EQ(loc.on_can_frame(gyro_can(c, 0.25, 0, 1001 * kMs), &o, &g), localizer::CanRx::kGyro);
  EXPECT_EQ(g.t_ns, 1001 * kMs);
  EXPECT_NEAR(g.gyro_z_radps, 0.25, 1e-5);
  EXPECT_EQ(loc.stats().gyro_samples, 1u);  // reached on_gyro
  EXPECT_EQ(loc.stats().odom_samples, 1u);
  // The two-argument form: true for odometry only, but a gyro frame still reaches on_gyro.
  EXPECT_FALSE(loc.on_can_frame(gyro_can(c, 0.25, 1, 1002 * kMs), &o));
  EXPECT_EQ(loc.stats().gyro_samples, 2u);
  EXPECT_TRUE(loc.on_can_frame(odom_can(c, 1, 1010 * kMs), &o));
  EXPECT_EQ(loc.stats().odom_samples, 2u);
  // Other IDs, and the inactive odometry variant, are counted as other.
  hal::CanFrame other;
  other.id = 0x123;
  other.len = 8;
  EXPECT_EQ(loc.on_can_frame(other, &o, &g), localizer::CanRx::kOther);
  other.id = p::can_id_of(c.protocol, p::Msg::kOdomTwist);  // test_config: wheels mode
  EXPECT_EQ(loc.on_can_frame(other, &o, &g), localizer::CanRx::kOther);
  EXPECT_EQ(loc.stats().can_rx_frames, 6u);
  EXPECT_EQ(loc.stats().can_rx_other, 2u);
  EXPECT_EQ(loc.gyro_decoder().counters().accepted, 2u);
}

TEST(Localizer, GyroFramesAreOtherFramesUnlessEnabled) {
  const auto c = test_config();  // gyro not enabled
  localizer::Localizer loc(c);
  localizer::CanOutput can(c.protocol);
  p::GyroSample g;
  EXPECT_EQ(loc.on_can_frame(gyro_can(c, 0.25, 0, 1000 * kMs), nullptr, &g),
            localizer::CanRx::kOther);
  EXPECT_EQ(loc.stats().gyro_samples, 0u);
  EXPECT_EQ(loc.stats().can_rx_other, 1u);
  // Never received: no gyro fault whatever the time.
  localizer::OutFrames out;
  can.tick(loc, 1000 * kMs, &out, nullptr);
  can.tick(loc, 5000 * kMs, &out, nullptr);
  EXPECT_EQ(status_of(c, out).faults & (p::fault::kImuTimeout | p::fault::kImuE2E), 0);
}

TEST(Localizer, SaturatedGyroSamplesAreCountedNotFused) {
  const auto c = gyro_config();
  localizer::Localizer loc(c);
  p::GyroSample g;
  EXPECT_EQ(loc.on_can_frame(gyro_can(c, 5.0, 0, 1000 * kMs, true), nullptr, &g),
            localizer::CanRx::kGyroSaturated);
  EXPECT_TRUE(g.saturated);
  EXPECT_EQ(loc.stats().gyro_saturated, 1u);
  EXPECT_EQ(loc.stats().gyro_samples, 0u);  // on_gyro not called
  EXPECT_EQ(loc.gyro_decoder().counters().saturated, 1u);
  EXPECT_EQ(loc.on_can_frame(gyro_can(c, 0.1, 1, 1010 * kMs), nullptr, &g),
            localizer::CanRx::kGyro);
  EXPECT_EQ(loc.stats().gyro_samples, 1u);
}

TEST(Localizer, RejectedGyroFramesSetImuE2EForOneStatusFrame) {
  Rig r(gyro_config());
  auto& [c, loc, can, out, t] = r;
  loc.on_can_frame(odom_can(c, 0, t));
  ASSERT_EQ(loc.on_can_frame(gyro_can(c, 0.1, 0, t), nullptr, nullptr), localizer::CanRx::kGyro);
  can.tick(loc, t += 10 * kMs, &out, nullptr);
  EXPECT_EQ(status_of(c, out).faults & p::fault::kImuE2E, 0);
  hal::CanFrame bad = gyro_can(c, 0.1, 1, t);
  bad.data[3] ^= 0x10;
  EXPECT_EQ(loc.on_can_frame(bad, nullptr, nullptr), localizer::CanRx::kRejected);
  EXPECT_EQ(loc.stats().gyro_samples, 1u);
  EXPECT_EQ(loc.gyro_decoder().counters().bad_crc, 1u);
  loc.on_can_frame(odom_can(c, 1, t));
  can.tick(loc, t += 10 * kMs, &out, nullptr);
  const auto faults = status_of(c, out).faults;
  EXPECT_NE(faults & p::fault::kImuE2E, 0);
  EXPECT_EQ(faults & p::fault::kOdomE2E, 0);  // the odometry's flag is its own
  loc.on_can_frame(odom_can(c, 2, t));
  can.tick(loc, t += 10 * kMs, &out, nullptr);
  EXPECT_EQ(status_of(c, out).faults & p::fault::kImuE2E, 0);  // an event flag: latched once
}

TEST(Localizer, ImuTimeoutIsSetAfterTheGyroTimeoutAndClearWhileSamplesArrive) {
  Rig r(gyro_config());  // gyro timeout 50 ms
  auto& [c, loc, can, out, t] = r;
  int oc = 0, gc = 0;
  // Enabled but silent since the first tick: flagged once the timeout has passed.
  loc.on_can_frame(odom_can(c, oc++, t));
  can.tick(loc, t, &out, nullptr);
  EXPECT_EQ(status_of(c, out).faults & p::fault::kImuTimeout, 0);
  for (int i = 0; i < 6; ++i) {
    t += 10 * kMs;
    loc.on_can_frame(odom_can(c, oc++, t));
    can.tick(loc, t, &out, nullptr);
  }
  EXPECT_NE(status_of(c, out).faults & p::fault::kImuTimeout, 0);  // 60 ms, none yet
  // Samples arriving every 10 ms: clear.
  for (int i = 0; i < 20; ++i) {
    t += 10 * kMs;
    loc.on_can_frame(odom_can(c, oc++, t));
    ASSERT_EQ(loc.on_can_frame(gyro_can(c, 0.05, gc++, t - 2 * kMs), nullptr, nullptr),
              localizer::CanRx::kGyro);
    can.tick(loc, t, &out, nullptr);
    EXPECT_EQ(status_of(c, out).faults & p::fault::kImuTimeout, 0) << i;
  }
  const std::int64_t last_gyro = t - 2 * kMs;
  // The gyro stops, the odometry goes on: clear up to the timeout, set after it.
  for (int i = 0; i < 10; ++i) {
    t += 10 * kMs;
    loc.on_can_frame(odom_can(c, oc++, t));
    can.tick(loc, t, &out, nullptr);
    const bool expect = t - last_gyro > 50 * kMs;
    EXPECT_EQ((status_of(c, out).faults & p::fault::kImuTimeout) != 0, expect) << i;
    EXPECT_EQ(loc.gyro_timed_out(t), expect) << i;
  }
  // Only saturated samples: still no usable gyro, the fault stays.
  t += 10 * kMs;
  loc.on_can_frame(odom_can(c, oc++, t));
  loc.on_can_frame(gyro_can(c, 9.0, gc++, t - 2 * kMs, true));
  can.tick(loc, t, &out, nullptr);
  EXPECT_NE(status_of(c, out).faults & p::fault::kImuTimeout, 0);
  // Back: clear at once.
  t += 10 * kMs;
  loc.on_can_frame(odom_can(c, oc++, t));
  loc.on_can_frame(gyro_can(c, 0.05, gc++, t - 2 * kMs));
  can.tick(loc, t, &out, nullptr);
  EXPECT_EQ(status_of(c, out).faults & p::fault::kImuTimeout, 0);
  EXPECT_EQ(status_of(c, out).faults & p::fault::kImuE2E, 0);
  EXPECT_EQ(status_of(c, out).faults & p::fault::kOdomTimeout, 0);
}

// The hand-written capacities follow the signal table: a message added to it must grow them.
TEST(Localizer, FrameCapacitiesFollowTheSignalTable) {
  int tx = 0;
  for (const p::MessageDef& m : p::message_table()) tx += m.dir == p::Direction::kTx ? 1 : 0;
  EXPECT_EQ(localizer::OutFrames::kMax, tx);
  // Every configuration of the inputs fits the receive filters the firmware reserves.
  int most = 0;
  for (const auto mode : {p::OdometryMode::kWheels, p::OdometryMode::kTwist}) {
    for (const bool gyro : {false, true}) {
      p::ProtocolConfig pc;
      pc.odometry.mode = mode;
      pc.gyro.enabled = gyro;
      const int n = localizer::receive_filters(pc, nullptr, 0);
      EXPECT_GE(n, 1);
      most = std::max(most, n);
    }
  }
  EXPECT_EQ(localizer::Localizer::kMaxReceiveFilters, most);
}

TEST(Localizer, ReceiveFiltersOnePerEnabledInput) {
  auto c = test_config();
  hal::CanFilter f[3];
  {
    localizer::Localizer loc(c);
    ASSERT_EQ(loc.receive_filters(f, 3), 1);
    EXPECT_EQ(f[0].id, 0x310u);
  }
  c.protocol.gyro.enabled = true;
  {
    localizer::Localizer loc(c);
    ASSERT_EQ(loc.receive_filters(f, 3), 2);
    EXPECT_EQ(f[0].id, 0x310u);  // table order: odometry first
    EXPECT_EQ(f[1].id, 0x312u);
    EXPECT_EQ(f[1].id, loc.gyro_decoder().can_id());
    EXPECT_EQ(f[1].mask, p::kCanStdIdMask);
    EXPECT_FALSE(f[1].extended);
    hal::CanFilter one[1];
    EXPECT_EQ(loc.receive_filters(one, 1), 2);  // needs two, wrote one
    EXPECT_EQ(one[0].id, 0x310u);
  }
  // Configured IDs and 29-bit inputs.
  c.protocol.base_id = 0x18FF1000;
  c.protocol.extended_ids = true;
  c.protocol.odometry.extended_id = true;
  c.protocol.odometry.mode = p::OdometryMode::kTwist;
  c.protocol.gyro.can_id = 0x18FF2000;
  localizer::Localizer loc(c);
  ASSERT_EQ(loc.receive_filters(f, 3), 2);
  EXPECT_EQ(f[0].id, 0x18FF1011u);
  EXPECT_EQ(f[1].id, 0x18FF2000u);
  EXPECT_EQ(f[1].mask, p::kCanExtIdMask);
  EXPECT_TRUE(f[0].extended);
  EXPECT_TRUE(f[1].extended);
}

TEST(Localizer, InvalidConfigurationThrows) {
  auto c = test_config();
  c.fusion.health.odom_timeout_ns = 0;
  EXPECT_THROW(localizer::Localizer{c}, std::invalid_argument);
  c = test_config();
  c.heartbeat_period_ns = 0;
  EXPECT_THROW(localizer::Localizer{c}, std::invalid_argument);
  c = test_config();
  c.gyro_timeout_ns = 0;
  EXPECT_THROW(localizer::Localizer{c}, std::invalid_argument);
  c = test_config();
  c.protocol.gyro.enabled = true;
  c.protocol.gyro.can_id = 0x304;  // AGV_Status
  EXPECT_THROW(localizer::Localizer{c}, std::invalid_argument);
}

// --- Configured odometry correction (keys odometry.*, localizer::OdometryCorrection) ---

namespace {

struct Sample {
  std::int64_t t_ns;
  double v, w;
};

// One fix to initialise at camera time 1000 ms, then 3 s of dead reckoning on a curved drive.
// `feed` maps the raw sample (odometry clock) to what is handed to on_odometry. Returns the
// estimate of every tick.
template <typename Feed>
std::vector<fusion::PoseEstimate> drive(const localizer::LocalizerConfig& c, std::int64_t raw_dt,
                                        Feed feed, std::int64_t fix_shift_ns = 0) {
  localizer::Localizer loc(c);
  localizer::CanOutput can(c.protocol);
  localizer::OutFrames out;
  localizer::TickRecord rec;
  std::vector<fusion::PoseEstimate> est;
  for (int i = 0; i < 320; ++i) {
    const std::int64_t t = 900 * kMs + i * 10 * kMs;  // camera clock
    const double w = 0.3 * std::sin(i * 0.02);
    const Sample s = feed(Sample{t + raw_dt, 0.5 + 0.001 * i, w});
    loc.on_odometry(s.t_ns, s.v, s.w);
    if (t == 1000 * kMs) loc.on_fix(good_fix(100.0), t + fix_shift_ns, t + fix_shift_ns + 5 * kMs);
    can.tick(loc, t + 5 * kMs, &out, &rec);
    est.push_back(rec.estimate);
  }
  return est;
}

// Equal up to rounding: the compiler may fuse s*w + b into one FMA in one place and not in the
// other (GCC does on aarch64), which changes the last bits. The effects checked below are
// millimetres, 1e-9 is far below them.
bool same(const std::vector<fusion::PoseEstimate>& a, const std::vector<fusion::PoseEstimate>& b) {
  constexpr double kTol = 1e-9;
  if (a.size() != b.size()) return false;
  for (size_t i = 0; i < a.size(); ++i) {
    if (a[i].valid != b[i].valid || std::abs(a[i].pose.x_mm - b[i].pose.x_mm) > kTol ||
        std::abs(a[i].pose.y_mm - b[i].pose.y_mm) > kTol ||
        std::abs(a[i].pose.theta_rad - b[i].pose.theta_rad) > kTol) {
      return false;
    }
  }
  return true;
}

}  // namespace

TEST(Localizer, EachOdometryCorrectionKeyChangesTheFusedInputAsStated) {
  const auto plain = test_config();
  const auto raw = [](Sample s) { return s; };
  const auto base = drive(plain, 0, raw);
  ASSERT_TRUE(base.back().valid);
  struct Case {
    const char* name;
    localizer::OdometryCorrection corr;
    std::int64_t raw_dt;            // odometry clock - camera clock in the fed samples
    std::int64_t camera_offset_ns;  // TimeBase::camera_offset_ns configured
  };
  localizer::OdometryCorrection speed, yaw, bias, curve, none, all;
  speed.speed_scale = 1.03;
  yaw.yaw_rate_scale = 0.97;
  bias.yaw_rate_bias_radps = -0.004;
  curve.yaw_per_metre_rad = 0.008;
  all = {1.03, 0.97, -0.004, 0.008};
  for (const Case& k : {Case{"speed_scale", speed, 0, 0}, Case{"yaw_rate_scale", yaw, 0, 0},
                        Case{"yaw_rate_bias", bias, 0, 0}, Case{"yaw_per_metre", curve, 0, 0},
                        Case{"camera_time_offset", none, 20 * kMs, 20 * kMs},
                        Case{"all", all, 20 * kMs, 20 * kMs}}) {
    auto c = plain;
    c.odometry = k.corr;
    c.time_base.camera_offset_ns = k.camera_offset_ns;
    // With the correction configured, raw samples give exactly what the plain localizer gives
    // when fed v' = s_v v + c q w, w' = s_w w + b + c v, with the exposure moved onto the
    // odometry's (vehicle's) clock, t' = t + offset (the output stays on the vehicle's clock) ...
    const auto corrected = drive(c, k.raw_dt, raw);
    const auto by_hand = drive(
        plain, k.raw_dt,
        [&](Sample s) {
          const double track_m = plain.fusion.slip.wheel_track_mm * 1e-3;  // the one track width
          const double q = 0.25 * track_m * track_m;
          return Sample{s.t_ns, s.v * k.corr.speed_scale + k.corr.yaw_per_metre_rad * q * s.w,
                        s.w * k.corr.yaw_rate_scale + k.corr.yaw_rate_bias_radps +
                            k.corr.yaw_per_metre_rad * s.v};
        },
        k.camera_offset_ns);
    EXPECT_TRUE(same(corrected, by_hand)) << k.name;
    // ... and not what the plain localizer makes of the raw samples.
    EXPECT_FALSE(same(corrected, drive(plain, k.raw_dt, raw))) << k.name;
  }
  // The stated size of the effect: 3 % more distance, 3 % less and then biased heading change.
  auto c = plain;
  c.odometry = speed;
  const auto sp = drive(c, 0, raw);
  const double d0 = base.back().pose.x_mm - base[10].pose.x_mm;
  EXPECT_NEAR((sp.back().pose.x_mm - sp[10].pose.x_mm) / d0, 1.03, 2e-3);
  c.odometry = yaw;
  const double h0 = base.back().pose.theta_rad - base[10].pose.theta_rad;
  const auto yw = drive(c, 0, raw);
  EXPECT_NEAR((yw.back().pose.theta_rad - yw[10].pose.theta_rad) / h0, 0.97, 2e-3);
  c.odometry = bias;
  const auto bi = drive(c, 0, raw);
  EXPECT_NEAR((bi.back().pose.theta_rad - bi[10].pose.theta_rad) - h0, -0.004 * 3.09, 1e-4);
  // Unequal wheels: 0.008 rad per metre of the distance read (drive's speeds, 10 ms apart).
  c.odometry = curve;
  const auto cu = drive(c, 0, raw);
  double read_m = 0.0;
  for (int i = 11; i < 320; ++i) read_m += (0.5 + 0.001 * i) * 0.01;
  EXPECT_NEAR((cu.back().pose.theta_rad - cu[10].pose.theta_rad) - h0, 0.008 * read_m, 1e-4);
}

TEST(Localizer, InvalidOdometryCorrectionThrows) {
  auto c = test_config();
  c.odometry.speed_scale = 0.0;
  EXPECT_THROW(localizer::Localizer{c}, std::invalid_argument);
  c = test_config();
  c.odometry.yaw_rate_scale = -1.0;
  EXPECT_THROW(localizer::Localizer{c}, std::invalid_argument);
  c = test_config();
  c.odometry.yaw_rate_bias_radps = std::numeric_limits<double>::quiet_NaN();
  EXPECT_THROW(localizer::Localizer{c}, std::invalid_argument);
  c = test_config();
  c.odometry.yaw_per_metre_rad = std::numeric_limits<double>::infinity();
  EXPECT_THROW(localizer::Localizer{c}, std::invalid_argument);
  c = test_config();
  c.fusion.slip.wheel_track_mm = 0.0;  // the one track width (the fusion refuses it)
  EXPECT_THROW(localizer::Localizer{c}, std::invalid_argument);
}

TEST(Localizer, PredictionForAFrameIsValidOnlyWhenThePoseIs) {
  Rig r;
  auto& [c, loc, can, out, t] = r;
  // Not initialised: odometry alone gives no prediction.
  for (int i = 0; i < 5; ++i) {
    loc.on_odometry(t, 0.5, 0.0);
    can.tick(loc, t += 10 * kMs, &out, nullptr);
  }
  EXPECT_FALSE(loc.prediction_at(t).valid);
  EXPECT_FALSE(loc.snapshot_at(t).valid);
  loc.on_fix(good_fix(100.0), t - 5 * kMs, t);
  loc.on_odometry(t, 0.5, 0.0);
  can.tick(loc, t += 10 * kMs, &out, nullptr);
  ASSERT_TRUE(pose_valid(c, out));
  // Initialised with odometry: the estimate at the exposure, moving at 0.5 m/s.
  const vision::Prediction p = loc.prediction_at(t + 4 * kMs);
  ASSERT_TRUE(p.valid);
  const fusion::PoseEstimate e = loc.ekf().estimate_at(t + 4 * kMs);
  EXPECT_EQ(p.vehicle_in_world.x_mm, e.pose.x_mm);
  EXPECT_TRUE(p.cov == e.cov.topLeftCorner(3, 3));
  EXPECT_GT(p.vehicle_in_world.x_mm, 100.0);
  const vision::MotionSnapshot s = loc.snapshot_at(t);
  ASSERT_TRUE(s.valid);
  EXPECT_NEAR(s.v_mm_per_s, 500.0, 50.0);
  // The same exposure but 60 ms after the last odometry: timed out, no prediction.
  EXPECT_FALSE(loc.prediction_at(t + 60 * kMs).valid);
  EXPECT_TRUE(loc.prediction_at(t + 40 * kMs).valid);
}

namespace {

vision::LandmarkFix guided_fix(double x_mm) {
  vision::LandmarkFix fix = good_fix(x_mm);
  fix.identity = vision::FixIdentity::kMapGuided;
  return fix;
}

p::QualityOut quality_of(const localizer::LocalizerConfig& c, const localizer::OutFrames& out) {
  return decoded<p::QualityOut>(c, out, p::Msg::kQuality,
                                [](auto&&... a) { return p::decode_quality(a...); });
}

}  // namespace

// docs/design/map_identity.md: a map-guided fix took its identity from the filter's own prediction,
// so it can only refine a filter that is tracking; it never starts or restarts one.
TEST(Localizer, MapGuidedFixNeverInitialisesTheFilter) {
  Rig r;
  auto& [c, loc, can, out, t] = r;
  for (int i = 0; i < 5; ++i) {
    loc.on_odometry(t, 0.5, 0.0);
    can.tick(loc, t += 10 * kMs, &out, nullptr);
  }
  loc.on_odometry(t, 0.5, 0.0);
  vision::LandmarkFix g = guided_fix(0.0);
  g.map_verified = true;  // even if a caller claims it: a map-guided fix is never verified
  loc.on_fix(g, t - 3 * kMs, t);
  EXPECT_FALSE(loc.ekf().initialised());
  EXPECT_EQ(loc.stats().fixes_map_guided, 1u);
  EXPECT_EQ(loc.stats().fixes_rejected_not_tracking, 1u);
  EXPECT_EQ(loc.stats().fixes_fused, 0u);
  can.tick(loc, t += 10 * kMs, &out, nullptr);
  EXPECT_FALSE(quality_of(c, out).map_guided_fix);
  // A QR fix initialises; then a map-guided fix is fused and flagged in the next quality frame
  // (and only that one).
  loc.on_odometry(t, 0.5, 0.0);
  loc.on_fix(good_fix(0.0), t - 3 * kMs, t);
  ASSERT_TRUE(loc.ekf().initialised());
  can.tick(loc, t += 10 * kMs, &out, nullptr);
  EXPECT_FALSE(quality_of(c, out).map_guided_fix);
  loc.on_odometry(t, 0.5, 0.0);
  loc.on_fix(guided_fix(loc.ekf().estimate_at(t - 3 * kMs).pose.x_mm), t - 3 * kMs, t);
  EXPECT_EQ(loc.stats().fixes_map_guided_fused, 1u);
  can.tick(loc, t += 10 * kMs, &out, nullptr);
  EXPECT_TRUE(quality_of(c, out).map_guided_fix);
  can.tick(loc, t += 10 * kMs, &out, nullptr);
  EXPECT_FALSE(quality_of(c, out).map_guided_fix);
}

TEST(Localizer, MapGuidedFixesNeverReinitialiseAKidnappedFilter) {
  const auto c = test_config();
  localizer::Localizer loc(c);
  std::int64_t t = 1000 * kMs;
  loc.on_odometry(t, 0.5, 0.0);
  loc.on_fix(good_fix(0.0), t - 1 * kMs, t);
  ASSERT_TRUE(loc.ekf().initialised());
  // The vehicle drives at 0.5 m/s; fixes put it 5 m further than the filter believes, every
  // 100 ms for 8 s: the kidnap rule's evidence (agreeing, >= 300 mm apart, >= 3 s) when the fixes
  // are QR fixes.
  auto drive = [&](bool guided, int steps) {
    for (int i = 0; i < steps && loc.stats().reinitialisations == 0; ++i) {
      for (int k = 0; k < 10; ++k) loc.on_odometry(t += 10 * kMs, 0.5, 0.0);
      const double x = 5000.0 + 0.5 * static_cast<double>(t - 1000 * kMs) / 1e6;
      loc.on_fix(guided ? guided_fix(x) : good_fix(x), t - 1 * kMs, t);
    }
  };
  drive(true, 80);
  EXPECT_EQ(loc.stats().reinitialisations, 0u);
  EXPECT_EQ(loc.stats().fixes_map_guided, 80u);
  EXPECT_EQ(loc.stats().fixes_map_guided_fused, 0u);
  EXPECT_LT(loc.ekf().estimate_at(t).pose.x_mm, 4500.0);
  drive(false, 80);
  EXPECT_GE(loc.stats().reinitialisations, 1u);
}

TEST(Localizer, MapGuidedFixIsRefusedByALostFilter) {
  fusion::Ekf ekf(test_config().fusion);
  std::int64_t t = 1000 * kMs;
  ASSERT_TRUE(ekf.add_odometry(t, 0.0, 0.0));
  // Initialised from a fix so uncertain that the prior's position spans landmarks (sigma
  // 400 mm > 4 x the 50 mm lost limit): the covariance cannot have chosen the identity.
  Eigen::Matrix3d wide = Eigen::Matrix3d::Identity() * 400.0 * 400.0;
  wide(2, 2) = 1e-4;
  ASSERT_EQ(ekf.add_fix(t, {0.0, 0.0, 0.0}, wide), fusion::FixOutcome::kInitialised);
  t += 10 * kMs;
  ASSERT_TRUE(ekf.add_odometry(t, 0.0, 0.0));
  const vision::LandmarkFix g = guided_fix(0.0);
  EXPECT_EQ(ekf.add_fix(t, g.vehicle_in_world, g.cov_world, false, /*map_guided=*/true),
            fusion::FixOutcome::kRejectedNotTracking);
  EXPECT_EQ(ekf.counters().fixes_rejected_not_tracking, 1u);
  // The same fix from a readable code is fused (or re-localises): only the identity differs.
  const fusion::FixOutcome o = ekf.add_fix(t, g.vehicle_in_world, g.cov_world, true, false);
  EXPECT_TRUE(o == fusion::FixOutcome::kFused || o == fusion::FixOutcome::kReinitialised)
      << fusion::to_string(o);
}

// Lost only on the heading, the position still separates mapped landmarks 1 m apart.
// A map-guided fix that passes the gate is fused (it used to be refused by the health label), and
// the prediction that map identity needs is given.
TEST(Localizer, MapGuidedFixIsFusedByAHeadingLostFilterWhenItPassesTheGate) {
  auto c = test_config();
  c.fusion.health.lost_heading_sigma_rad = deg_to_rad(0.05);
  localizer::Localizer loc(c);
  localizer::CanOutput can(c.protocol);
  localizer::OutFrames out;
  localizer::TickRecord rec;
  std::int64_t t = 1000 * kMs;
  loc.on_odometry(t, 0.5, 0.0);
  loc.on_fix(good_fix(0.0), t, t + kMs);
  for (int i = 0; i < 200; ++i) {
    t += 10 * kMs;
    loc.on_odometry(t, 0.5, 0.0);
  }
  can.tick(loc, t, &out, &rec);
  ASSERT_EQ(rec.estimate.health, fusion::HealthState::kLost);
  ASSERT_LT(rec.estimate.position_sigma_mm, c.fusion.health.lost_position_sigma_mm);
  EXPECT_TRUE(loc.prediction_at(t).valid);
  EXPECT_FALSE(pose_valid(c, out));  // the output still says lost
  loc.on_fix(guided_fix(rec.estimate.pose.x_mm), t, t + kMs);
  EXPECT_EQ(loc.stats().fixes_map_guided_fused, 1u);
}

// Time base: the output is on the vehicle's clock (the odometry's). A camera whose
// stamps are 12 ms late (vehicle clock = camera clock - 12 ms, camera.time_offset_ms = -12)
// gives, with the offset configured, the pose of the vehicle at the tick's own time; without
// it the fixes pull the pose 12 mm back (at 1 m/s).
TEST(Localizer, CalibratedCameraOffsetKeepsTheOutputOnTheVehicleClock) {
  auto run = [](std::int64_t configured_offset_ns) {
    auto c = test_config();
    c.time_base.camera_offset_ns = configured_offset_ns;
    localizer::Localizer loc(c);
    localizer::CanOutput can(c.protocol);
    localizer::OutFrames out;
    localizer::TickRecord rec;
    double worst_mm = 0.0;
    for (int i = 0; i <= 300; ++i) {  // 3 s straight at 1 m/s, truth x = t
      const std::int64_t t = 1000 * kMs + i * 10 * kMs;
      loc.on_odometry(t, 1.0, 0.0);
      if (i % 20 == 0) {  // a landmark fix every 200 ms, exposed at t, stamped 12 ms late
        const double x_true_mm = static_cast<double>(t - 1000 * kMs) * 1e-6;
        loc.on_fix(good_fix(x_true_mm), t + 12 * kMs, t + 30 * kMs);
      }
      can.tick(loc, t, &out, &rec);
      if (i >= 100 && rec.estimate.valid) {
        const double x_true_mm = static_cast<double>(t - 1000 * kMs) * 1e-6;
        worst_mm = std::max(worst_mm, std::abs(rec.estimate.pose.x_mm - x_true_mm));
      }
    }
    return worst_mm;
  };
  EXPECT_LT(run(-12 * kMs), 1.0);
  EXPECT_GT(run(0), 5.0);
}

// ---- Fault transitions for the log (localizer/fault_transitions.hpp) ----

TEST(FaultTransitionLog, EachSetAndClearOnceWithTheBitsName) {
  localizer::FaultTransitionLog log;
  std::int64_t t = 1000 * kMs;
  EXPECT_EQ(log.update(0, t).n, 0);
  auto ft = log.update(p::fault::kCameraStalled | p::fault::kCanBusOff, t += 10 * kMs);
  ASSERT_EQ(ft.n, 2);
  EXPECT_EQ(ft.items[0].bit, p::fault::kCameraStalled);
  EXPECT_STREQ(ft.items[0].signal, "FaultCameraStalled");
  EXPECT_STREQ(ft.items[0].name, "camera_stalled");
  EXPECT_TRUE(ft.items[0].set);
  EXPECT_EQ(ft.items[0].changes, 1u);
  EXPECT_STREQ(ft.items[1].signal, "FaultCanBusOff");
  // Still set: nothing more.
  for (int i = 0; i < 100; ++i) {
    EXPECT_EQ(log.update(p::fault::kCameraStalled | p::fault::kCanBusOff, t += 10 * kMs).n, 0);
  }
  // Bus-off clears: reported at once.
  ft = log.update(p::fault::kCameraStalled, t += 10 * kMs);
  ASSERT_EQ(ft.n, 1);
  EXPECT_STREQ(ft.items[0].name, "can_bus_off");
  EXPECT_FALSE(ft.items[0].set);
  EXPECT_EQ(ft.items[0].changes, 1u);
  // The 16-bit word: the gyro bits are named too.
  ft = log.update(p::fault::kCameraStalled | p::fault::kImuTimeout, t += 10 * kMs);
  ASSERT_EQ(ft.n, 1);
  EXPECT_STREQ(ft.items[0].signal, "FaultImuTimeout");
}

TEST(FaultTransitionLog, EveryFaultBitHasANameInBitOrder) {
  const auto& names = localizer::fault_bit_names();
  std::uint16_t all = 0;
  for (std::size_t i = 0; i < names.size(); ++i) {
    if (i > 0) {
      EXPECT_LT(names[i - 1].bit, names[i].bit);
    }
    EXPECT_EQ(names[i].bit & (names[i].bit - 1), 0) << "one bit each";
    all = static_cast<std::uint16_t>(all | names[i].bit);
  }
  EXPECT_EQ(all, 0x3FF);  // the eight bits of byte 6 and the two gyro bits
}

// Odometry timeout from the first tick until odometry flows 30 ms later: both lines at once.
TEST(FaultTransitionLog, SetAndClearAreReportedWhenTheyHappen) {
  localizer::FaultTransitionLog log;
  std::int64_t t = 1000 * kMs;
  auto ft = log.update(p::fault::kOdomTimeout, t);
  ASSERT_EQ(ft.n, 1);
  EXPECT_TRUE(ft.items[0].set);
  EXPECT_EQ(log.update(p::fault::kOdomTimeout, t += 10 * kMs).n, 0);
  ft = log.update(0, t += 20 * kMs);
  ASSERT_EQ(ft.n, 1);
  EXPECT_STREQ(ft.items[0].name, "odometry_timeout");
  EXPECT_FALSE(ft.items[0].set);
  EXPECT_EQ(ft.items[0].changes, 1u);
}

TEST(FaultTransitionLog, FlappingFaultIsRateLimitedAndItsFinalStateReported) {
  const std::int64_t hold = localizer::FaultTransitionLog::kDefaultWindowNs;
  localizer::FaultTransitionLog log;
  std::int64_t t = 1000 * kMs;
  // Toggles every 10 ms tick for 60 s: 6000 changes.
  int lines = 0;
  std::uint32_t changes = 0;
  bool last_reported = false;
  for (int i = 0; i < 6000; ++i) {
    const auto ft = log.update((i % 2 == 0) ? p::fault::kOdomTimeout : 0, t += 10 * kMs);
    for (int k = 0; k < ft.n; ++k) {
      ++lines;
      changes += ft.items[k].changes;
      last_reported = ft.items[k].set;
    }
  }
  // At most kBurst lines per window.
  const int burst = localizer::FaultTransitionLog::kBurst;
  EXPECT_LE(lines, burst * static_cast<int>(60'000'000'000 / hold + 1));
  EXPECT_GE(lines, burst);
  // Settles set (the last update was i = 5999: clear; make it set and hold still).
  auto ft = log.update(p::fault::kOdomTimeout, t += 10 * kMs);
  for (int k = 0; k < ft.n; ++k) last_reported = ft.items[k].set, changes += ft.items[k].changes;
  for (int j = 0; j < 2; ++j) {
    ft = log.update(p::fault::kOdomTimeout, t += hold);
    for (int k = 0; k < ft.n; ++k) last_reported = ft.items[k].set, changes += ft.items[k].changes;
  }
  EXPECT_TRUE(last_reported) << "the log ends in the bit's real state";
  EXPECT_EQ(changes, 6001u) << "every change is counted in some line";
  // Settled: quiet.
  EXPECT_EQ(log.update(p::fault::kOdomTimeout, t += hold).n, 0);
}
