// Large maps (docs/design/large_maps.md): with the spatial index the identity gate decides as the
// scan of the whole map does, and the tracking windows of a 60 000-landmark map visit a handful of
// landmarks per frame (counted, not timed: a regression to a per-frame scan of the map fails).
#include <gtest/gtest.h>

#include <cmath>
#include <random>
#include <vector>

#include "../support/prediction.hpp"
#include "agv/common/landmark_index.hpp"
#include "agv/vision/map_identity.hpp"
#include "agv/vision/tracking.hpp"

using namespace agv;
using namespace agv::vision;

namespace {

LandmarkMap grid_map(int side, double spacing_mm) {
  LandmarkMap m;
  std::uint32_t id = 1;
  for (int r = 0; r < side; ++r) {
    for (int c = 0; c < side; ++c, ++id) {
      m.entries[id] = {id, {c * spacing_mm, r * spacing_mm, deg_to_rad(90.0 * (id % 4))}};
    }
  }
  return m;
}

using testsupport::predict;

}  // namespace

// Random maps, predictions from tight to lost (heading sigma up to 10 deg, where no radius bounds
// the gate and the index is not used) and measurements near and between landmarks. 600
// landmarks on 10 m x 10 m: the density of a tight grid (6 per square metre) with the reference
// full scan cheap enough for the sanitizer builds (1500 on 16 m x 16 m took 98 s under ASan).
TEST(LargeMap, IdentityGateWithTheIndexDecidesAsTheFullScan) {
  constexpr std::uint32_t kLandmarks = 600;
  std::mt19937_64 rng(11);
  std::uniform_real_distribution<double> u(-5000.0, 5000.0), a(-kPi, kPi);
  LandmarkMap map;
  for (std::uint32_t id = 1; id <= kLandmarks; ++id) {
    map.entries[id] = {id, {u(rng), u(rng), a(rng)}};
  }
  const LandmarkIndex index(map);
  const MapIdentityConfig cfg;
  const std::array<bool, 4> all{true, true, true, true}, one{true, false, false, false};
  std::normal_distribution<double> n(0.0, 1.0);
  std::uniform_int_distribution<std::uint32_t> pick(1, kLandmarks);
  const double sigmas_mm[] = {0.5, 3.0, 20.0, 150.0, 800.0};
  const double sigmas_deg[] = {0.05, 0.5, 2.0, 6.0, 10.0};
  int accepted = 0;
  // 500 trials: every sigma pair 20 times (2000 took 40-58 s under ASan+UBSan).
  for (int t = 0; t < 500; ++t) {
    const double s_mm = sigmas_mm[t % 5], s_deg = sigmas_deg[(t / 5) % 5];
    const LandmarkMapEntry& e = map.entries.at(pick(rng));
    const Pose2 v_true{e.pose.x_mm + 100.0 * n(rng), e.pose.y_mm + 100.0 * n(rng), a(rng)};
    const Pose2 v_pred{v_true.x_mm + s_mm * n(rng), v_true.y_mm + s_mm * n(rng),
                       v_true.theta_rad + deg_to_rad(s_deg) * n(rng)};
    const Pose2 l = compose(inverse(v_true), e.pose);
    const Eigen::Matrix3d meas = Eigen::Vector3d(0.05, 0.05, 1e-4).asDiagonal();
    const auto& turns = t % 2 ? all : one;
    const Prediction pred = predict(v_pred, s_mm, s_deg);
    const auto full = gate_identity({l.x_mm, l.y_mm}, l.theta_rad, meas, turns, pred, map, cfg);
    const auto fast =
        gate_identity({l.x_mm, l.y_mm}, l.theta_rad, meas, turns, pred, map, cfg, &index);
    ASSERT_EQ(full.result, fast.result) << t;
    ASSERT_EQ(full.id, fast.id) << t;
    ASSERT_EQ(full.turn, fast.turn) << t;
    ASSERT_EQ(full.d2_best, fast.d2_best) << t;
    if (full.d2_second <= cfg.clear_chi2) {
      ASSERT_EQ(full.d2_second, fast.d2_second) << t;
    }
    accepted += full.result == MapIdentityResult::kAccepted;
  }
  EXPECT_GT(accepted, 50);  // the comparison covers accepted decisions, not only refusals
}

TEST(LargeMap, IdentitySearchRadiusGrowsWithTheUncertaintyAndIsUnboundedWhenLost) {
  const Eigen::Matrix3d meas = Eigen::Vector3d(0.05, 0.05, 1e-4).asDiagonal();
  const Vec2 c{100.0, 0.0};
  const double r_tight = identity_search_radius_mm(c, meas, predict({}, 3.0, 0.5), 60.0);
  const double r_loose = identity_search_radius_mm(c, meas, predict({}, 100.0, 2.0), 60.0);
  EXPECT_LT(r_tight, 50.0);
  EXPECT_GT(r_loose, r_tight);
  EXPECT_TRUE(std::isinf(identity_search_radius_mm(c, meas, predict({}, 3.0, 8.0), 60.0)));
}

// A trusted prediction over a 60 000-landmark grid: the windows come from a few landmarks of the
// index, the same count as on a 1 000-landmark grid.
TEST(LargeMap, TrackingWindowsVisitTheNeighbourhoodNotTheMap) {
  const CameraModel cam = CameraModel::default_640x480();
  std::vector<size_t> visited;
  for (const int side : {32, 245}) {
    const LandmarkMap map = grid_map(side, 1000.0);
    const WindowPlanner planner(VisionConfig{}, cam, LandmarkGeometry{}, &map);
    ASSERT_NE(planner.index(), nullptr);
    // The camera over landmark (20, 20).
    const Pose2 v{20000.0 - cam.mount.offset_x_mm, 20000.0 - cam.mount.offset_y_mm, 0.0};
    std::vector<SearchWindow> w;
    planner.plan(predict(v, 3.0, 0.5), &w);
    ASSERT_EQ(w.size(), 1u) << side;
    EXPECT_EQ(w[0].landmark_id, static_cast<std::uint32_t>(20 * side + 21));
    visited.push_back(planner.index()->last_visited());
    EXPECT_LE(visited.back(), 9u) << side;
  }
  EXPECT_EQ(visited[0], visited[1]);
}
