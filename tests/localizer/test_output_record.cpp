// The core's transport-neutral output (TickRecord, PoseOutput) and its CAN encoding
// (localizer::CanOutput), and the fix counters the statistics read from the EKF.
#include <gtest/gtest.h>

#include <cmath>

#include "agv/localizer/can_output.hpp"
#include "agv/localizer/localizer.hpp"
#include "localizer_test_support.hpp"

using namespace agv;
namespace p = agv::protocol;
using localizer_test::good_fix;
using localizer_test::kMs;
using localizer_test::test_config;

namespace {

localizer::LocalizerConfig config_100ms_heartbeat() {
  localizer::LocalizerConfig c = test_config();
  c.heartbeat_period_ns = 100 * kMs;
  return c;
}

// Odometry at 0.5 m/s and one fix: the filter initialised at the returned time.
std::int64_t initialised(localizer::Localizer* loc) {
  std::int64_t t = 1000 * kMs;
  for (int i = 0; i < 5; ++i) loc->on_odometry(t += 10 * kMs, 0.5, 0.0);
  loc->on_fix(good_fix(0.0), t - 5 * kMs, t);
  return t;
}

// Every frame of a period decodes to the record's values (to the signals' resolution).
void expect_frames_carry(const localizer::LocalizerConfig& c, const localizer::TickRecord& r,
                         const localizer::OutFrames& out) {
  ASSERT_EQ(out.n, r.heartbeat_due ? 6 : 5);
  EXPECT_EQ(out.e2e_exposure_ns, r.pose.e2e_exposure_ns);
  p::PoseOut pose;
  ASSERT_TRUE(p::decode_pose(c.protocol, out.frame[0], out.frame[1], &pose));
  EXPECT_EQ(pose.valid, r.pose_valid);
  EXPECT_NEAR(pose.x_mm, r.pose.pose.x_mm, 0.1);
  EXPECT_NEAR(pose.y_mm, r.pose.pose.y_mm, 0.1);
  EXPECT_NEAR(pose.theta_rad, r.pose.pose.theta_rad, 1e-4);
  p::VelocityOut v;
  ASSERT_TRUE(p::decode_velocity(c.protocol, out.frame[2], &v));
  EXPECT_EQ(v.valid, r.velocity.valid);
  EXPECT_NEAR(v.v_mps, r.velocity.v_mps, 1e-3);
  p::QualityOut q;
  ASSERT_TRUE(p::decode_quality(c.protocol, out.frame[3], &q));
  EXPECT_EQ(q.valid, r.quality.valid);
  EXPECT_NEAR(q.sigma_x_mm, r.quality.sigma_x_mm, 0.1);
  p::StatusOut st;
  ASSERT_TRUE(p::decode_status(c.protocol, out.frame[4], &st));
  EXPECT_EQ(st.health, r.status.health);
  EXPECT_EQ(st.faults, r.status.faults);
  EXPECT_EQ(st.rejections, r.status.rejections);
  EXPECT_EQ(st.last_landmark_valid, r.status.last_landmark_valid);
  if (r.heartbeat_due) {
    p::HeartbeatOut hb;
    int version = 0;
    ASSERT_TRUE(p::decode_heartbeat(c.protocol, out.frame[5], &hb, &version));
    EXPECT_NEAR(hb.uptime_s, r.heartbeat.uptime_s, 0.5);  // whole seconds
  }
}

}  // namespace

TEST(LocalizerOutput, TheFramesCarryTheTickRecord) {
  const auto c = config_100ms_heartbeat();
  localizer::Localizer loc(c);
  localizer::CanOutput can(c.protocol);
  std::int64_t t = 1000 * kMs;
  int heartbeats = 0, valid = 0;
  for (int i = 0; i < 40; ++i) {
    loc.on_odometry(t, 0.5, 0.05);
    if (i == 10) loc.on_fix(good_fix(100.0), t - 5 * kMs, t);
    const localizer::TickRecord r = loc.tick(t += 10 * kMs);
    EXPECT_EQ(r.t_ns, t);
    EXPECT_EQ(r.pose_valid, p::pose_valid_on_can(r.pose.pose));
    localizer::OutFrames out;
    can.encode(r, &out);
    expect_frames_carry(c, r, out);
    heartbeats += r.heartbeat_due ? 1 : 0;
    valid += r.pose_valid ? 1 : 0;
  }
  EXPECT_EQ(heartbeats, 4);  // every 100 ms over 400 ms
  EXPECT_GT(valid, 20);      // after the fix
}

// The alive counters live in the CAN output: the pose pair sent at once after a fix and the
// periodic one count on one sequence, as on the bus.
TEST(LocalizerOutput, PoseNowAndTickShareThePoseCounter) {
  const auto c = config_100ms_heartbeat();
  localizer::Localizer loc(c);
  localizer::CanOutput can(c.protocol);
  localizer::OutFrames out;
  can.tick(loc, 1000 * kMs, &out);
  EXPECT_EQ(can.encoder().next_counter(p::Msg::kPoseXY), 1);
  can.pose_now(loc, 1005 * kMs, &out);
  EXPECT_EQ(out.n, 2);
  can.tick(loc, 1010 * kMs, &out);
  EXPECT_EQ(can.encoder().next_counter(p::Msg::kPoseXY), 3);
  EXPECT_EQ(can.encoder().next_counter(p::Msg::kVelocity), 2);
}

// A fix ahead of the odometry is held by the EKF and fused when the odometry catches up: the
// statistics count it then (they are the EKF's counters, not a second count of add_fix results).
TEST(LocalizerOutput, AHeldFixIsCountedWhenTheEkfFusesIt) {
  const auto c = config_100ms_heartbeat();
  localizer::Localizer loc(c);
  std::int64_t t = initialised(&loc);
  ASSERT_EQ(loc.stats().fixes_fused, 1u);
  // Exposed 250 ms after the newest odometry (more than fusion.max_fix_lead), where the vehicle
  // is then at 0.5 m/s; the odometry resumes after a 300 ms gap.
  const std::int64_t exposure = t + 250 * kMs;
  loc.on_fix(good_fix(127.5), exposure, exposure + 30 * kMs);
  EXPECT_EQ(loc.ekf().counters().fixes_held, 1u);
  EXPECT_EQ(loc.stats().fixes_fused, 1u);
  t += 300 * kMs;
  for (int i = 0; i < 5; ++i) loc.on_odometry(t += 10 * kMs, 0.5, 0.0);
  EXPECT_EQ(loc.ekf().counters().fixes_fused, 1u);  // the first one initialised
  EXPECT_EQ(loc.stats().fixes_fused, 2u);
  EXPECT_EQ(loc.stats().fixes_received, 2u);
}

// An operator-set pose (VDA 5050 initPosition) re-initialises the EKF, but it is no fix: the fix
// statistics do not count it.
TEST(LocalizerOutput, AnOperatorPoseIsNotCountedAsAFix) {
  const auto c = config_100ms_heartbeat();
  localizer::Localizer loc(c);
  std::int64_t t = initialised(&loc);
  loc.on_odometry(t += 10 * kMs, 0.5, 0.0);
  ASSERT_TRUE(loc.init_position(t, Pose2{500.0, 500.0, 1.0}));
  EXPECT_EQ(loc.ekf().counters().reinitialisations, 1u);
  EXPECT_EQ(loc.stats().reinitialisations, 0u);
  EXPECT_EQ(loc.stats().fixes_fused, 1u);
  EXPECT_EQ(loc.stats().fixes_rejected_gate, 0u);
}

// The mapping from the EKF's counters: a kidnap is counted by the EKF as a gate rejection and a
// re-initialisation; the statistics show it as a fused fix that re-initialised the filter.
TEST(LocalizerOutput, FixOutcomeCountsFromTheEkfCounters) {
  fusion::Ekf::Counters e;
  e.fixes_fused = 10;
  e.fixes_initialised = 1;
  e.fixes_rejected_gate = 4;  // one of them became a kidnap
  e.reinitialisations = 3;    // the kidnap, a re-localisation from a fix, an operator pose
  e.relocalisations = 2;      // the fix's and the operator's
  e.fixes_rejected_too_old = 5;
  e.fixes_rejected_invalid = 6;
  e.fixes_rejected_not_tracking = 7;
  localizer::OperatorPoseCounts op;
  op.reinitialisations = 1;
  localizer::OutputStats s;
  localizer::fix_outcome_counts(e, /*exposed_after_arrival=*/2, op, &s);
  EXPECT_EQ(s.fixes_fused, 13u);  // 10 fused + 1 initialisation + 2 re-initialisations
  EXPECT_EQ(s.fixes_rejected_gate, 3u);
  EXPECT_EQ(s.reinitialisations, 2u);
  EXPECT_EQ(s.fixes_rejected_too_old, 5u);
  EXPECT_EQ(s.fixes_rejected_invalid, 8u);
  EXPECT_EQ(s.fixes_rejected_not_tracking, 7u);
}
