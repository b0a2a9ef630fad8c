// The core's transport-neutral output (TickRecord, PoseOutput) and its CAN encoding
// (localizer::CanOutput).
#include <gtest/gtest.h>

#include <cmath>

#include "agv/localizer/can_output.hpp"
#include "agv/localizer/localizer.hpp"

using namespace agv;
namespace p = agv::protocol;

namespace {

constexpr std::int64_t kMs = 1'000'000;

localizer::LocalizerConfig test_config() {
  localizer::LocalizerConfig c;
  c.fusion.health.odom_timeout_ns = 50 * kMs;
  c.heartbeat_period_ns = 100 * kMs;
  return c;
}

vision::LandmarkFix fix_at(double x_mm) {
  vision::LandmarkFix fix;
  fix.status = vision::FixStatus::kOk;
  fix.landmark_id = 4;
  fix.vehicle_in_world = {x_mm, 20.0, 0.0};
  fix.cov_world = Eigen::Matrix3d::Identity() * 4.0;
  fix.cov_world(2, 2) = 1e-4;
  return fix;
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
  const auto c = test_config();
  localizer::Localizer loc(c);
  localizer::CanOutput can(c.protocol);
  std::int64_t t = 1000 * kMs;
  int heartbeats = 0, valid = 0;
  for (int i = 0; i < 40; ++i) {
    loc.on_odometry(t, 0.5, 0.05);
    if (i == 10) loc.on_fix(fix_at(100.0), t - 5 * kMs, t);
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
  const auto c = test_config();
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
