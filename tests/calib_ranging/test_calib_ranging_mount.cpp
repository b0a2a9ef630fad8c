// The second camera's mount from rack landmarks seen at floor-localized poses
// (tools/desk/src/calib_ranging_mount.*): synthetic sightings projected through a known mount,
// with corner noise and the floor localizer's pose noise; the solve starts from a mount that is
// off by the ranging evaluation's calibration errors (1 deg, 5 mm per axis).
#include <gtest/gtest.h>

#include <cmath>
#include <random>
#include <vector>

#include "agv/sim/ranging_camera.hpp"
#include "calib_ranging_mount.hpp"

namespace agv::desk {
namespace {

constexpr double kDeg = kPi / 180.0;

CameraIntrinsics intrinsics() {
  CameraIntrinsics k;
  k.width_px = 1280;
  k.height_px = 800;
  k.fx = k.fy = 1000.0;
  k.cx = 640.0;
  k.cy = 400.0;
  return k;
}

ranging::RangingMount true_mount() {
  ranging::RangingMount m;
  m.x_mm = 200.0;
  m.y_mm = 250.0;
  m.z_mm = 1000.0;
  m.roll_rad = 0.3 * kDeg;
  m.pitch_rad = -0.4 * kDeg;
  m.yaw_rad = 90.0 * kDeg;
  return m;
}

ranging::RangingMount off_mount() {
  ranging::RangingMount m = true_mount();
  m.x_mm += 5.0;
  m.y_mm -= 5.0;
  m.z_mm += 5.0;
  m.roll_rad -= 1.0 * kDeg;
  m.pitch_rad += 1.0 * kDeg;
  m.yaw_rad += 1.0 * kDeg;
  return m;
}

// A rack face along y = 2000 mm facing -y (towards the aisle at y < 2000), landmarks every
// 700 mm at two heights.
std::vector<site::WallLandmark> rack_face() {
  std::vector<site::WallLandmark> walls;
  for (int i = 0; i < 12; ++i) {
    site::WallLandmark w;
    w.id = static_cast<std::uint32_t>(10 + i);
    w.x_mm = 700.0 * i;
    w.y_mm = 2000.0;
    w.z_mm = i % 2 ? 1400.0 : 800.0;
    w.facing_rad = -kPi / 2.0;
    w.size_mm = 150.0;
    walls.push_back(w);
  }
  return walls;
}

struct Drive {
  double corner_noise_px = 0.3;
  double pose_sigma_mm = 0.3, pose_sigma_rad = 0.02 * kDeg;
  double focal_scale = 1.0;  // the true focal length over the calibrated one
  unsigned seed = 1;
};

// Two passes along the face (1.5 m and 3 m from it) and a slow turn; each frame's sightings are
// the landmarks wholly inside the image, projected through the true mount at the true pose; the
// sightings carry a pose off by the floor localizer's noise.
std::vector<rcal::MountSighting> sightings(const std::vector<site::WallLandmark>& walls,
                                           const Drive& d) {
  std::mt19937 rng(d.seed);
  std::normal_distribution<double> n01(0.0, 1.0);
  CameraIntrinsics k = intrinsics();
  k.fx *= d.focal_scale;
  k.fy *= d.focal_scale;
  std::vector<rcal::MountSighting> out;
  std::int64_t t_ns = 0;
  for (int pass = 0; pass < 2; ++pass) {
    for (int f = 0; f < 40; ++f) {
      const Pose2 truth{200.0 * f, pass ? -1000.0 : 500.0, (pass ? -8.0 : 6.0) * kDeg * (f % 3)};
      t_ns += 100'000'000;
      const Pose2 believed{truth.x_mm + d.pose_sigma_mm * n01(rng),
                           truth.y_mm + d.pose_sigma_mm * n01(rng),
                           truth.theta_rad + d.pose_sigma_rad * n01(rng)};
      for (std::size_t i = 0; i < walls.size(); ++i) {
        rcal::MountSighting s;
        s.t_ns = t_ns;
        s.vehicle = believed;
        s.vehicle_sigma = {d.pose_sigma_mm, d.pose_sigma_mm, d.pose_sigma_rad};
        s.landmark_index = i;
        const auto corners = rcal::wall_corners_site(walls[i]);
        bool in_view = true;
        for (std::size_t c = 0; c < 4 && in_view; ++c) {
          Vec2 px;
          in_view = rcal::project_undistorted(k, true_mount(), truth, corners[c], &px) &&
                    px.x > 5 && px.y > 5 && px.x < k.width_px - 5 && px.y < k.height_px - 5;
          s.corners_undistorted_px[c] = {px.x + d.corner_noise_px * n01(rng),
                                         px.y + d.corner_noise_px * n01(rng)};
        }
        if (in_view) out.push_back(s);
      }
    }
  }
  return out;
}

std::array<double, 6> error(const ranging::RangingMount& a, const ranging::RangingMount& b) {
  return {a.x_mm - b.x_mm,         a.y_mm - b.y_mm,           a.z_mm - b.z_mm,
          a.roll_rad - b.roll_rad, a.pitch_rad - b.pitch_rad, a.yaw_rad - b.yaw_rad};
}

TEST(CalibRangingMount, ProjectionMatchesTheRenderersCamera) {
  const CameraIntrinsics k = intrinsics();
  const Pose2 vehicle{1200.0, -300.0, 0.4};
  const sim::RenderCamera cam = sim::ranging_camera(k, vehicle, true_mount());
  int compared = 0;
  for (const auto& w : rack_face()) {
    for (const auto& c : rcal::wall_corners_site(w)) {
      Vec2 ours;
      if (!rcal::project_undistorted(k, true_mount(), vehicle, c, &ours)) continue;
      ++compared;
      const auto theirs = sim::project_points(cam, {{c[0], c[1], c[2]}});
      EXPECT_NEAR(ours.x, theirs[0].x, 1e-6);
      EXPECT_NEAR(ours.y, theirs[0].y, 1e-6);
    }
  }
  EXPECT_GT(compared, 20);
}

TEST(CalibRangingMount, RecoversTheMountFromAnOffStart) {
  const auto walls = rack_face();
  const auto s = sightings(walls, {});
  ASSERT_GT(s.size(), 150u);
  const rcal::Result r = rcal::solve_mount(intrinsics(), walls, s, off_mount());
  ASSERT_EQ(r.error, rcal::Error::kNone) << r.message;
  const auto e = error(r.mount, true_mount());
  for (std::size_t i = 0; i < 6; ++i) {
    EXPECT_LT(std::abs(e[i]), 4.0 * r.sigma[i]) << "axis " << i;
    EXPECT_GT(r.sigma[i], 0.0) << "axis " << i;
  }
  // The calibration leaves far less than the 1 deg / 5 mm it started from.
  EXPECT_LT(std::abs(e[5]), 0.05 * kDeg);
  EXPECT_LT(std::hypot(e[0], e[1]), 1.0);
  EXPECT_NEAR(r.rms_px, 0.3 * std::sqrt(2.0), 0.15);
  EXPECT_EQ(r.sightings_used, static_cast<int>(s.size()));
}

TEST(CalibRangingMount, ALandmarkSurveyedWrongIsLeftOut) {
  auto walls = rack_face();
  const auto s = sightings(walls, {});
  walls[4].x_mm += 500.0;  // the map is wrong; the frames saw it where it is
  const rcal::Result r = rcal::solve_mount(intrinsics(), walls, s, off_mount());
  ASSERT_EQ(r.error, rcal::Error::kNone) << r.message;
  int rejected = 0;
  for (const auto& l : r.landmarks) {
    if (!l.rejected) continue;
    ++rejected;
    EXPECT_EQ(l.id, walls[4].id);
  }
  EXPECT_EQ(rejected, 1);
  EXPECT_LT(std::abs(error(r.mount, true_mount())[5]), 0.05 * kDeg);
}

// A focal length 0.3 % longer than calibrated reads every landmark 0.3 % nearer: the mount's
// offset along the optical axis (y, the camera looks left) takes it up, more than 5 sigma off.
// Told as the lens's doubt, the focal length is solved beside the mount (the two passes see the
// landmarks at two depths) and every axis is within 3 sigma.
TEST(CalibRangingMount, TheLensDoubtIsCarriedIntoTheMountSigma) {
  const auto walls = rack_face();
  Drive d;
  d.focal_scale = 1.003;
  const auto s = sightings(walls, d);
  const rcal::Result exact = rcal::solve_mount(intrinsics(), walls, s, off_mount());
  ASSERT_EQ(exact.error, rcal::Error::kNone) << exact.message;
  const double e_exact = std::abs(error(exact.mount, true_mount())[1]);
  EXPECT_GT(e_exact, 5.0 * exact.sigma[1]) << e_exact << " mm, sigma " << exact.sigma[1];
  rcal::Options told;
  told.focal_sigma_rel = 0.003;
  told.max_sigma_mm = 10.0;
  const rcal::Result r = rcal::solve_mount(intrinsics(), walls, s, off_mount(), told);
  ASSERT_EQ(r.error, rcal::Error::kNone) << r.message;
  const auto e = error(r.mount, true_mount());
  for (std::size_t i = 0; i < 6; ++i) EXPECT_LT(std::abs(e[i]), 3.0 * r.sigma[i]) << "axis " << i;
}

TEST(CalibRangingMount, PosesTooUncertainAreReportedNotTrusted) {
  const auto walls = rack_face();
  Drive d;
  d.pose_sigma_mm = 30.0;  // dead reckoning far from any floor landmark
  d.pose_sigma_rad = 2.0 * kDeg;
  const rcal::Result r = rcal::solve_mount(intrinsics(), walls, sightings(walls, d), off_mount());
  EXPECT_EQ(r.error, rcal::Error::kPoorlyObserved);
  EXPECT_NE(r.message.find("yaw"), std::string::npos) << r.message;
}

TEST(CalibRangingMount, TooFewFramesOrLandmarksAreRefused) {
  const auto walls = rack_face();
  auto s = sightings(walls, {});
  s.resize(5);
  const rcal::Result r = rcal::solve_mount(intrinsics(), walls, s, off_mount());
  EXPECT_EQ(r.error, rcal::Error::kTooFewSightings);
  EXPECT_NE(r.message.find("frames"), std::string::npos);
  // The result is the initial mount, never a half-solved one.
  EXPECT_EQ(r.mount.yaw_rad, off_mount().yaw_rad);
}

}  // namespace
}  // namespace agv::desk
