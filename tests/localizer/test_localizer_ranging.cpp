// Landmarks on racks in the localizer (Localizer::on_ranging): a second camera's range-bearing
// observations, simulated from a known pose with the ranging library's own corner-noise model
// (a 150 mm tag, f = 1000 px, 0.3 px corners) and seeded noise, initialise a lost filter from
// two landmarks, never from one or from an inconsistent map, and narrow the pose between floor
// fixes while tracking.
#include <gtest/gtest.h>

#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>
#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <functional>
#include <optional>
#include <random>
#include <vector>

#include "agv/localizer/localizer.hpp"
#include "agv/ranging/range_models.hpp"
#include "localizer_ranging_support.hpp"

namespace agv {
namespace {

using namespace ranging_test;  // NOLINT: the shared simulation

struct StandRun {
  std::int64_t first_valid_ns = -1;  // data time of the first valid pose, -1 never
  localizer::TickRecord last;
};

// Standing still at the truth for duration_ns: odometry at 100 Hz, frames at 15 fps, a tick
// after every frame.
StandRun stand(localizer::Localizer* loc, std::int64_t t0_ns, std::int64_t duration_ns,
               const std::vector<Landmark>& lms, const std::vector<Vec2>& map, std::mt19937* rng) {
  StandRun r;
  std::int64_t next_frame = t0_ns;
  for (std::int64_t t = t0_ns; t <= t0_ns + duration_ns; t += kOdomPeriodNs) {
    loc->on_odometry(t, 0.0, 0.0);
    if (t < next_frame) continue;
    const auto obs = frame(kTruth, lms, map, rng);
    loc->on_ranging(next_frame, obs);
    next_frame += kFramePeriodNs;
    loc->set_camera_state(t, false, false);
    r.last = loc->tick(t);
    if (r.last.pose_valid && r.first_valid_ns < 0) r.first_valid_ns = t - t0_ns;
  }
  return r;
}

TEST(LocalizerRanging, TwoRackLandmarksLocalizeALostVehicleWithinOneSecond) {
  localizer::Localizer loc(config());
  std::mt19937 rng(54);
  const StandRun r = stand(&loc, 0, 1000 * kMs, kTwo, true_map(kTwo), &rng);
  ASSERT_GE(r.first_valid_ns, 0) << "never localized";
  // One fix is not trusted alone: the second agreeing frame initialises.
  EXPECT_GE(r.first_valid_ns, kFramePeriodNs);
  EXPECT_LE(r.first_valid_ns, 1000 * kMs);
  const fusion::PoseEstimate& e = r.last.estimate;
  const double err_mm = std::hypot(e.pose.x_mm - kTruth.x_mm, e.pose.y_mm - kTruth.y_mm);
  const double err_deg = std::abs(rad_to_deg(wrap_angle_rad(e.pose.theta_rad - kTruth.theta_rad)));
  std::printf("localized after %.0f ms; at 1 s: %.1f mm, %.3f deg off, sigma %.1f mm %.3f deg\n",
              static_cast<double>(r.first_valid_ns) / 1e6, err_mm, err_deg, e.position_sigma_mm,
              rad_to_deg(e.heading_sigma_rad));
  EXPECT_LT(err_mm, 50.0);
  EXPECT_LT(err_deg, 1.0);
  EXPECT_EQ(e.health, fusion::HealthState::kLocalized);
  EXPECT_EQ(loc.stats().ranging_initialisations, 1u);
  EXPECT_EQ(loc.stats().fixes_fused, 0u);      // rack initialisations are not floor fixes
  EXPECT_GT(loc.stats().ranging_fused, 0u);    // after it, the landmarks are EKF updates
  EXPECT_EQ(loc.stats().ranging_frames, 15u);  // 0 to 933 ms
}

TEST(LocalizerRanging, OneLandmarkNeverInitialisesASecondDoes) {
  localizer::Localizer loc(config());
  std::mt19937 rng(7);
  const std::vector<Landmark> one = {kTwo[0]};
  const StandRun r = stand(&loc, 0, 2000 * kMs, one, true_map(one), &rng);
  EXPECT_LT(r.first_valid_ns, 0);
  EXPECT_FALSE(loc.ekf().initialised());
  EXPECT_EQ(loc.stats().ranging_fixes, 30u);
  EXPECT_EQ(loc.stats().ranging_fix_refused[static_cast<int>(ranging::FixStatus::kTooFew)], 30u);
  // The same frames with the second landmark in view: localized.
  const StandRun r2 = stand(&loc, 2010 * kMs, 1000 * kMs, kTwo, true_map(kTwo), &rng);
  EXPECT_GE(r2.first_valid_ns, 0);
}

// A landmark missed in every other frame (a glint, a passer-by, the tag at the edge of the
// view): the frames that read one landmark give no fix and are skipped, not a break of the run,
// so the two-landmark frames 133 ms apart still initialise. Before, each one-landmark frame
// reset the run and the vehicle never localized.
TEST(LocalizerRanging, AFrameThatReadsOneLandmarkDoesNotBreakTheRun) {
  localizer::Localizer loc(config());
  std::mt19937 rng(54);
  const std::vector<Vec2> map = true_map(kTwo);
  const std::vector<Landmark> one = {kTwo[0]};
  const std::vector<Vec2> one_map = {map[0]};
  std::int64_t first_valid_ns = -1;
  std::int64_t next_frame = 0;
  int frame_index = 0;
  for (std::int64_t t = 0; t <= 1000 * kMs; t += kOdomPeriodNs) {
    loc.on_odometry(t, 0.0, 0.0);
    if (t < next_frame) continue;
    const bool both = frame_index++ % 2 == 0;
    const auto obs = both ? frame(kTruth, kTwo, map, &rng) : frame(kTruth, one, one_map, &rng);
    loc.on_ranging(next_frame, obs);
    next_frame += kFramePeriodNs;
    loc.set_camera_state(t, false, false);
    if (loc.tick(t).pose_valid && first_valid_ns < 0) first_valid_ns = t;
  }
  const auto too_few = static_cast<int>(ranging::FixStatus::kTooFew);
  EXPECT_GE(loc.stats().ranging_fix_refused[too_few], 1u);
  ASSERT_GE(first_valid_ns, 0) << "never localized";
  EXPECT_LE(first_valid_ns, 2 * kFramePeriodNs + kOdomPeriodNs);  // the second two-landmark frame
  EXPECT_EQ(loc.stats().ranging_initialisations, 1u);
  const fusion::PoseEstimate e = loc.ekf().estimate_at(1000 * kMs);
  EXPECT_LT(std::hypot(e.pose.x_mm - kTruth.x_mm, e.pose.y_mm - kTruth.y_mm), 50.0);
}

TEST(LocalizerRanging, AMapEntryHalfAMetreOffGivesNoConfidentWrongPose) {
  std::mt19937 rng(11);
  // Three landmarks in view, one map entry 0.5 m off in each of 8 directions: the fix is refused
  // (inconsistent), or any pose it gives has the error inside 3 sigma.
  int refused_frames = 0, valid_runs = 0;
  for (int k = 0; k < 8; ++k) {
    localizer::Localizer loc(config());
    std::vector<Vec2> map = true_map(kThree);
    const double a = k * M_PI / 4.0;
    map[1] = {map[1].x + 500.0 * std::cos(a), map[1].y + 500.0 * std::sin(a)};
    const StandRun r = stand(&loc, 0, 1000 * kMs, kThree, map, &rng);
    const fusion::PoseEstimate& e = r.last.estimate;
    if (r.last.pose_valid) {
      const double err_mm = std::hypot(e.pose.x_mm - kTruth.x_mm, e.pose.y_mm - kTruth.y_mm);
      EXPECT_LT(err_mm, 3.0 * e.position_sigma_mm) << "direction " << k;
      ++valid_runs;
    }
    refused_frames += static_cast<int>(
        loc.stats().ranging_fix_refused[static_cast<int>(ranging::FixStatus::kInconsistent)]);
  }
  std::printf("map entry 0.5 m off, 8 directions: %d localized, %d of 120 frames inconsistent\n",
              valid_runs, refused_frames);
  EXPECT_GT(refused_frames, 0);
  // The correct map localizes with the same landmarks.
  localizer::Localizer ok(config());
  const StandRun r = stand(&ok, 0, 1000 * kMs, kThree, true_map(kThree), &rng);
  EXPECT_TRUE(r.last.pose_valid);
}

// Two landmarks, one map entry 0.5 m off in 36 directions. Ranges and bearings alone cannot see
// an error that turns the pose about the other landmark; each landmark's face yaw (its full tag
// pose, seen 30 degrees off face-on) says the heading, which that turn contradicts.
TEST(LocalizerRanging, TwoLandmarksWithFaceYawsGiveNoConfidentWrongPoseFromAWrongMap) {
  std::vector<Landmark> two = kTwo;
  for (Landmark& l : two) l.full_pose = true;
  two[0].facing_rad = std::atan2(kTruth.y_mm - 2200.0, kTruth.x_mm - 3500.0) + deg_to_rad(30.0);
  two[1].facing_rad = std::atan2(kTruth.y_mm + 1600.0, kTruth.x_mm - 3800.0) - deg_to_rad(30.0);
  int confident_wrong[2] = {0, 0}, localized[2] = {0, 0};
  for (int use = 0; use < 2; ++use) {
    std::mt19937 rng(541);
    for (int k = 0; k < 36; ++k) {
      std::vector<Landmark> lms = two;
      for (Landmark& l : lms) l.full_pose = use == 1;
      localizer::Localizer loc(config());
      std::vector<Vec2> map = true_map(lms);
      const double a = k * M_PI / 18.0;
      map[0] = {map[0].x + 500.0 * std::cos(a), map[0].y + 500.0 * std::sin(a)};
      const StandRun r = stand(&loc, 0, 1000 * kMs, lms, map, &rng);
      if (!r.last.pose_valid) continue;
      ++localized[use];
      const fusion::PoseEstimate& e = r.last.estimate;
      const double err_mm = std::hypot(e.pose.x_mm - kTruth.x_mm, e.pose.y_mm - kTruth.y_mm);
      confident_wrong[use] += err_mm > 3.0 * e.position_sigma_mm;
    }
  }
  std::printf(
      "two landmarks, map entry 0.5 m off, 36 directions: without face yaws %d localized,"
      " %d outside 3 sigma; with %d localized, %d outside 3 sigma\n",
      localized[0], confident_wrong[0], localized[1], confident_wrong[1]);
  EXPECT_GE(confident_wrong[0], 1);  // the limit the face yaws remove
  EXPECT_EQ(confident_wrong[1], 0);
  // The correct map still localizes with the face yaws.
  std::mt19937 rng(5);
  localizer::Localizer ok(config());
  EXPECT_TRUE(stand(&ok, 0, 1000 * kMs, two, true_map(two), &rng).last.pose_valid);
}

TEST(LocalizerRanging, RackUpdatesNarrowThePoseBetweenFloorFixes) {
  // Driving at 0.5 m/s along x after a floor fix; with the rack landmarks in view the position
  // sigma after 3 s is smaller than with the wheels alone.
  auto drive = [](bool with_racks) {
    localizer::Localizer loc(config());
    std::mt19937 rng(3);
    start_at_floor_fix(&loc, 0.5);
    const double v = 0.5;
    std::int64_t next_frame = kFramePeriodNs;
    localizer::TickRecord rec;
    for (std::int64_t t = kOdomPeriodNs; t <= 3000 * kMs; t += kOdomPeriodNs) {
      loc.on_odometry(t, v, 0.0);
      if (t < next_frame) continue;
      const double d_mm = v * static_cast<double>(next_frame) * 1e-6;
      const Pose2 at{kTruth.x_mm + d_mm * std::cos(kTruth.theta_rad),
                     kTruth.y_mm + d_mm * std::sin(kTruth.theta_rad), kTruth.theta_rad};
      if (with_racks) {
        std::vector<localizer::RackObservation> obs;
        for (const Landmark& l : kTwo) obs.push_back(observe(at, l, l.xy_mm, &rng));
        loc.on_ranging(next_frame, obs);
      }
      next_frame += kFramePeriodNs;
      loc.set_camera_state(t, false, false);
      rec = loc.tick(t);
    }
    EXPECT_EQ(loc.stats().ranging_rejected_gate, 0u);
    return rec.estimate;
  };
  const fusion::PoseEstimate wheels = drive(false);
  const fusion::PoseEstimate racks = drive(true);
  std::printf("position sigma after 3 s: wheels %.2f mm, with rack landmarks %.2f mm\n",
              wheels.position_sigma_mm, racks.position_sigma_mm);
  ASSERT_TRUE(wheels.valid && racks.valid);
  EXPECT_LT(racks.position_sigma_mm, 0.5 * wheels.position_sigma_mm);
  const double d_mm = 0.5 * static_cast<double>(racks.t_ns) * 1e-6;
  const Pose2 end{kTruth.x_mm + d_mm * std::cos(kTruth.theta_rad),
                  kTruth.y_mm + d_mm * std::sin(kTruth.theta_rad), kTruth.theta_rad};
  const double err_mm = std::hypot(racks.pose.x_mm - end.x_mm, racks.pose.y_mm - end.y_mm);
  EXPECT_LT(err_mm, 3.0 * racks.position_sigma_mm);
}

// A drive at 0.5 m/s from a floor fix at kTruth with kTwo in view at 15 fps, wheels only. At
// step_ns the vehicle turns by step_rad in place without the odometry seeing it (a wheel slip);
// bad_frames are observed from a pose turned by step_rad without the vehicle turning (a bad
// frame). Returns the estimate at the end, and the frame index of the first re-localisation.
struct StepDrive {
  fusion::PoseEstimate end;
  Pose2 truth_end;
  int relocalised_frame = -1;
  std::uint64_t relocalisations = 0;
  std::uint64_t gated = 0;
};
StepDrive drive_with_step(std::int64_t step_ns, double step_rad, const std::vector<int>& bad_frames,
                          const std::vector<Landmark>& lms, const std::vector<Vec2>& map,
                          bool step_rule = true) {
  localizer::LocalizerConfig cfg = config();
  if (!step_rule) cfg.fusion.recovery.unseen_slip_max_rad = 0.0;
  localizer::Localizer loc(cfg);
  std::mt19937 rng(3);
  const double v = 0.5;
  start_at_floor_fix(&loc, v);
  StepDrive r;
  auto truth_at = [&](std::int64_t t) {
    const double d_mm = v * static_cast<double>(t) * 1e-6;
    if (t < step_ns)
      return Pose2{kTruth.x_mm + d_mm * std::cos(kTruth.theta_rad),
                   kTruth.y_mm + d_mm * std::sin(kTruth.theta_rad), kTruth.theta_rad};
    const double d0_mm = v * static_cast<double>(step_ns) * 1e-6;
    const double th = kTruth.theta_rad + step_rad;
    return Pose2{kTruth.x_mm + d0_mm * std::cos(kTruth.theta_rad) + (d_mm - d0_mm) * std::cos(th),
                 kTruth.y_mm + d0_mm * std::sin(kTruth.theta_rad) + (d_mm - d0_mm) * std::sin(th),
                 th};
  };
  std::int64_t next_frame = kFramePeriodNs;
  int frame_index = 0;
  for (std::int64_t t = kOdomPeriodNs; t <= 3000 * kMs; t += kOdomPeriodNs) {
    loc.on_odometry(t, v, 0.0);
    if (t < next_frame) continue;
    Pose2 at = truth_at(next_frame);
    if (std::find(bad_frames.begin(), bad_frames.end(), frame_index) != bad_frames.end())
      at.theta_rad += step_rad;
    const auto obs = frame(at, lms, map, &rng);
    const localizer::RangingResult res = loc.on_ranging(next_frame, obs);
    if (res == localizer::RangingResult::kRelocalised && r.relocalised_frame < 0)
      r.relocalised_frame = frame_index;
    next_frame += kFramePeriodNs;
    ++frame_index;
    loc.set_camera_state(t, false, false);
    r.end = loc.tick(t).estimate;
  }
  r.truth_end = truth_at(r.end.t_ns);
  r.relocalisations = loc.stats().ranging_step_relocalisations;
  r.gated = loc.stats().ranging_rejected_gate;
  return r;
}

double position_error_mm(const StepDrive& r) {
  return std::hypot(r.end.pose.x_mm - r.truth_end.x_mm, r.end.pose.y_mm - r.truth_end.y_mm);
}
double heading_error_rad(const StepDrive& r) {
  return std::abs(wrap_angle_rad(r.end.pose.theta_rad - r.truth_end.theta_rad));
}

TEST(LocalizerRanging, AHeadingStepTheWheelsDidNotSeeIsRelocalisedByRackFixes) {
  // 1 s of rack updates make the heading sigma small; then an unseen 2 deg turn. Every landmark
  // fails its gate from then on unless the rack fixes re-localise the filter.
  const std::int64_t step_ns = 1000 * kMs;
  const StepDrive r = drive_with_step(step_ns, deg_to_rad(2.0), {}, kTwo, true_map(kTwo));
  const int step_frame = static_cast<int>(step_ns / kFramePeriodNs);
  std::printf(
      "2 deg unseen step at frame %d: re-localised at frame %d; at 3 s %.2f mm %.3f deg off,"
      " sigma %.2f mm %.3f deg; %llu landmarks gated\n",
      step_frame, r.relocalised_frame, position_error_mm(r), rad_to_deg(heading_error_rad(r)),
      r.end.position_sigma_mm, rad_to_deg(r.end.heading_sigma_rad),
      static_cast<unsigned long long>(r.gated));
  ASSERT_GE(r.relocalised_frame, step_frame);
  EXPECT_LE(r.relocalised_frame, step_frame + 3);  // init_fixes (2) frames after the step
  EXPECT_EQ(r.relocalisations, 1u);
  EXPECT_LT(position_error_mm(r), 3.0 * r.end.position_sigma_mm + 1.0);
  EXPECT_LT(heading_error_rad(r), 3.0 * r.end.heading_sigma_rad + deg_to_rad(0.01));
  EXPECT_EQ(r.end.health, fusion::HealthState::kLocalized);
  // The same drive without the rule (fusion.recovery.unseen_slip_max_rad 0, as before it): the
  // landmarks stay gated and the confident pose ends outside 3 sigma.
  const StepDrive off = drive_with_step(step_ns, deg_to_rad(2.0), {}, kTwo, true_map(kTwo), false);
  std::printf("without the rule: %.2f mm off, sigma %.2f mm; %llu landmarks gated\n",
              position_error_mm(off), off.end.position_sigma_mm,
              static_cast<unsigned long long>(off.gated));
  EXPECT_EQ(off.relocalisations, 0u);
  EXPECT_GT(position_error_mm(off), 3.0 * off.end.position_sigma_mm);
}

TEST(LocalizerRanging, SingleDisagreeingFramesDoNotMoveAConfidentFilter) {
  // Frames seen as if turned by 2 deg, one at a time (two of them with a good frame between):
  // each is gated, none re-localises, and the pose stays where the good frames have it.
  const StepDrive r =
      drive_with_step(INT64_MAX, deg_to_rad(2.0), {20, 30, 32}, kTwo, true_map(kTwo));
  EXPECT_EQ(r.relocalisations, 0u);
  EXPECT_EQ(r.relocalised_frame, -1);
  EXPECT_GE(r.gated, 4u);  // the bad frames' landmarks were seen and refused
  EXPECT_LT(position_error_mm(r), 3.0 * r.end.position_sigma_mm + 1.0);
  EXPECT_LT(heading_error_rad(r), deg_to_rad(0.1));
}

TEST(LocalizerRanging, AWrongMapEntryAmongCorrectOnesDoesNotMoveATrackingFilter) {
  // Three in view while tracking, one map entry 0.5 m off in 8 directions: the correct landmarks
  // are fused in every frame, so no frame is all gated and the wrong entry never re-localises.
  for (int k = 0; k < 8; ++k) {
    std::vector<Vec2> map = true_map(kThree);
    const double a = k * M_PI / 4.0;
    map[1] = {map[1].x + 500.0 * std::cos(a), map[1].y + 500.0 * std::sin(a)};
    const StepDrive r = drive_with_step(INT64_MAX, 0.0, {}, kThree, map);
    EXPECT_EQ(r.relocalisations, 0u) << "direction " << k;
    EXPECT_LT(position_error_mm(r), 3.0 * r.end.position_sigma_mm + 1.0) << "direction " << k;
  }
}

// Standing at kTruth for 1 s seeing lms, each frame's observations changed by `alter`: the
// first valid estimate, or none.
std::optional<fusion::PoseEstimate> first_valid_estimate(
    const localizer::LocalizerConfig& c, const std::vector<Landmark>& lms, std::mt19937* rng,
    const std::function<void(std::vector<localizer::RackObservation>*)>& alter) {
  localizer::Localizer loc(c);
  for (std::int64_t t = 0, next_frame = 0; t <= 1000 * kMs; t += kOdomPeriodNs) {
    loc.on_odometry(t, 0.0, 0.0);
    if (t < next_frame) continue;
    std::vector<localizer::RackObservation> obs = frame(kTruth, lms, true_map(lms), rng);
    alter(&obs);
    loc.on_ranging(next_frame, obs);
    next_frame += kFramePeriodNs;
    loc.set_camera_state(t, false, false);
    const localizer::TickRecord rec = loc.tick(t);
    if (rec.pose_valid) return rec.estimate;
  }
  return std::nullopt;
}

// Standing at the truth, the camera turned by yaw_err_rad from its calibrated yaw (every bearing
// and face yaw off alike), the core told common_sigma_rad of it: the heading error over the
// heading sigma at the first valid pose (the initialising fix), -1 when none in 1 s.
double initial_heading_sigmas(double yaw_err_rad, double common_sigma_rad) {
  localizer::LocalizerConfig c = config();
  c.ranging.common_bearing_sigma_rad = common_sigma_rad;
  std::mt19937 rng(11);
  std::vector<Landmark> lms = kThree;
  for (Landmark& l : lms) l.full_pose = true;
  const auto e = first_valid_estimate(c, lms, &rng, [&](auto* obs) {
    for (localizer::RackObservation& o : *obs) {
      o.vehicle.bearing_rad += yaw_err_rad;
      o.vehicle.face_yaw_rad += yaw_err_rad;
      o.sensor.bearing_rad += yaw_err_rad;
    }
  });
  if (!e) return -1.0;
  return std::abs(wrap_angle_rad(e->pose.theta_rad - kTruth.theta_rad)) / e->heading_sigma_rad;
}

TEST(LocalizerRanging, TheMountsYawDoubtIsInTheInitialisingFixsHeadingSigma) {
  // No set of landmarks shows a camera turned on its mount: the fix's heading takes the whole
  // turn. Told the mount's doubt, the fix reports it; not told, it claims 0.03 deg (16 sigma off).
  const double err = deg_to_rad(0.5);
  const double told = initial_heading_sigmas(err, err), untold = initial_heading_sigmas(err, 0.0);
  std::printf("0.5 deg mount yaw error: %.2f sigma with the doubt, %.2f sigma without\n", told,
              untold);
  ASSERT_GT(told, 0.0);
  EXPECT_LT(told, 2.0);
  EXPECT_GT(untold, 3.0);
}

// Two landmarks 5-6 m away, 35 deg apart: one frame's fix is 20-100 mm across the baseline.
const std::vector<Landmark> kFarTwo = {{{5000.0, 1900.0}}, {{5200.0, -1400.0}}};

// The worst-axis position sigma of a noise-free frame's fix from lms at kTruth.
double single_fix_sd_mm(const std::vector<Landmark>& lms) {
  std::vector<ranging::Observation> in;
  std::mt19937 rng(1);
  for (const Landmark& l : lms) {
    localizer::RackObservation o = observe(kTruth, l, l.xy_mm, &rng);
    in.push_back(o.vehicle);
  }
  const ranging::FixResult f = ranging::fix_from_landmarks(in, ranging::FixOptions{});
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix2d> eig(f.cov.topLeftCorner<2, 2>());
  return f.status == ranging::FixStatus::kOk ? std::sqrt(eig.eigenvalues().maxCoeff()) : -1.0;
}

// Standing at kTruth for 1 s; every frame's landmarks also carry an error that repeats in all of
// them (range scale, bearing offset: a calibration's), drawn once, of which the observations say
// so (systematic_cov) when told. The first valid pose's NEES (3 dof), -1 when none.
double stacked_init_nees(const localizer::LocalizerConfig& c, const std::vector<Landmark>& lms,
                         bool told, std::mt19937* rng) {
  constexpr double kScaleSd = 0.002, kBearingSd = 1e-3;
  std::normal_distribution<double> n01(0.0, 1.0);
  const double scale = kScaleSd * n01(*rng), offset = kBearingSd * n01(*rng);
  const auto e = first_valid_estimate(c, lms, rng, [&](auto* obs) {
    for (localizer::RackObservation& o : *obs) {
      const Eigen::Matrix2d S =
          Eigen::Vector2d(std::pow(kScaleSd * o.vehicle.range_mm, 2), kBearingSd * kBearingSd)
              .asDiagonal();
      o.vehicle.range_mm *= 1.0 + scale;
      o.vehicle.bearing_rad += offset;
      o.vehicle.cov += S;
      if (told) o.vehicle.systematic_cov.topLeftCorner<2, 2>() = S;
    }
  });
  if (!e) return -1.0;
  const Eigen::Vector3d err(e->pose.x_mm - kTruth.x_mm, e->pose.y_mm - kTruth.y_mm,
                            wrap_angle_rad(e->pose.theta_rad - kTruth.theta_rad));
  return err.dot(e->cov.topLeftCorner<3, 3>().ldlt().solve(err));
}

TEST(LocalizerRanging, StackedFramesInitialiseWhereOneFrameIsTooUncertain) {
  const double sd = single_fix_sd_mm(kFarTwo);
  std::printf("one frame's fix: %.1f mm worst-axis sigma\n", sd);
  ASSERT_GT(sd, localizer::RangingAidConfig{}.init_position_sd_mm);  // the premise
  ASSERT_LT(sd, localizer::rack_fix_options().max_position_sd_mm);
  localizer::LocalizerConfig single = config();
  single.ranging.stack_fixes = false;
  std::mt19937 rng(21);
  localizer::Localizer alone(single);
  EXPECT_LT(stand(&alone, 0, 1000 * kMs, kFarTwo, true_map(kFarTwo), &rng).first_valid_ns, 0);

  localizer::Localizer stacked(config());
  const StandRun r = stand(&stacked, 0, 1000 * kMs, kFarTwo, true_map(kFarTwo), &rng);
  ASSERT_GE(r.first_valid_ns, 0) << "never localized";
  const fusion::PoseEstimate& e = r.last.estimate;
  const double err_mm = std::hypot(e.pose.x_mm - kTruth.x_mm, e.pose.y_mm - kTruth.y_mm);
  std::printf("stacked: localized after %.0f ms; at 1 s %.1f mm off, sigma %.1f mm\n",
              static_cast<double>(r.first_valid_ns) / 1e6, err_mm, e.position_sigma_mm);
  EXPECT_LE(r.first_valid_ns, 1000 * kMs);
  EXPECT_LT(err_mm, 3.0 * e.position_sigma_mm);
  EXPECT_EQ(stacked.stats().ranging_initialisations, 1u);
}

TEST(LocalizerRanging, AnErrorEveryFrameRepeatsIsNotAveragedAwayByTheStack) {
  // 40 vehicles switched on, each with its own calibration error: told which share of each
  // observation's covariance repeats, the stacked pose that initialises covers its error. The
  // limit is widened so that the stack can start the filter with that share in it, and it takes
  // twelve frames (0.73 s) so that the share would be averaged down if it were not told.
  localizer::LocalizerConfig c = config();
  c.ranging.init_position_sd_mm = 30.0;
  c.ranging.init_fixes = 12;
  int outside[2] = {0, 0}, localized[2] = {0, 0};
  for (int told = 0; told < 2; ++told) {
    std::mt19937 rng(77);
    for (int k = 0; k < 40; ++k) {
      const double nees = stacked_init_nees(c, kFarTwo, told == 1, &rng);
      if (nees < 0.0) continue;
      ++localized[told];
      outside[told] += nees > 14.16;
    }
  }
  std::printf("repeated errors, 40 runs: not told %d of %d outside 3 sigma, told %d of %d\n",
              outside[0], localized[0], outside[1], localized[1]);
  EXPECT_GE(localized[1], 36);
  EXPECT_LE(outside[1], 2);
  EXPECT_GT(outside[0], outside[1] + 4);
}

}  // namespace
}  // namespace agv
