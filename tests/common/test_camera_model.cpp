#include <gtest/gtest.h>

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstdint>
#include <limits>
#include <vector>

#include "agv/common/camera_model.hpp"
#include "agv/common/landmark.hpp"

using namespace agv;

TEST(CameraModel, DefaultAxesFollowFramesDoc) {
  const CameraModel m = CameraModel::default_640x480();
  Vec2 px;
  // A point ahead of the vehicle appears above the image centre, one to the left appears left.
  ASSERT_TRUE(m.vehicle_to_pixel({26.0, 0.0}, &px));
  EXPECT_NEAR(px.x, 319.5, 1e-9);
  EXPECT_NEAR(px.y, 239.5 - 100.0, 1e-9);
  ASSERT_TRUE(m.vehicle_to_pixel({0.0, 26.0}, &px));
  EXPECT_NEAR(px.x, 319.5 - 100.0, 1e-9);
  EXPECT_NEAR(px.y, 239.5, 1e-9);
  EXPECT_NEAR(m.mm_per_px(), 0.26, 1e-12);
}

TEST(CameraModel, RoundTripWithDistortionOffsetAndYaw) {
  CameraModel m = CameraModel::default_640x480();
  m.intrinsics.k1 = -0.21;
  m.intrinsics.k2 = 0.05;
  m.intrinsics.p1 = 0.001;
  m.intrinsics.p2 = -0.0007;
  m.intrinsics.k3 = -0.01;
  m.mount = {35.0, -12.0, deg_to_rad(3.0), 180.0};
  for (double x = -60; x <= 60; x += 15) {
    for (double y = -80; y <= 80; y += 20) {
      Vec2 px, back;
      ASSERT_TRUE(m.vehicle_to_pixel({x + 35.0, y - 12.0}, &px));
      ASSERT_TRUE(m.pixel_to_vehicle(px, &back));
      EXPECT_NEAR(back.x, x + 35.0, 1e-7);
      EXPECT_NEAR(back.y, y - 12.0, 1e-7);
    }
  }
}

TEST(CameraModel, RejectsNonFiniteInput) {
  const CameraModel m = CameraModel::default_640x480();
  Vec2 out;
  EXPECT_FALSE(m.vehicle_to_pixel({std::nan(""), 0.0}, &out));
  EXPECT_FALSE(m.pixel_to_vehicle({0.0, std::numeric_limits<double>::infinity()}, &out));
}

// Tilt 0 keeps the untilted code path: these are the exact values of the perpendicular model
// (no rounding difference allowed), and a vanishing tilt through the rotation path agrees.
TEST(CameraModel, ZeroTiltIsTheUntiltedModelExactly) {
  CameraModel m = CameraModel::default_640x480();
  m.mount = {35.0, -12.0, deg_to_rad(3.0), 180.0};
  EXPECT_FALSE(m.mount.tilted());
  const Vec2 p{61.25, 7.5};
  const double dx = p.x - 35.0, dy = p.y + 12.0;
  const double c = std::cos(deg_to_rad(3.0)), s = std::sin(deg_to_rad(3.0));
  const Vec2 expect =
      m.distort_normalized_to_pixel({(dx * s - dy * c) / 180.0, -(dx * c + dy * s) / 180.0});
  Vec2 px;
  ASSERT_TRUE(m.vehicle_to_pixel(p, &px));
  EXPECT_EQ(px.x, expect.x);
  EXPECT_EQ(px.y, expect.y);
  CameraModel t = m;
  t.mount.roll_rad = 1e-15;
  t.mount.pitch_rad = -1e-15;
  ASSERT_TRUE(t.mount.tilted());
  Vec2 pt, back, back_t;
  ASSERT_TRUE(t.vehicle_to_pixel(p, &pt));
  EXPECT_NEAR(pt.x, px.x, 1e-9);
  EXPECT_NEAR(pt.y, px.y, 1e-9);
  ASSERT_TRUE(m.pixel_to_vehicle({100.0, 400.0}, &back));
  ASSERT_TRUE(t.pixel_to_vehicle({100.0, 400.0}, &back_t));
  EXPECT_NEAR(back.x, back_t.x, 1e-9);
  EXPECT_NEAR(back.y, back_t.y, 1e-9);
}

// docs/design/frames.md "Camera tilt": +roll turns the optical axis to image left, +pitch to image
// down.
TEST(CameraModel, TiltSignsFollowFramesDoc) {
  for (double yaw_deg : {0.0, 90.0, -30.0}) {
    CameraModel m = CameraModel::default_640x480();
    m.mount.yaw_rad = deg_to_rad(yaw_deg);
    const double h = m.mount.height_mm, a = deg_to_rad(2.0);
    const double cy = std::cos(m.mount.yaw_rad), sy = std::sin(m.mount.yaw_rad);
    const Vec2 up{cy, sy}, left{-sy, cy};  // image up / image left in the vehicle frame
    Vec2 q;
    m.mount.roll_rad = a;
    ASSERT_TRUE(m.pixel_to_vehicle({319.5, 239.5}, &q));
    EXPECT_NEAR(q.x, h * std::tan(a) * left.x, 1e-9);
    EXPECT_NEAR(q.y, h * std::tan(a) * left.y, 1e-9);
    m.mount.roll_rad = 0.0;
    m.mount.pitch_rad = a;
    ASSERT_TRUE(m.pixel_to_vehicle({319.5, 239.5}, &q));
    EXPECT_NEAR(q.x, -h * std::tan(a) * up.x, 1e-9);
    EXPECT_NEAR(q.y, -h * std::tan(a) * up.y, 1e-9);
  }
}

TEST(CameraModel, TiltedRoundTripWithDistortion) {
  CameraModel m = CameraModel::default_640x480();
  m.intrinsics.k1 = -0.21;
  m.intrinsics.k2 = 0.05;
  m.intrinsics.p1 = 0.001;
  m.mount = {35.0, -12.0, deg_to_rad(3.0), 180.0, deg_to_rad(1.5), deg_to_rad(-1.2)};
  double max_err = 0.0;
  for (double x = -60; x <= 60; x += 15) {
    for (double y = -80; y <= 80; y += 20) {
      Vec2 px, back;
      ASSERT_TRUE(m.vehicle_to_pixel({x + 35.0, y - 12.0}, &px));
      ASSERT_TRUE(m.pixel_to_vehicle(px, &back));
      max_err = std::max({max_err, std::abs(back.x - x - 35.0), std::abs(back.y - y + 12.0)});
      // The tilt really moves the image: the untilted model puts the point elsewhere.
      CameraModel flat = m;
      flat.mount.roll_rad = flat.mount.pitch_rad = 0.0;
      Vec2 px_flat;
      ASSERT_TRUE(flat.vehicle_to_pixel({x + 35.0, y - 12.0}, &px_flat));
      EXPECT_GT(std::hypot(px.x - px_flat.x, px.y - px_flat.y), 10.0);
    }
  }
  EXPECT_LT(max_err, 1e-7);
  // A floor point behind a strongly tilted camera cannot be imaged; a ray above the horizon
  // does not reach the floor.
  CameraModel steep = CameraModel::default_640x480();
  steep.mount.pitch_rad = deg_to_rad(45.0);
  Vec2 px, q;
  EXPECT_FALSE(steep.vehicle_to_pixel({1000.0, 0.0}, &px));  // image up = behind
  steep.intrinsics.fx = steep.intrinsics.fy = 100.0;
  EXPECT_FALSE(steep.pixel_to_vehicle({319.5, 239.5 + 300.0}, &q));  // above the horizon
}

// The localizer's loops map through one FloorProjector built with the localizer: it must give
// what the model gives, for tilted and untilted mounts, and keep the model it was built with.
TEST(CameraModel, FloorProjectorKeepsItsModelAndMatchesItExactly) {
  CameraModel tilted = CameraModel::default_640x480();
  tilted.intrinsics.k1 = -0.21;
  tilted.intrinsics.p2 = 0.002;
  tilted.mount = {35.0, -12.0, deg_to_rad(3.0), 180.0, deg_to_rad(1.5), deg_to_rad(-1.2)};
  CameraModel yawed = tilted;
  yawed.mount.roll_rad = yawed.mount.pitch_rad = 0.0;
  for (const CameraModel& m : {tilted, yawed}) {
    const FloorProjector proj(m);
    CameraModel changed = m;
    changed.mount.yaw_rad += 0.1;
    changed.mount.pitch_rad += 0.01;
    for (double x = -60; x <= 60; x += 15) {
      for (double y = -80; y <= 80; y += 20) {
        Vec2 px_m, px_p, v_m, v_p, px_c;
        ASSERT_TRUE(m.vehicle_to_pixel({x, y}, &px_m));
        ASSERT_TRUE(proj.vehicle_to_pixel({x, y}, &px_p));
        EXPECT_EQ(px_m.x, px_p.x);
        EXPECT_EQ(px_m.y, px_p.y);
        ASSERT_TRUE(m.pixel_to_vehicle(px_m, &v_m));
        ASSERT_TRUE(proj.pixel_to_vehicle(px_m, &v_p));
        EXPECT_EQ(v_m.x, v_p.x);
        EXPECT_EQ(v_m.y, v_p.y);
        ASSERT_TRUE(changed.vehicle_to_pixel({x, y}, &px_c));
        EXPECT_GT(std::hypot(px_c.x - px_p.x, px_c.y - px_p.y), 1.0);
      }
    }
    Vec2 out;
    EXPECT_FALSE(proj.vehicle_to_pixel({std::numeric_limits<double>::quiet_NaN(), 0.0}, &out));
    EXPECT_FALSE(proj.pixel_to_vehicle({std::numeric_limits<double>::infinity(), 0.0}, &out));
    EXPECT_EQ(proj.model().mount.yaw_rad, m.mount.yaw_rad);
  }
}

// A plane at one pose (a landmark's page) maps through one folded matrix: the same pixels as the
// rigid transform then vehicle_to_pixel, to rounding, on tilted, yawed and distorted cameras, and
// the same refusals (behind a tilted camera, non-finite points, no height).
TEST(CameraModel, PlaneProjectorMatchesVehicleToPixel) {
  CameraModel tilted = CameraModel::default_640x480();
  tilted.intrinsics.k1 = -0.21;
  tilted.intrinsics.k2 = 0.05;
  tilted.intrinsics.p1 = -0.001;
  tilted.intrinsics.p2 = 0.002;
  tilted.mount = {35.0, -12.0, deg_to_rad(3.0), 180.0, deg_to_rad(1.5), deg_to_rad(-1.2)};
  CameraModel yawed = tilted;
  yawed.mount.roll_rad = yawed.mount.pitch_rad = 0.0;
  CameraModel radial = yawed;  // the lens terms each projector keeps: all, radial only, none
  radial.intrinsics.p1 = radial.intrinsics.p2 = 0.0;
  int compared = 0;
  for (const CameraModel& m : {tilted, yawed, radial, CameraModel::default_640x480()}) {
    const FloorProjector proj(m);
    for (const Pose2 pose : {Pose2{0, 0, 0}, Pose2{12.5, -30.0, 0.7}, Pose2{-40, 25, -2.9}}) {
      const double co = std::cos(pose.theta_rad), si = std::sin(pose.theta_rad);
      // Page axes u, v of a landmark: its (x, y) = (-v, -u), rotated by the pose.
      const PlaneProjector plane = proj.plane({pose.x_mm, pose.y_mm}, {si, -co}, {-co, -si});
      for (double u = -30; u <= 30; u += 7.5) {
        for (double v = -30; v <= 30; v += 7.5) {
          Vec2 want, got;
          ASSERT_TRUE(proj.vehicle_to_pixel(transform(pose, page_to_landmark({u, v})), &want));
          ASSERT_TRUE(plane.to_pixel({u, v}, &got));
          EXPECT_NEAR(got.x, want.x, 1e-9);
          EXPECT_NEAR(got.y, want.y, 1e-9);
          ++compared;
        }
      }
      Vec2 out{7.0, 7.0};
      EXPECT_FALSE(plane.to_pixel({std::numeric_limits<double>::quiet_NaN(), 0.0}, &out));
      EXPECT_FALSE(plane.to_pixel({0.0, std::numeric_limits<double>::infinity()}, &out));
      EXPECT_EQ(out.x, 7.0);
    }
  }
  EXPECT_EQ(compared, 4 * 3 * 81);
  CameraModel steep = CameraModel::default_640x480();
  steep.mount.pitch_rad = deg_to_rad(45.0);
  Vec2 px;
  const FloorProjector steep_proj(steep);
  ASSERT_FALSE(steep_proj.vehicle_to_pixel({1000.0, 0.0}, &px));
  EXPECT_FALSE(steep_proj.plane({1000.0, 0.0}, {1, 0}, {0, 1}).to_pixel({0, 0}, &px));
  CameraModel flat = CameraModel::default_640x480();
  flat.mount.height_mm = 0.0;
  EXPECT_FALSE(FloorProjector(flat).plane({0, 0}, {1, 0}, {0, 1}).to_pixel({0, 0}, &px));
  EXPECT_FALSE(PlaneProjector().to_pixel({0, 0}, &px));
}

// FloorProjector::undistort skips the Newton iteration for a lens without distortion; it must give
// CameraModel's answer to the last bit, including its refusals (non-finite input, a point whose
// Newton terms overflow, a failed round trip, bad intrinsics).
TEST(CameraModel, UndistortWithoutDistortionEqualsTheNewtonIterationBitForBit) {
  const double inf = std::numeric_limits<double>::infinity();
  const double nan = std::numeric_limits<double>::quiet_NaN();
  const CameraModel plain = CameraModel::default_640x480();
  CameraModel tiny_f = plain;  // normalised coordinates near overflow
  tiny_f.intrinsics.fx = tiny_f.intrinsics.fy = 1e-300;
  CameraModel bad_c = plain;
  bad_c.intrinsics.cx = nan;
  CameraModel no_f = plain;
  no_f.intrinsics.fy = 0.0;
  // 62882254552920.35 and 4.728825993706969e+20 fail the plain model's round trip.
  std::vector<double> coords{-0.0,
                             0.0,
                             0.5,
                             319.5,
                             639.0,
                             -250.25,
                             62882254552920.35,
                             4.728825993706969e+20,
                             -1e15,
                             1e150,
                             1e154,
                             -1e155,
                             1e160,
                             1e300,
                             inf,
                             nan};
  for (int i = 0; i < 40; ++i) coords.push_back(-100.0 + 21.37 * i);
  int compared = 0, refused = 0;
  for (const CameraModel& m : {plain, tiny_f, bad_c, no_f}) {
    const FloorProjector proj(m);
    for (const double x : coords) {
      for (const double y : coords) {
        Vec2 want{7.0, 7.0}, got{7.0, 7.0};
        const bool ok_want = m.undistort_pixel_to_normalized({x, y}, &want);
        const bool ok_got = proj.undistort({x, y}, &got);
        ASSERT_EQ(ok_got, ok_want) << x << ", " << y;
        EXPECT_EQ(std::bit_cast<std::uint64_t>(got.x), std::bit_cast<std::uint64_t>(want.x));
        EXPECT_EQ(std::bit_cast<std::uint64_t>(got.y), std::bit_cast<std::uint64_t>(want.y));
        ++compared;
        refused += ok_want ? 0 : 1;
      }
    }
  }
  EXPECT_EQ(compared, 4 * 56 * 56);
  // Every kind of refusal was exercised, and most plain pixels were mapped.
  EXPECT_GT(refused, 3 * 56 * 56);
  EXPECT_LT(refused, 4 * 56 * 56);
}

// With radial terms only, FloorProjector::undistort iterates on the scale along the ray: the
// same point as CameraModel's 2-D iteration to rounding, and the same refusals, over the image
// and far beyond it (past the fold of a strong barrel lens, where both refuse).
TEST(CameraModel, RadialUndistortAlongTheRayEqualsTheTwoDimensionalIteration) {
  const CameraModel plain = CameraModel::default_640x480();
  CameraModel k1 = plain;
  k1.intrinsics.k1 = -0.2;
  CameraModel k123 = plain;
  k123.intrinsics.k1 = -0.21;
  k123.intrinsics.k2 = 0.05;
  k123.intrinsics.k3 = -0.01;
  CameraModel pincushion = plain;
  pincushion.intrinsics.k1 = 0.3;
  CameraModel strong = plain;  // its fold lies inside the sampled range
  strong.intrinsics.k1 = -0.6;
  CameraModel tangential = k1;  // kept on CameraModel's iteration: identical
  tangential.intrinsics.p1 = 0.001;
  int compared = 0, refused = 0;
  double worst = 0.0;
  for (const CameraModel& m : {k1, k123, pincushion, strong, tangential}) {
    const FloorProjector proj(m);
    for (double x = -700.0; x <= 1340.0; x += 13.3) {
      for (double y = -620.0; y <= 1100.0; y += 11.9) {
        Vec2 want{7.0, 7.0}, got{7.0, 7.0};
        const bool ok_want = m.undistort_pixel_to_normalized({x, y}, &want);
        const bool ok_got = proj.undistort({x, y}, &got);
        ASSERT_EQ(ok_got, ok_want) << x << ", " << y << " k1 " << m.intrinsics.k1;
        worst = std::max({worst, std::abs(got.x - want.x), std::abs(got.y - want.y)});
        ++compared;
        refused += ok_want ? 0 : 1;
      }
    }
  }
  EXPECT_LT(worst, 5e-14);  // 1e-11 mm on the floor at 200 mm
  EXPECT_GT(compared, 5 * 20000);
  EXPECT_GT(refused, 1000);  // the strong lens's fold and beyond
  EXPECT_LT(refused, compared / 2);
  std::printf("radial undistort: %d points, %d refused by both, worst difference %.3g\n", compared,
              refused, worst);
}
