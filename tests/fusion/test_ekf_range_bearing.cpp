// The EKF's range-bearing aid (Ekf::add_range_bearing) on a simulated straight drive past two
// landmarks seen by a forward camera mounted off the reference point.
#include <gtest/gtest.h>

#include <Eigen/Cholesky>
#include <cmath>
#include <cstdint>
#include <limits>
#include <random>
#include <vector>

#include "agv/common/geometry.hpp"
#include "agv/fusion/ekf.hpp"
#include "agv/fusion/range_bearing.hpp"
#include "ekf_test_util.hpp"

using namespace agv;
using namespace agv::fusion;
using namespace agv::fusion::test;

namespace {

constexpr std::int64_t kOdomPeriodNs = 10 * kMs;
constexpr double kSigmaRangeMm = 10.0;
const double kSigmaBearingRad = deg_to_rad(0.2);
const Eigen::Vector2d kLandmarks[2] = {{5000.0, 800.0}, {5000.0, -800.0}};
const Eigen::Vector2d kSensorMm{300.0, 50.0};
const double kSensorYawRad = deg_to_rad(5.0);

// Truth: along +x at 1 m/s from the origin, heading 0.
Pose2 truth_at(std::int64_t t_ns) { return {1000.0 * static_cast<double>(t_ns) * 1e-9, 0.0, 0.0}; }

// What the camera measures of landmark lm from the true pose (noise when rng is given).
RangeBearingObs observe(const Pose2& pose, const Eigen::Vector2d& lm, std::mt19937* rng) {
  const double c = std::cos(pose.theta_rad), s = std::sin(pose.theta_rad);
  const Eigen::Vector2d sensor(pose.x_mm + c * kSensorMm.x() - s * kSensorMm.y(),
                               pose.y_mm + s * kSensorMm.x() + c * kSensorMm.y());
  const Eigen::Vector2d d = lm - sensor;
  RangeBearingObs o;
  o.landmark_xy_mm = lm;
  o.sensor_xy_mm = kSensorMm;
  o.sensor_yaw_rad = kSensorYawRad;
  o.range_mm = d.norm();
  o.bearing_rad = wrap_angle_rad(std::atan2(d.y(), d.x()) - pose.theta_rad - kSensorYawRad);
  if (rng) {
    std::normal_distribution<double> n(0.0, 1.0);
    o.range_mm += kSigmaRangeMm * n(*rng);
    o.bearing_rad += kSigmaBearingRad * n(*rng);
  }
  o.R = Eigen::Vector2d(kSigmaRangeMm * kSigmaRangeMm, kSigmaBearingRad * kSigmaBearingRad)
            .asDiagonal();
  return o;
}

// A filter whose noise model is exactly the simulation's: no calibration states, no process
// noise beyond the odometry samples' own, no covariance floors.
EkfConfig consistent_config() {
  EkfConfig c;
  c.odometry.estimate_calibration = false;
  c.core.along_track_sigma_mm_per_sqrt_m = 0.0;
  c.core.cross_track_sigma_mm_per_sqrt_m = 0.0;
  c.core.heading_sigma_rad_per_sqrt_m = 0.0;
  c.core.heading_drift_sigma_rad_per_sqrt_s = 0.0;
  c.core.turn_heading_sigma_rad_per_sqrt_rad = 0.0;
  c.fix.floor_sigma_mm = 0.0;
  c.fix.floor_sigma_rad = 0.0;
  c.range_bearing.range_floor_sigma_mm = 0.0;
  c.range_bearing.bearing_floor_sigma_rad = 0.0;
  return c;
}

struct OdomSample {
  std::int64_t t_ns;
  double v_mps, omega_radps;
};

// Period-mean odometry samples of the truth with the configured sample noise, 0..duration.
std::vector<OdomSample> odometry(const EkfConfig& c, std::int64_t duration_ns, std::mt19937* rng) {
  std::normal_distribution<double> n(0.0, 1.0);
  std::vector<OdomSample> out;
  for (std::int64_t t = 0; t <= duration_ns; t += kOdomPeriodNs)
    out.push_back(
        {t, 1.0 + c.odometry.v_sigma_mps * n(*rng), c.odometry.omega_sigma_radps * n(*rng)});
  return out;
}

Eigen::Matrix3d prior_cov(double sigma_mm, double sigma_deg) {
  return Eigen::Vector3d(sigma_mm * sigma_mm, sigma_mm * sigma_mm,
                         deg_to_rad(sigma_deg) * deg_to_rad(sigma_deg))
      .asDiagonal();
}

// Drives the samples from a prior at `start` (covariance P0), observing both landmarks every
// 100 ms (none when with_range_bearing is false).
void drive(Ekf* ekf, const std::vector<OdomSample>& odom, const Pose2& start,
           const Eigen::Matrix3d& P0, bool with_range_bearing, std::mt19937* rng) {
  ASSERT_TRUE(ekf->add_odometry(odom[0].t_ns, odom[0].v_mps, odom[0].omega_radps));
  ASSERT_TRUE(ekf->set_pose(0, start, P0));
  for (std::size_t k = 1; k < odom.size(); ++k) {
    ASSERT_TRUE(ekf->add_odometry(odom[k].t_ns, odom[k].v_mps, odom[k].omega_radps));
    if (!with_range_bearing || k % 10 != 0) continue;
    for (const Eigen::Vector2d& lm : kLandmarks)
      ekf->add_range_bearing(odom[k].t_ns, observe(truth_at(odom[k].t_ns), lm, rng));
  }
}

Eigen::Vector3d error(const PoseEstimate& e, const Pose2& truth) {
  return {e.pose.x_mm - truth.x_mm, e.pose.y_mm - truth.y_mm,
          wrap_angle_rad(e.pose.theta_rad - truth.theta_rad)};
}

}  // namespace

TEST(FusionRangeBearing, ConvergesFromAPerturbedPriorWithTwoLandmarks) {
  const EkfConfig c = consistent_config();
  std::mt19937 rng(7);
  const std::vector<OdomSample> odom = odometry(c, 2 * kS, &rng);
  const Pose2 start{60.0, -40.0, deg_to_rad(1.5)};  // truth is the origin
  const Eigen::Matrix3d P0 = prior_cov(100.0, 2.0);
  const Pose2 truth = truth_at(2 * kS);

  Ekf dead_reckoning(c);
  drive(&dead_reckoning, odom, start, P0, false, &rng);
  const Eigen::Vector3d e0 = error(dead_reckoning.estimate_at(2 * kS), truth);
  EXPECT_GT(e0.head<2>().norm(), 60.0);  // odometry alone keeps the prior's error (and adds)

  Ekf ekf(c);
  drive(&ekf, odom, start, P0, true, &rng);
  EXPECT_EQ(ekf.counters().range_bearing_fused, 40u);
  EXPECT_EQ(ekf.counters().range_bearing_rejected_gate, 0u);
  const PoseEstimate e = ekf.estimate_at(2 * kS);
  ASSERT_TRUE(e.valid);
  const Eigen::Vector3d err = error(e, truth);
  EXPECT_LT(err.head<2>().norm(), 10.0) << err.transpose();
  EXPECT_LT(std::abs(err(2)), deg_to_rad(0.3));
  for (int i = 0; i < 3; ++i) EXPECT_LT(std::abs(err(i)), 3.0 * std::sqrt(e.cov(i, i))) << i;
  EXPECT_LT(e.position_sigma_mm, 10.0);  // and it knows it
}

TEST(FusionRangeBearing, GateRejectsALandmarkMappedHalfAMetreOff) {
  const EkfConfig c = consistent_config();
  std::mt19937 rng(11);
  const std::vector<OdomSample> odom = odometry(c, 2 * kS, &rng);
  Ekf ekf(c);
  drive(&ekf, odom, {20.0, 10.0, 0.0}, prior_cov(30.0, 1.0), true, &rng);
  const std::int64_t t = 2 * kS;
  const PoseEstimate before = ekf.estimate_at(t);
  ASSERT_LT(before.position_sigma_mm, 10.0);  // confident

  // Seen where the landmark really is, reported with a map position 0.5 m off.
  RangeBearingObs moved = observe(truth_at(t), kLandmarks[0], nullptr);
  moved.landmark_xy_mm.y() += 500.0;
  EXPECT_EQ(ekf.add_range_bearing(t, moved), FixOutcome::kRejectedGate);
  EXPECT_EQ(ekf.counters().range_bearing_rejected_gate, 1u);
  const PoseEstimate after = ekf.estimate_at(t);
  EXPECT_EQ(after.pose.x_mm, before.pose.x_mm);
  EXPECT_EQ(after.pose.y_mm, before.pose.y_mm);
  EXPECT_EQ(after.pose.theta_rad, before.pose.theta_rad);

  // The same observation with the right map position passes.
  EXPECT_EQ(ekf.add_range_bearing(t, observe(truth_at(t), kLandmarks[0], nullptr)),
            FixOutcome::kFused);
}

TEST(FusionRangeBearing, LateObservationGivesTheInOrderResult) {
  const EkfConfig c;  // the defaults: calibration states, process noise, floors
  std::mt19937 rng(3);
  const std::vector<OdomSample> odom = odometry(c, 1500 * kMs, &rng);
  const std::int64_t t_obs = 1000 * kMs, t_late = 1300 * kMs;
  RangeBearingObs obs[2];
  for (int i = 0; i < 2; ++i) obs[i] = observe(truth_at(t_obs), kLandmarks[i], &rng);

  Ekf in_order(c), late(c);
  for (Ekf* ekf : {&in_order, &late}) {
    ASSERT_TRUE(ekf->add_odometry(0, odom[0].v_mps, odom[0].omega_radps));
    ASSERT_TRUE(ekf->set_pose(0, {30.0, -20.0, deg_to_rad(0.5)}, prior_cov(50.0, 1.0)));
  }
  for (std::size_t k = 1; k < odom.size(); ++k) {
    for (Ekf* ekf : {&in_order, &late})
      ASSERT_TRUE(ekf->add_odometry(odom[k].t_ns, odom[k].v_mps, odom[k].omega_radps));
    for (int i = 0; i < 2; ++i) {
      if (odom[k].t_ns == t_obs) {
        EXPECT_EQ(in_order.add_range_bearing(t_obs, obs[i]), FixOutcome::kFused);
      }
      if (odom[k].t_ns == t_late) {
        EXPECT_EQ(late.add_range_bearing(t_obs, obs[i]), FixOutcome::kFused);
      }
    }
  }
  EXPECT_EQ(in_order.counters().range_bearing_delayed, 0u);
  EXPECT_EQ(late.counters().range_bearing_delayed, 2u);
  const PoseEstimate a = in_order.estimate_at(1500 * kMs), b = late.estimate_at(1500 * kMs);
  ASSERT_TRUE(a.valid && b.valid);
  EXPECT_NEAR(a.pose.x_mm, b.pose.x_mm, 1e-9);
  EXPECT_NEAR(a.pose.y_mm, b.pose.y_mm, 1e-9);
  EXPECT_NEAR(a.pose.theta_rad, b.pose.theta_rad, 1e-12);
  EXPECT_LE((a.cov - b.cov).cwiseAbs().maxCoeff(), 1e-9);
  // The observations moved the estimate (else the comparison proves nothing).
  Ekf none(c);
  ASSERT_TRUE(none.add_odometry(0, odom[0].v_mps, odom[0].omega_radps));
  ASSERT_TRUE(none.set_pose(0, {30.0, -20.0, deg_to_rad(0.5)}, prior_cov(50.0, 1.0)));
  for (std::size_t k = 1; k < odom.size(); ++k)
    ASSERT_TRUE(none.add_odometry(odom[k].t_ns, odom[k].v_mps, odom[k].omega_radps));
  EXPECT_GT(std::abs(none.estimate_at(1500 * kMs).pose.y_mm - a.pose.y_mm), 5.0);

  // Older than max_delay_ns behind the newest event: refused.
  RangeBearingObs old = observe(truth_at(900 * kMs), kLandmarks[0], nullptr);
  EXPECT_EQ(late.add_range_bearing(900 * kMs, old), FixOutcome::kRejectedTooOld);
  EXPECT_EQ(late.counters().range_bearing_rejected_too_old, 1u);
}

TEST(FusionRangeBearing, NeesOfAMonteCarloIsWithinTheChiSquareBounds) {
  // 200 runs, each from a prior drawn around the truth with the covariance the filter is told,
  // 1.5 s of noisy odometry and range-bearing observations. The mean NEES of the pose (3 dof)
  // at the end is chi2(3 N) / N for a consistent filter; two-sided 99 % bounds
  // (Wilson-Hilferty).
  const EkfConfig c = consistent_config();
  constexpr int kRuns = 200;
  const Eigen::Matrix3d P0 = prior_cov(30.0, 1.0);
  const Eigen::Matrix3d L0 = P0.llt().matrixL();
  double nees_sum = 0.0;
  for (int run = 0; run < kRuns; ++run) {
    std::mt19937 rng(1000 + static_cast<unsigned>(run));
    std::normal_distribution<double> n(0.0, 1.0);
    const Eigen::Vector3d d0 = L0 * Eigen::Vector3d(n(rng), n(rng), n(rng));
    const std::vector<OdomSample> odom = odometry(c, 1500 * kMs, &rng);
    Ekf ekf(c);
    drive(&ekf, odom, {d0(0), d0(1), d0(2)}, P0, true, &rng);
    const PoseEstimate e = ekf.estimate_at(1500 * kMs);
    ASSERT_TRUE(e.valid);
    const Eigen::Vector3d err = error(e, truth_at(1500 * kMs));
    const Eigen::Matrix3d P = e.cov.topLeftCorner<3, 3>();
    nees_sum += err.dot(P.llt().solve(err));
  }
  const double k = 3.0 * kRuns, z = 2.576;
  const double lo = k * std::pow(1.0 - 2.0 / (9.0 * k) - z * std::sqrt(2.0 / (9.0 * k)), 3) / kRuns;
  const double hi = k * std::pow(1.0 - 2.0 / (9.0 * k) + z * std::sqrt(2.0 / (9.0 * k)), 3) / kRuns;
  const double nees = nees_sum / kRuns;
  EXPECT_GT(nees, lo);
  EXPECT_LT(nees, hi);
  RecordProperty("mean_nees", std::to_string(nees));
}

TEST(FusionRangeBearing, NeverInitialisesAndRefusesBadInput) {
  Ekf ekf{EkfConfig{}};
  ASSERT_TRUE(ekf.add_odometry(0, 1.0, 0.0));
  const RangeBearingObs good = observe(truth_at(0), kLandmarks[0], nullptr);
  EXPECT_EQ(ekf.add_range_bearing(0, good), FixOutcome::kRejectedNotTracking);
  EXPECT_FALSE(ekf.initialised());
  EXPECT_FALSE(ekf.estimate_at(0).valid);
  EXPECT_EQ(ekf.counters().range_bearing_rejected_not_initialised, 1u);

  ASSERT_TRUE(ekf.set_pose(0, truth_at(0), prior_cov(5.0, 0.2)));
  RangeBearingObs bad = good;
  bad.range_mm = std::numeric_limits<double>::quiet_NaN();
  EXPECT_EQ(ekf.add_range_bearing(0, bad), FixOutcome::kRejectedInvalid);
  bad = good;
  bad.range_mm = 0.0;
  EXPECT_EQ(ekf.add_range_bearing(0, bad), FixOutcome::kRejectedInvalid);
  bad = good;
  bad.R(0, 1) = 1.0;  // not symmetric
  EXPECT_EQ(ekf.add_range_bearing(0, bad), FixOutcome::kRejectedInvalid);
  bad = good;
  bad.R(1, 1) = -1e-6;  // not positive definite
  EXPECT_EQ(ekf.add_range_bearing(0, bad), FixOutcome::kRejectedInvalid);
  bad = good;
  bad.landmark_xy_mm = truth_at(0).x_mm * Eigen::Vector2d::UnitX() + kSensorMm;  // at the sensor
  EXPECT_EQ(ekf.add_range_bearing(0, bad), FixOutcome::kRejectedInvalid);
  bad = good;
  bad.common_bearing_sigma_rad = -1e-3;
  EXPECT_EQ(ekf.add_range_bearing(0, bad), FixOutcome::kRejectedInvalid);
  bad.common_bearing_sigma_rad = std::numeric_limits<double>::infinity();
  EXPECT_EQ(ekf.add_range_bearing(0, bad), FixOutcome::kRejectedInvalid);
  bad = good;
  bad.R_systematic = 2.0 * good.R;  // more repeats than there is
  EXPECT_EQ(ekf.add_range_bearing(0, bad), FixOutcome::kRejectedInvalid);
  bad.R_systematic = good.R;
  bad.R_systematic(0, 0) = std::numeric_limits<double>::quiet_NaN();
  EXPECT_EQ(ekf.add_range_bearing(0, bad), FixOutcome::kRejectedInvalid);
  EXPECT_EQ(ekf.counters().range_bearing_rejected_invalid, 9u);
  EXPECT_EQ(ekf.add_range_bearing(0, good), FixOutcome::kFused);
  EXPECT_EQ(ekf.counters().range_bearing_fused, 1u);
}

// ---- A heading step the wheels did not see, then one landmark at a time ----

namespace {

constexpr std::int64_t kStepNs = 1000 * kMs;
constexpr std::int64_t kStepDriveNs = 2500 * kMs;

// A straight drive of kStepDriveNs from truth_at(0) with a 30 mm / 1 deg prior: every odometry
// sample fused, frame(t_ns, k) called at every 10th (100 ms).
template <typename Frame>
void drive_frames(Ekf* ekf, const EkfConfig& c, std::mt19937* rng, Frame frame) {
  const std::vector<OdomSample> odom = odometry(c, kStepDriveNs, rng);
  EXPECT_TRUE(ekf->add_odometry(odom[0].t_ns, odom[0].v_mps, odom[0].omega_radps));
  EXPECT_TRUE(ekf->set_pose(0, truth_at(0), prior_cov(30.0, 1.0)));
  for (std::size_t k = 1; k < odom.size(); ++k) {
    EXPECT_TRUE(ekf->add_odometry(odom[k].t_ns, odom[k].v_mps, odom[k].omega_radps));
    if (k % 10 == 0) frame(odom[k].t_ns, k);
  }
}

// The truth turned by step_rad at kStepNs about where it is then, straight on afterwards.
Pose2 stepped_truth(std::int64_t t_ns, double step_rad) {
  if (t_ns <= kStepNs) return truth_at(t_ns);
  const Pose2 p0 = truth_at(kStepNs);
  const double d_mm = 1000.0 * static_cast<double>(t_ns - kStepNs) * 1e-9;
  return {p0.x_mm + d_mm * std::cos(step_rad), p0.y_mm + d_mm * std::sin(step_rad), step_rad};
}

struct StepResult {
  PoseEstimate end;
  Pose2 truth_end;
  Ekf::Counters counters;
};

// Odometry of a straight drive (the wheels do not see the step); both landmarks every 100 ms
// before the step, then one per frame: kLandmarks[0] reported at its map position plus
// map_offset, and, when with_good, kLandmarks[1] (right) after it in the same frame; when
// alternate, kLandmarks[0] and [1] in turns, one per frame (both right).
StepResult drive_step(const EkfConfig& c, double step_rad, const Eigen::Vector2d& map_offset,
                      bool with_good, bool alternate = false) {
  std::mt19937 rng(5);
  Ekf ekf(c);
  drive_frames(&ekf, c, &rng, [&](std::int64_t t, std::size_t k) {
    const Pose2 truth = stepped_truth(t, step_rad);
    if (t <= kStepNs) {
      for (const Eigen::Vector2d& lm : kLandmarks)
        ekf.add_range_bearing(t, observe(truth, lm, &rng));
      return;
    }
    if (alternate) {
      ekf.add_range_bearing(t, observe(truth, kLandmarks[(k / 10) % 2], &rng));
      return;
    }
    RangeBearingObs first = observe(truth, kLandmarks[0], &rng);
    first.landmark_xy_mm += map_offset;
    ekf.add_range_bearing(t, first);
    if (with_good) ekf.add_range_bearing(t, observe(truth, kLandmarks[1], &rng));
  });
  return {ekf.estimate_at(kStepDriveNs), stepped_truth(kStepDriveNs, step_rad), ekf.counters()};
}

// Largest error over sigma of x, y and heading.
double worst_sigmas(const StepResult& r) {
  const Eigen::Vector3d err = error(r.end, r.truth_end);
  double worst = 0.0;
  for (int i = 0; i < 3; ++i)
    worst = std::max(worst, std::abs(err(i)) / std::sqrt(r.end.cov(i, i)));
  return worst;
}

}  // namespace

TEST(FusionRangeBearing, AnUnseenHeadingStepIsRecoveredFromOneLandmarkAtATime) {
  // 1 s of two landmarks make the heading sigma small; then the vehicle turns by 2 deg, the
  // wheels do not see it, and the camera sees one landmark per frame, the two in turns.
  const EkfConfig c = consistent_config();
  const StepResult r = drive_step(c, deg_to_rad(2.0), Eigen::Vector2d::Zero(), false, true);
  const Eigen::Vector3d err = error(r.end, r.truth_end);
  EXPECT_EQ(r.counters.range_bearing_unseen_slips, 1u);
  EXPECT_EQ(r.counters.range_bearing_rejected_gate, 1u);  // the first, awaiting a second
  EXPECT_LT(worst_sigmas(r), 3.0) << err.transpose();
  EXPECT_LT(std::abs(err(2)), deg_to_rad(0.3));
  // Without the rule every landmark after the step is gated and the confident pose ends outside
  // 3 sigma.
  EkfConfig off = c;
  off.recovery.unseen_slip_max_rad = 0.0;
  const StepResult o = drive_step(off, deg_to_rad(2.0), Eigen::Vector2d::Zero(), false, true);
  EXPECT_EQ(o.counters.range_bearing_unseen_slips, 0u);
  EXPECT_EQ(o.counters.range_bearing_rejected_gate, 15u);
  EXPECT_GT(worst_sigmas(o), 3.0);
}

TEST(FusionRangeBearing, AWrongMapEntryIsNotTakenForAnUnseenSlip) {
  const EkfConfig c = consistent_config();
  for (int k = 0; k < 8; ++k) {
    const double a = k * M_PI / 4.0;
    const Eigen::Vector2d off(500.0 * std::cos(a), 500.0 * std::sin(a));
    // Among a correct landmark fused in every frame it never counts as an unseen slip.
    const StepResult with_good = drive_step(c, 0.0, off, true);
    EXPECT_EQ(with_good.counters.range_bearing_unseen_slips, 0u) << "direction " << k;
    EXPECT_LT(worst_sigmas(with_good), 3.0) << "direction " << k;
    // Alone frame after frame it fits a heading change every time, but is one landmark: gated.
    const StepResult alone = drive_step(c, 0.0, off, false);
    EXPECT_EQ(alone.counters.range_bearing_unseen_slips, 0u) << "direction " << k;
    EXPECT_EQ(alone.counters.range_bearing_rejected_gate, 15u) << "direction " << k;
    EXPECT_LT(worst_sigmas(alone), 3.0) << "direction " << k;
  }
}

TEST(FusionRangeBearing, AnUnconfirmedHeadingStepIsReportedButNotFused) {
  // A 2 deg step the wheels do not see, then one landmark per frame, always the same: it fits
  // the change every frame but never confirms it. The state stays where the filter has it;
  // the reported sigma covers the change.
  const EkfConfig c = consistent_config();
  const StepResult r = drive_step(c, deg_to_rad(2.0), Eigen::Vector2d::Zero(), false);
  EXPECT_EQ(r.counters.range_bearing_unseen_slips, 0u);
  EXPECT_EQ(r.counters.range_bearing_rejected_gate, 15u);
  EXPECT_LT(worst_sigmas(r), 3.0) << error(r.end, r.truth_end).transpose();
  EkfConfig off = c;
  off.recovery.unseen_slip_max_rad = 0.0;
  const StepResult o = drive_step(off, deg_to_rad(2.0), Eigen::Vector2d::Zero(), false);
  EXPECT_EQ(o.counters.range_bearing_rejected_gate, 15u);
  EXPECT_GT(worst_sigmas(o), 3.0);
  EXPECT_DOUBLE_EQ(r.end.pose.x_mm, o.end.pose.x_mm);
  EXPECT_DOUBLE_EQ(r.end.pose.y_mm, o.end.pose.y_mm);
  EXPECT_DOUBLE_EQ(r.end.pose.theta_rad, o.end.pose.theta_rad);
}

TEST(FusionRangeBearing, FramesOfOneMapErrorDoNotShrinkTheSigmaAlongTheSightBelowTheFloor) {
  // Both map entries 1.5 mm off along the line of sight (a survey error, or the print proud of
  // its face), every frame exact otherwise and precise (0.5 mm): the error is common to all
  // frames, and however many are fused the reported sigma along the sight must cover it.
  EkfConfig c = consistent_config();
  c.range_bearing.range_floor_sigma_mm = 2.0;
  std::mt19937 rng(3);
  Ekf ekf(c);
  drive_frames(&ekf, c, &rng, [&](std::int64_t t, std::size_t) {
    for (const Eigen::Vector2d& lm : kLandmarks) {
      RangeBearingObs o = observe(truth_at(t), lm, nullptr);
      o.landmark_xy_mm.x() += 1.5;
      o.R = Eigen::Vector2d(0.25, 1e-8).asDiagonal();
      ekf.add_range_bearing(t, o);
    }
  });
  const PoseEstimate e = ekf.estimate_at(kStepDriveNs);
  const Eigen::Vector3d err = error(e, truth_at(kStepDriveNs));
  EXPECT_EQ(ekf.counters().range_bearing_rejected_gate, 0u);
  EXPECT_GT(std::sqrt(e.cov(0, 0)), 0.8);
  EXPECT_LT(std::abs(err(0)), 3.0 * std::sqrt(e.cov(0, 0))) << err.transpose();
}

TEST(FusionRangeBearing, ASensorsYawErrorIsNotAveragedAwayOverFrames) {
  // The camera is mounted 0.5 deg off the yaw it is calibrated at, and says so
  // (common_bearing_sigma_rad 0.3 deg); every frame is exact otherwise and precise. Fused as
  // independent the frames would drive the heading sigma far below the turn they all share.
  const double mount_error_rad = deg_to_rad(0.5), common_sigma_rad = deg_to_rad(0.3);
  auto run = [&](double told_sigma_rad, double prior_deg, double yaw_error_rad) {
    EkfConfig c = consistent_config();
    std::mt19937 rng(5);
    Ekf ekf(c);
    ASSERT_TRUE(ekf.add_odometry(0, 1.0, 0.0));
    ASSERT_TRUE(ekf.set_pose(0, truth_at(0), prior_cov(20.0, prior_deg)));
    for (std::int64_t t = kOdomPeriodNs; t <= 2 * kS; t += kOdomPeriodNs) {
      ASSERT_TRUE(ekf.add_odometry(t, 1.0, 0.0));
      if (t % (100 * kMs) != 0) continue;
      for (const Eigen::Vector2d& lm : kLandmarks) {
        RangeBearingObs o = observe(truth_at(t), lm, nullptr);
        o.bearing_rad -= yaw_error_rad;
        o.R = Eigen::Vector2d(1.0, 1e-8).asDiagonal();
        o.common_bearing_sigma_rad = told_sigma_rad;
        ekf.add_range_bearing(t, o);
      }
    }
    const PoseEstimate e = ekf.estimate_at(2 * kS);
    const double err_rad = std::abs(error(e, truth_at(2 * kS))(2));
    if (told_sigma_rad == 0.0) {
      EXPECT_GT(err_rad, 10.0 * std::sqrt(e.cov(2, 2)));  // what the floor is for
    } else if (prior_deg > rad_to_deg(told_sigma_rad)) {
      EXPECT_NEAR(std::sqrt(e.cov(2, 2)), told_sigma_rad, 1e-3 * told_sigma_rad);
      EXPECT_LT(err_rad, 3.0 * std::sqrt(e.cov(2, 2)));
    } else {
      // A heading already better than the sensor's yaw is not made better by it.
      EXPECT_EQ(ekf.counters().range_bearing_fused, 40u);
      EXPECT_GE(std::sqrt(e.cov(2, 2)), 0.999 * deg_to_rad(prior_deg));
    }
  };
  run(0.0, 2.0, mount_error_rad);
  run(common_sigma_rad, 2.0, mount_error_rad);
  run(common_sigma_rad, 0.1, 0.0);
}

TEST(FusionRangeBearing, ARepeatedRangeAndBearingErrorIsNotAveragedAwayOverFrames) {
  // Every frame's ranges 1 % long and bearings 1 mrad off alike for each landmark in turn (a
  // focal length and a lens calibration slightly off), the frames otherwise precise; the
  // observations say which share of R repeats. Not told, the frames shrink the reported position
  // sigma below that error; told, the reported covariance keeps it, the filter's own state is
  // the same (the frames' noise still averages), and a floor fix is weighed against it and
  // clears it.
  struct Run {
    PoseEstimate end, after_fix;
    double nees = 0.0;
    FixOutcome floor_fix = FixOutcome::kRejectedInvalid;
  };
  auto run = [](bool told) {
    EkfConfig c = consistent_config();
    Ekf ekf(c);
    std::mt19937 rng(9);
    drive_frames(&ekf, c, &rng, [&](std::int64_t t, std::size_t) {
      for (int i = 0; i < 2; ++i) {
        RangeBearingObs o = observe(truth_at(t), kLandmarks[i], nullptr);
        o.range_mm *= 1.01;
        o.bearing_rad += i == 0 ? 1e-3 : -1e-3;
        const Eigen::Matrix2d S =
            Eigen::Vector2d(std::pow(0.01 * o.range_mm, 2), 1e-6).asDiagonal();
        o.R = Eigen::Vector2d(0.25, 1e-8).asDiagonal();
        o.R += S;
        if (told) o.R_systematic = S;
        ekf.add_range_bearing(t, o);
      }
    });
    Run r;
    r.end = ekf.estimate_at(kStepDriveNs);
    const Eigen::Vector2d err = error(r.end, truth_at(kStepDriveNs)).head<2>();
    r.nees = err.dot(r.end.cov.topLeftCorner<2, 2>().ldlt().solve(err));
    r.floor_fix = ekf.add_fix(kStepDriveNs, truth_at(kStepDriveNs), prior_cov(0.5, 0.05), true);
    r.after_fix = ekf.estimate_at(kStepDriveNs);
    return r;
  };
  const Run untold = run(false), told = run(true);
  std::printf("position NEES (2 dof): not told %.1f, told %.2f; sigma %.2f / %.2f mm\n",
              untold.nees, told.nees, untold.end.position_sigma_mm, told.end.position_sigma_mm);
  EXPECT_GT(untold.nees, 11.83);  // outside 3 sigma
  EXPECT_LT(told.nees, 11.83);
  EXPECT_EQ(told.end.pose.x_mm, untold.end.pose.x_mm);
  EXPECT_EQ(told.end.pose.y_mm, untold.end.pose.y_mm);
  EXPECT_EQ(told.end.pose.theta_rad, untold.end.pose.theta_rad);
  EXPECT_GT(told.end.position_sigma_mm, 2.0 * untold.end.position_sigma_mm);
  EXPECT_EQ(told.floor_fix, FixOutcome::kFused);
  EXPECT_LT(told.after_fix.position_sigma_mm, 1.0);
  EXPECT_LT(error(told.after_fix, truth_at(kStepDriveNs)).head<2>().norm(), 1.0);
}
