// The small rendered rack scene the observer's tests share (test_ranging_observe.cpp,
// test_ranging_windows.cpp): a 640 x 400 forward camera, a rack face 3.5 m ahead with four
// tag36h11 landmarks, one frame rendered once per suite.
#pragma once

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <opencv2/core.hpp>
#include <vector>

#include "agv/ranging/observe.hpp"
#include "agv/sim/ranging_camera.hpp"

namespace agv::ranging::observe_test {

// clang-format off
inline CameraIntrinsics small_camera() {
  return {.width_px = 640, .height_px = 400, .fx = 600.0, .fy = 600.0, .cx = 321.5, .cy = 198.0,
          .k1 = -0.06, .k2 = 0.01};
}
// clang-format on

inline RangingMount forward_mount() {
  return {.x_mm = 300.0, .y_mm = 40.0, .z_mm = 1000.0, .pitch_rad = 0.02, .yaw_rad = -0.03};
}

// A rack face at x = 4 m facing -x with landmarks on it, one more on a pillar to the left.
inline sim::SiteScene rack_scene() {
  sim::SiteScene s;
  s.site.outline.vertices_mm = {{-5000, -5000}, {9000, -5000}, {9000, 5000}, {-5000, 5000}};
  site::Obstacle rack;
  rack.id = "rack";
  rack.outline.vertices_mm = {{4000, -2500}, {5000, -2500}, {5000, 2500}, {4000, 2500}};
  rack.height_mm = 2500.0;
  s.site.obstacles.push_back(rack);
  using site::LandmarkFamily;
  s.site.wall_landmarks.push_back({21, LandmarkFamily::kTag36h11, 4000, -1100, 1150, kPi, 150});
  s.site.wall_landmarks.push_back({22, LandmarkFamily::kTag36h11, 4000, 150, 1250, kPi, 150});
  s.site.wall_landmarks.push_back({23, LandmarkFamily::kTag36h11, 4000, 1200, 900, kPi, 150});
  // Shallow pair: two tags 200 mm apart, far away (they subtend about 3 degrees).
  s.site.wall_landmarks.push_back({30, LandmarkFamily::kTag36h11, 4000, 1700, 1300, kPi, 150});
  s.floor.amplitude = 8.0;
  return s;
}

inline const Pose2 kVehicle{500.0, 200.0, 0.06};

inline sim::RenderResult render(const sim::SiteScene& s, const Pose2& pose, std::uint64_t seed) {
  const CameraIntrinsics k = small_camera();
  sim::SiteRenderParams p;
  p.read_noise_sigma = 2.0;
  p.defocus_sigma_px = 0.5;
  p.illumination_ratio = 0.8;
  return sim::render_site_frame(s, sim::ranging_camera(k, pose, forward_mount()), p, seed);
}

struct Truth {
  double range_mm, bearing_rad, yaw_rad;
};
inline Truth truth_for(const site::WallLandmark& w, const Pose2& v) {
  const double dx = w.x_mm - v.x_mm, dy = w.y_mm - v.y_mm;
  return {std::hypot(dx, dy), wrap_angle_rad(std::atan2(dy, dx) - v.theta_rad),
          wrap_angle_rad(w.facing_rad - v.theta_rad)};
}

inline const site::WallLandmark& landmark(const sim::SiteScene& s, std::uint32_t id) {
  for (const site::WallLandmark& w : s.site.wall_landmarks) {
    if (w.id == id) return w;
  }
  return s.site.wall_landmarks.front();
}

class RangingObserve : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    scene_ = new sim::SiteScene(rack_scene());
    frame_ = new sim::RenderResult(render(*scene_, kVehicle, 3));
  }
  static void TearDownTestSuite() {
    delete scene_;
    delete frame_;
  }
  static inline sim::SiteScene* scene_ = nullptr;
  static inline sim::RenderResult* frame_ = nullptr;
};

inline PosePrior near_prior() {
  PosePrior p;
  p.pose = {kVehicle.x_mm + 25.0, kVehicle.y_mm - 20.0, kVehicle.theta_rad + deg_to_rad(0.25)};
  p.cov = Eigen::Vector3d(30.0 * 30.0, 30.0 * 30.0, std::pow(deg_to_rad(0.3), 2)).asDiagonal();
  return p;
}

inline void expect_same_reads(const ObserveResult& sweep, const ObserveResult& windows) {
  ASSERT_EQ(windows.seen.size(), sweep.seen.size());
  for (const LandmarkObservation& a : sweep.seen) {
    const auto b = std::find_if(windows.seen.begin(), windows.seen.end(),
                                [&](const LandmarkObservation& o) { return o.id == a.id; });
    ASSERT_NE(b, windows.seen.end()) << a.id;
    for (std::size_t i = 0; i < 4; ++i) {
      EXPECT_NEAR(b->corners_px[i].x, a.corners_px[i].x, 0.2) << a.id;
      EXPECT_NEAR(b->corners_px[i].y, a.corners_px[i].y, 0.2) << a.id;
    }
    EXPECT_NEAR(b->pose.range_mm, a.pose.range_mm, 0.02 * std::sqrt(a.pose.cov(0, 0)) + 1.0);
  }
}

}  // namespace agv::ranging::observe_test
