// The observer's predicted windows (algo/src/ranging/observe_windows.cpp) on small rendered
// frames: the predicted corners, windows and shrunk windows against the full sweep, the predicted
// path, when a frame is swept whole and why, the interval's search, landmarks behind obstacles.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <vector>

#include "observe_scene.hpp"

namespace agv::ranging {
namespace {

using namespace observe_test;

TEST_F(RangingObserve, PredictedCornersAreTheRenderedOnes) {
  const LandmarkObserver obs(small_camera(), forward_mount(), scene_->site.wall_landmarks);
  PosePrior exact;
  exact.pose = kVehicle;
  exact.cov = Eigen::Vector3d(1.0, 1.0, 1e-8).asDiagonal();
  const WindowPlan plan = obs.plan_windows(&exact, 1);
  ASSERT_FALSE(plan.full_sweep) << sweep_reason_name(plan.reason);
  ASSERT_EQ(plan.predicted.size(), 4u);
  for (const PredictedLandmark& p : plan.predicted) {
    for (const sim::WallLandmarkTruth& wt : frame_->wall_landmarks) {
      if (wt.id != p.id) continue;
      for (std::size_t i = 0; i < 4; ++i) {
        EXPECT_NEAR(p.corners_px[i].x, wt.corners_px[i].x, 0.2) << p.id;
        EXPECT_NEAR(p.corners_px[i].y, wt.corners_px[i].y, 0.2) << p.id;
      }
    }
  }
}

TEST_F(RangingObserve, WindowsReadWhatTheFullSweepReads) {
  const LandmarkObserver obs(small_camera(), forward_mount(), scene_->site.wall_landmarks);
  const PosePrior prior = near_prior();
  const ObserveResult sweep = obs.observe(frame_->image);
  WindowOptions windows_only;  // the predicted path would read them all (next tests)
  windows_only.predicted_first = false;
  const ObserveResult windows = obs.observe(frame_->image, &prior, 1, windows_only);
  EXPECT_FALSE(windows.full_sweep);
  EXPECT_EQ(windows.reason, SweepReason::kWindows);
  EXPECT_GE(windows.windows_searched, 1u);
  EXPECT_TRUE(windows.refused.empty());
  expect_same_reads(sweep, windows);
}

TEST_F(RangingObserve, ShrunkWindowsReadWhatTheFullSweepReads) {
  // 1.2 m from the rack the tags span about 75 px: their windows are searched at half size and the
  // tags refined at full size from the scaled corners.
  const Pose2 near{2500.0, 650.0, 0.0};
  const sim::RenderResult frame = render(*scene_, near, 9);
  const LandmarkObserver obs(small_camera(), forward_mount(), scene_->site.wall_landmarks);
  PosePrior prior = near_prior();
  prior.pose = {near.x_mm - 20.0, near.y_mm + 25.0, near.theta_rad - deg_to_rad(0.2)};
  const WindowPlan plan = obs.plan_windows(&prior, 1);
  ASSERT_FALSE(plan.full_sweep) << sweep_reason_name(plan.reason);
  EXPECT_TRUE(std::any_of(plan.windows.begin(), plan.windows.end(),
                          [](const SearchWindow& w) { return w.decimation >= 2; }));
  const ObserveResult sweep = obs.observe(frame.image);
  EXPECT_GE(sweep.seen.size(), 2u);
  expect_same_reads(sweep, obs.observe(frame.image, plan));
}

TEST_F(RangingObserve, ATightPriorReadsOnThePredictedPathWithoutWindowSearch) {
  // A localized EKF's prior (5 mm, 0.05 deg, about one sigma off): every landmark's corners are
  // predicted within the detector's predicted search, read there, and no window is searched.
  const LandmarkObserver obs(small_camera(), forward_mount(), scene_->site.wall_landmarks);
  PosePrior tight;
  tight.pose = {kVehicle.x_mm + 4.0, kVehicle.y_mm - 5.0, kVehicle.theta_rad + deg_to_rad(0.04)};
  tight.cov = Eigen::Vector3d(25.0, 25.0, std::pow(deg_to_rad(0.05), 2)).asDiagonal();
  const WindowPlan plan = obs.plan_windows(&tight, 1);
  ASSERT_FALSE(plan.full_sweep) << sweep_reason_name(plan.reason);
  for (const PredictedLandmark& p : plan.predicted) EXPECT_TRUE(p.predicted_path) << p.id;
  const ObserveResult sweep = obs.observe(frame_->image);
  const ObserveResult r = obs.observe(frame_->image, plan);
  EXPECT_EQ(r.predicted_reads, 4u);
  EXPECT_EQ(r.windows_searched, 0u);
  expect_same_reads(sweep, r);
  // Off: every window searched by libapriltag, the same reads.
  WindowOptions off;
  off.predicted_first = false;
  const ObserveResult all = obs.observe(frame_->image, &tight, 1, off);
  EXPECT_EQ(all.predicted_reads, 0u);
  EXPECT_GE(all.windows_searched, 1u);
  expect_same_reads(sweep, all);
}

double corner_rms_px(const ObserveResult& r, const sim::RenderResult& truth) {
  double ss = 0.0;
  int n = 0;
  for (const LandmarkObservation& o : r.seen) {
    for (const sim::WallLandmarkTruth& wt : truth.wall_landmarks) {
      if (wt.id != o.id) continue;
      for (std::size_t i = 0; i < 4; ++i) {
        ss += std::pow(o.corners_px[i].x - wt.corners_px[i].x, 2) +
              std::pow(o.corners_px[i].y - wt.corners_px[i].y, 2);
        ++n;
      }
    }
  }
  return n > 0 ? std::sqrt(ss / n) : 1e9;
}

TEST_F(RangingObserve, ALooserPriorStillTriesThePredictedPathFirst) {
  // 30 mm / 0.3 deg claimed and about one sigma off: three corner sigmas reach beyond the
  // predicted search, yet the corners are within it. The landmarks are read there, no window is
  // searched, and the corners are as close to the rendered ones as the full sweep's.
  const LandmarkObserver obs(small_camera(), forward_mount(), scene_->site.wall_landmarks);
  const PosePrior loose = near_prior();
  const WindowPlan plan = obs.plan_windows(&loose, 1);
  ASSERT_FALSE(plan.full_sweep) << sweep_reason_name(plan.reason);
  const double search_px = overhead::TagDetectParams{}.predicted_search_px;
  for (const PredictedLandmark& p : plan.predicted) {
    EXPECT_GT(WindowOptions{}.sigma_count * p.corner_sigma_px, search_px) << p.id;
    EXPECT_TRUE(p.predicted_path) << p.id;
  }
  const ObserveResult r = obs.observe(frame_->image, plan);
  const ObserveResult sweep = obs.observe(frame_->image);
  EXPECT_EQ(r.predicted_reads, 4u);
  EXPECT_EQ(r.windows_searched, 0u);
  ASSERT_EQ(r.seen.size(), sweep.seen.size());
  EXPECT_LT(corner_rms_px(r, *frame_), corner_rms_px(sweep, *frame_) + 0.01);
  for (const LandmarkObservation& a : sweep.seen) {
    const auto b = std::find_if(r.seen.begin(), r.seen.end(),
                                [&](const LandmarkObservation& o) { return o.id == a.id; });
    ASSERT_NE(b, r.seen.end()) << a.id;
    EXPECT_NEAR(b->pose.range_mm, a.pose.range_mm, 0.15 * std::sqrt(a.pose.cov(0, 0))) << a.id;
  }
}

TEST_F(RangingObserve, APredictedReadThatFailsFallsBackToItsWindow) {
  // The prior claims 1 mm but is 70 mm off: the predicted path is tried and fails (the square
  // is beyond its search), and the landmarks are still read in their windows... when the window
  // reaches them; here the margin does (16 px and half the tag's side).
  const LandmarkObserver obs(small_camera(), forward_mount(), scene_->site.wall_landmarks);
  PosePrior wrong;
  wrong.pose = {kVehicle.x_mm, kVehicle.y_mm + 70.0, kVehicle.theta_rad};
  wrong.cov = Eigen::Vector3d(1.0, 1.0, 1e-8).asDiagonal();
  const WindowPlan plan = obs.plan_windows(&wrong, 1);
  ASSERT_FALSE(plan.full_sweep) << sweep_reason_name(plan.reason);
  const ObserveResult r = obs.observe(frame_->image, plan);
  EXPECT_LT(r.predicted_reads, r.seen.size());
  EXPECT_GE(r.windows_searched, 1u);
  EXPECT_TRUE(r.refused.empty());
  expect_same_reads(obs.observe(frame_->image), r);
}

TEST_F(RangingObserve, FullSweepWithoutAUsablePriorAndAtTheInterval) {
  const LandmarkObserver obs(small_camera(), forward_mount(), scene_->site.wall_landmarks);
  PosePrior prior = near_prior();
  EXPECT_EQ(obs.observe(frame_->image, nullptr, 1).reason, SweepReason::kNoPrior);
  ObserveOptions full_interval;
  full_interval.interval_sweep_decimate = 1.0;
  const LandmarkObserver swept(small_camera(), forward_mount(), scene_->site.wall_landmarks,
                               full_interval);
  const ObserveResult interval = swept.observe(frame_->image, &prior, 300);
  EXPECT_TRUE(interval.full_sweep);
  EXPECT_EQ(interval.reason, SweepReason::kInterval);
  EXPECT_EQ(interval.seen.size(), 4u);
  WindowOptions never;
  never.full_sweep_interval_frames = 0;
  EXPECT_EQ(obs.plan_windows(&prior, 300, never).reason, SweepReason::kWindows);
  WindowOptions small_share;
  small_share.max_window_share = 0.01;
  EXPECT_EQ(obs.plan_windows(&prior, 1, small_share).reason, SweepReason::kWindowsTooLarge);
  prior.cov(0, 0) = 400.0 * 400.0;
  EXPECT_EQ(obs.plan_windows(&prior, 1).reason, SweepReason::kUncertainPrior);
  prior = near_prior();
  prior.cov(2, 2) = std::pow(deg_to_rad(5.0), 2);
  EXPECT_EQ(obs.plan_windows(&prior, 1).reason, SweepReason::kUncertainPrior);
  prior.cov(2, 2) = std::nan("");
  const ObserveResult bad = obs.observe(frame_->image, &prior, 1);
  EXPECT_EQ(bad.reason, SweepReason::kUncertainPrior);
  EXPECT_EQ(bad.seen.size(), 4u);
  EXPECT_STREQ(sweep_reason_name(SweepReason::kUncertainPrior), "uncertain_prior");
}

TEST_F(RangingObserve, WindowsFollowThePriorNotTheFrame) {
  // A prior turned 25 degrees away (but claiming 0.3 degrees): its windows miss tags the frame
  // holds; only the search of the whole frame at the interval finds them.
  const LandmarkObserver obs(small_camera(), forward_mount(), scene_->site.wall_landmarks);
  PosePrior away = near_prior();
  away.pose.theta_rad += deg_to_rad(25.0);
  const ObserveResult r = obs.observe(frame_->image, &away, 1);
  EXPECT_FALSE(r.full_sweep);
  EXPECT_LT(r.seen.size(), 4u);
  // At the interval: the windows and the whole frame at quad decimation 2, every tag found and
  // refined as the full sweep does, without a full sweep.
  const ObserveResult at = obs.observe(frame_->image, &away, 300);
  EXPECT_FALSE(at.full_sweep);
  EXPECT_EQ(at.reason, SweepReason::kInterval);
  EXPECT_TRUE(at.refused.empty());
  expect_same_reads(obs.observe(frame_->image), at);
}

TEST(RangingObserveTable, ALandmarkBehindAnObstacleGetsNoWindow) {
  // A pillar between the camera and landmark 22: the renderer hides it, so does the plan once the
  // observer knows the site's obstacles.
  sim::SiteScene s = rack_scene();
  site::Obstacle pillar;
  pillar.id = "pillar";
  pillar.kind = site::ObstacleKind::kPillar;
  pillar.outline.vertices_mm = {{2400, 100}, {2600, 100}, {2600, 300}, {2400, 300}};
  pillar.height_mm = 3000.0;
  s.site.obstacles.push_back(pillar);
  const sim::RenderResult frame = render(s, kVehicle, 11);
  LandmarkObserver obs(small_camera(), forward_mount(), s.site.wall_landmarks);
  const ObserveResult sweep = obs.observe(frame.image);
  const auto has_22 = [](const auto& v) {
    return std::any_of(v.begin(), v.end(), [](const auto& o) { return o.id == 22u; });
  };
  EXPECT_FALSE(has_22(sweep.seen));
  EXPECT_EQ(sweep.seen.size(), 3u);
  PosePrior exact;
  exact.pose = kVehicle;
  exact.cov = Eigen::Vector3d(1.0, 1.0, 1e-8).asDiagonal();
  const WindowPlan blind = obs.plan_windows(&exact, 1);
  EXPECT_TRUE(has_22(blind.predicted));
  EXPECT_EQ(blind.hidden, 0u);
  obs.set_obstacles(s.site.obstacles);
  const WindowPlan plan = obs.plan_windows(&exact, 1);
  EXPECT_FALSE(has_22(plan.predicted));
  EXPECT_EQ(plan.hidden, 1u);
  EXPECT_EQ(plan.predicted.size(), blind.predicted.size() - 1);
  expect_same_reads(sweep, obs.observe(frame.image, plan));
}

}  // namespace
}  // namespace agv::ranging
