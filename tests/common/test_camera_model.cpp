#include <gtest/gtest.h>

#include "agv/common/camera_model.hpp"

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
