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
// the heading off by that much), then floor fixes (by default at the true pose from two
// consecutive floor frames, 3.00 and 3.03 s) and 1 s more of frames.
struct MountDrive {
  localizer::OutputStats stats;
  fusion::PoseEstimate after_fix;  // the estimate right after the last floor fix
  Pose2 truth_at_fix;
};

struct DriveOptions {
  bool floor_check = true;
  double mount_error_rad = 0.0;
  bool turned_after_fix = true;
  // Floor frames (ms, on the 10 ms odometry grid, ascending), each fix the truth plus its error
  // (a misread). The drive ends 1 s after the last.
  struct FloorFrame {
    std::int64_t t_ms;
    Pose2 error;
    double sd_mm = 0.1;  // the fix's stated sigma (heading 1 mrad)
  };
  std::vector<FloorFrame> floor_frames{{3000, Pose2{}}, {3030, Pose2{}}};
  int conflict_fixes = localizer::RangingAidConfig{}.conflict_fixes;
};

// The floor frame at t, or nullptr.
const DriveOptions::FloorFrame* floor_frame(std::int64_t t, const DriveOptions& o) {
  for (const DriveOptions::FloorFrame& f : o.floor_frames)
    if (f.t_ms * kMs == t) return &f;
  return nullptr;
}

MountDrive drive(const DriveOptions& o) {
  localizer::LocalizerConfig cfg = config();
  cfg.ranging.floor_check = o.floor_check;
  cfg.ranging.conflict_fixes = o.conflict_fixes;
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
  const std::int64_t end_ns = (o.floor_frames.back().t_ms + 1000) * kMs;
  for (std::int64_t t = kOdomPeriodNs; t <= end_ns; t += kOdomPeriodNs) {
    loc.on_odometry(t, v, 0.0);
    if (const DriveOptions::FloorFrame* f = floor_frame(t, o)) {
      const Pose2& e = f->error;
      vision::LandmarkMeasurement floor;
      floor.status = vision::FixStatus::kOk;
      floor.landmark_id = 10;
      floor.vehicle_in_world = truth(t);
      floor.vehicle_in_world.x_mm += e.x_mm;
      floor.vehicle_in_world.y_mm += e.y_mm;
      floor.vehicle_in_world.theta_rad += e.theta_rad;
      floor.cov_world = Eigen::Matrix3d::Identity() * f->sd_mm * f->sd_mm;
      floor.cov_world(2, 2) = 1e-6;
      loc.on_fix(floor, t, t);
      r.after_fix = loc.ekf().estimate_at(t);
      r.truth_at_fix = truth(t);
    }
    if (t < next_frame) continue;
    Pose2 seen_from = truth(next_frame);
    if (o.turned_after_fix || next_frame < o.floor_frames.front().t_ms * kMs) seen_from.theta_rad += o.mount_error_rad;
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

MountDrive drive_with_turned_camera(bool floor_check, double mount_error_rad,
                                    bool turned_after_fix = true) {
  DriveOptions o;
  o.floor_check = floor_check;
  o.mount_error_rad = mount_error_rad;
  o.turned_after_fix = turned_after_fix;
  return drive(o);
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
  EXPECT_EQ(without.stats.fixes_rejected_gate, 2u);
  EXPECT_GT(heading_err(without), deg_to_rad(1.0));
  EXPECT_EQ(with.stats.ranging_floor_disputes, 1u);  // the first of the two
  EXPECT_EQ(with.stats.ranging_floor_conflicts, 1u);
  EXPECT_EQ(with.stats.ranging_suspensions, 1u);
  EXPECT_LT(heading_err(with), deg_to_rad(0.2));
  EXPECT_LT(position_err(with), 5.0);
  // Suspended: the frames of the last second are not used.
  EXPECT_GE(with.stats.ranging_suspended_frames, 13u);
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

// One wrong floor fix (a misread: 40 mm off along the drive) and no other floor frame,
// the rack camera as calibrated: the rack-aided filter gates it and the floor-only twin, less
// sure 3 s after its last floor landmark, fuses it. One fix is not enough to overrule the rack
// landmarks: the filter keeps its pose and the rack aid. Taking over at the first
// (conflict_fixes 1) put the wrong fix's pose in the filter and suspended the right rack aid.
TEST(LocalizerRanging, OneWrongFloorFixDoesNotOverruleTheRackLandmarks) {
  DriveOptions o;
  o.floor_frames = {{3000, Pose2{40.0, 0.0, 0.0}}};
  o.conflict_fixes = 1;
  const MountDrive at_once = drive(o);
  o.conflict_fixes = 2;
  const MountDrive two = drive(o);
  auto position_err = [](const MountDrive& r) {
    return std::hypot(r.after_fix.pose.x_mm - r.truth_at_fix.x_mm,
                      r.after_fix.pose.y_mm - r.truth_at_fix.y_mm);
  };
  std::printf("one wrong floor fix: taken over at once %.1f mm off, %llu suspensions; two in a "
              "row needed %.1f mm, %llu\n",
              position_err(at_once),
              static_cast<unsigned long long>(at_once.stats.ranging_suspensions),
              position_err(two), static_cast<unsigned long long>(two.stats.ranging_suspensions));
  // The premise: the twin fused the wrong fix, the filter gated it.
  ASSERT_EQ(at_once.stats.ranging_floor_conflicts, 1u);
  EXPECT_EQ(at_once.stats.ranging_suspensions, 1u);
  EXPECT_GT(position_err(at_once), 20.0);
  EXPECT_EQ(two.stats.ranging_floor_conflicts, 0u);
  EXPECT_EQ(two.stats.ranging_floor_disputes, 1u);
  EXPECT_EQ(two.stats.ranging_suspensions, 0u);
  EXPECT_EQ(two.stats.ranging_suspended_frames, 0u);
  EXPECT_LT(position_err(two), 5.0);
}

// Wrong floor fixes with a right one between them are not taken over (the filter fuses the right
// one, and the count starts again); two in a row are (70 ms apart: a rack frame between them).
TEST(LocalizerRanging, TwoWrongFloorFixesInARowOverruleTheRackLandmarks) {
  const Pose2 wrong{40.0, 0.0, 0.0};
  DriveOptions o;
  o.floor_frames = {{3000, wrong}, {3070, Pose2{}}, {3140, wrong}};
  const MountDrive apart = drive(o);
  o.floor_frames = {{3000, wrong}, {3070, wrong}};
  const MountDrive in_a_row = drive(o);
  EXPECT_EQ(apart.stats.ranging_floor_disputes, 1u);
  EXPECT_EQ(apart.stats.ranging_floor_conflicts, 0u);
  EXPECT_EQ(apart.stats.ranging_suspensions, 0u);
  EXPECT_EQ(in_a_row.stats.ranging_floor_disputes, 1u);
  EXPECT_EQ(in_a_row.stats.ranging_floor_conflicts, 1u);
}

// A misread floor fix 40 mm off, a right one 70 ms later, and 7 s of rack frames later a misread
// 15 mm off. The first: the filter gates it, its floor-only twin (3 s from its last floor fix)
// fuses it. The second: the filter fuses it and the twin, now 0.1 mm sure of the misread, gates
// it; it takes over the filter's estimate. Without that it drifted 136 mm off at a 3.6 mm sigma
// (on the odometry calibration the 40 mm jump taught it) by the third and gated it, ready to
// overrule the rack landmarks at the next dispute. The third: a dispute, but not in a row with the
// first (the fused one started the count again; without that, taken over: 15 mm off).
TEST(LocalizerRanging, AFusedFloorFixResetsTheTwinAndStartsTheCountAgain) {
  const Pose2 wrong{40.0, 0.0, 0.0};
  DriveOptions o;
  o.floor_frames = {{3000, wrong}, {3070, Pose2{}}, {10000, Pose2{15.0, 0.0, 0.0}}};
  const MountDrive r = drive(o);
  const double err_mm = std::hypot(r.after_fix.pose.x_mm - r.truth_at_fix.x_mm,
                                   r.after_fix.pose.y_mm - r.truth_at_fix.y_mm);
  std::printf("misread, right, misread: %llu twin resets, %llu disputes, filter %.1f mm off\n",
              static_cast<unsigned long long>(r.stats.ranging_floor_twin_resyncs),
              static_cast<unsigned long long>(r.stats.ranging_floor_disputes), err_mm);
  EXPECT_EQ(r.stats.ranging_floor_twin_resyncs, 1u);
  EXPECT_EQ(r.stats.ranging_floor_disputes, 2u);
  EXPECT_EQ(r.stats.ranging_floor_conflicts, 0u);
  EXPECT_EQ(r.stats.ranging_suspensions, 0u);
  EXPECT_EQ(r.stats.fixes_rejected_gate, 2u);
  EXPECT_LT(err_mm, 5.0);
}

}  // namespace
}  // namespace agv
