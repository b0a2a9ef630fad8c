// The floor check (RangingAidConfig::floor_check): a floor-only twin of the filter arbitrates a
// floor fix the filter gates after rack updates, so that rack landmarks seen through a camera
// turned since its calibration cannot veto the floor camera.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <random>
#include <vector>

#include "agv/localizer/localizer.hpp"
#include "localizer_ranging_support.hpp"

namespace agv {
namespace {

using namespace ranging_test;  // NOLINT: the shared simulation

// A drive at 0.5 m/s from a floor fix at kTruth for 3 s, the rack landmarks seen through a camera
// turned mount_error_rad from its calibration (each frame observed from the true position with
// the heading off by that much), then a floor fix at the true pose and 1 s more of frames.
struct MountDrive {
  localizer::OutputStats stats;
  fusion::PoseEstimate after_fix;  // the estimate right after the floor fix at 3 s
  Pose2 truth_at_fix;
};

MountDrive drive_with_turned_camera(bool floor_check, double mount_error_rad,
                                    bool turned_after_fix = true) {
  localizer::LocalizerConfig cfg = config();
  cfg.ranging.floor_check = floor_check;
  localizer::Localizer loc(cfg);
  std::mt19937 rng(11);
  start_at_floor_fix(&loc, 0.5);
  const double v = 0.5;
  auto truth = [&](std::int64_t t) {
    const double d_mm = v * static_cast<double>(t) * 1e-6;
    return Pose2{kTruth.x_mm + d_mm * std::cos(kTruth.theta_rad),
                 kTruth.y_mm + d_mm * std::sin(kTruth.theta_rad), kTruth.theta_rad};
  };
  MountDrive r;
  std::int64_t next_frame = kFramePeriodNs;
  for (std::int64_t t = kOdomPeriodNs; t <= 4000 * kMs; t += kOdomPeriodNs) {
    loc.on_odometry(t, v, 0.0);
    if (t == 3000 * kMs) {
      vision::LandmarkMeasurement floor;
      floor.status = vision::FixStatus::kOk;
      floor.landmark_id = 10;
      floor.vehicle_in_world = truth(t);
      floor.cov_world = Eigen::Matrix3d::Identity() * 0.01;
      floor.cov_world(2, 2) = 1e-6;
      loc.on_fix(floor, t, t);
      r.after_fix = loc.ekf().estimate_at(t);
      r.truth_at_fix = truth(t);
    }
    if (t < next_frame) continue;
    Pose2 seen_from = truth(next_frame);
    if (turned_after_fix || next_frame < 3000 * kMs) seen_from.theta_rad += mount_error_rad;
    std::vector<localizer::RackObservation> obs;
    for (const Landmark& l : kTwo) obs.push_back(observe(seen_from, l, l.xy_mm, &rng));
    loc.on_ranging(next_frame, obs);
    next_frame += kFramePeriodNs;
    loc.set_camera_state(t, false, false);
    loc.tick(t);
  }
  r.stats = loc.stats();
  return r;
}

// A camera turned 2 degrees since its calibration pulls the filter's heading 2 degrees off; the
// floor fix that shows it fails the gate of a filter the rack updates made confident. Without the
// floor-only twin it is refused and the filter stays wrong; with it, the twin (which fused the
// fix) overrules the rack aid: the filter is reset to the floor camera's pose and the rack aid
// suspended.
TEST(LocalizerRanging, AFloorFixOverrulesRackLandmarksSeenThroughATurnedCamera) {
  const double err = deg_to_rad(2.0);
  const MountDrive without = drive_with_turned_camera(false, err);
  const MountDrive with = drive_with_turned_camera(true, err);
  auto heading_err = [](const MountDrive& r) {
    return std::abs(wrap_angle_rad(r.after_fix.pose.theta_rad - r.truth_at_fix.theta_rad));
  };
  auto position_err = [](const MountDrive& r) {
    return std::hypot(r.after_fix.pose.x_mm - r.truth_at_fix.x_mm,
                      r.after_fix.pose.y_mm - r.truth_at_fix.y_mm);
  };
  std::printf(
      "turned camera: without the twin heading %.3f deg off, %.1f mm; with it %.3f deg, "
      "%.1f mm\n",
      heading_err(without) * 180.0 / kPi, position_err(without), heading_err(with) * 180.0 / kPi,
      position_err(with));
  EXPECT_EQ(without.stats.fixes_rejected_gate, 1u);
  EXPECT_GT(heading_err(without), deg_to_rad(1.0));
  EXPECT_EQ(with.stats.ranging_floor_conflicts, 1u);
  EXPECT_EQ(with.stats.ranging_suspensions, 1u);
  EXPECT_LT(heading_err(with), deg_to_rad(0.2));
  EXPECT_LT(position_err(with), 5.0);
  // Suspended: the frames of the last second are not used.
  EXPECT_GE(with.stats.ranging_suspended_frames, 14u);
  EXPECT_EQ(without.stats.ranging_suspended_frames, 0u);
}

// The rack frames after the reset agree with the floor camera's pose (here the camera is right
// again; on a drive, the filter had been overconfident after a slip the wheels did not show): the
// rack aid is not suspended and fuses them.
TEST(LocalizerRanging, RackFramesThatAgreeAfterTheResetKeepTheRackAid) {
  const MountDrive r = drive_with_turned_camera(true, deg_to_rad(2.0), false);
  EXPECT_EQ(r.stats.ranging_floor_conflicts, 1u);
  EXPECT_EQ(r.stats.ranging_suspensions, 0u);
  EXPECT_EQ(r.stats.ranging_suspended_frames, 0u);
  EXPECT_LT(std::abs(wrap_angle_rad(r.after_fix.pose.theta_rad - r.truth_at_fix.theta_rad)),
            deg_to_rad(0.2));
}

// With the camera as calibrated the floor fix is fused and nothing is overruled.
TEST(LocalizerRanging, ACalibratedCameraIsNeverOverruled) {
  const MountDrive r = drive_with_turned_camera(true, 0.0);
  EXPECT_EQ(r.stats.ranging_floor_conflicts, 0u);
  EXPECT_EQ(r.stats.ranging_suspensions, 0u);
  EXPECT_EQ(r.stats.ranging_suspended_frames, 0u);
  EXPECT_EQ(r.stats.fixes_rejected_gate, 0u);
}

}  // namespace
}  // namespace agv
