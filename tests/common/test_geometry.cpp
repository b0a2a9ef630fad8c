#include <gtest/gtest.h>

#include "agv/common/geometry.hpp"

using namespace agv;

TEST(Geometry, WrapAngleRange) {
  EXPECT_DOUBLE_EQ(wrap_angle_rad(kPi), kPi);
  EXPECT_DOUBLE_EQ(wrap_angle_rad(-kPi), kPi);
  EXPECT_NEAR(wrap_angle_rad(3 * kPi + 0.1), -kPi + 0.1, 1e-12);
  EXPECT_NEAR(wrap_angle_rad(-7.5 * kPi), 0.5 * kPi, 1e-12);
  EXPECT_NEAR(wrap_angle_deg(270.0), -90.0, 1e-9);
}

TEST(Geometry, ComposeInverseIsIdentity) {
  const Pose2 a{120.0, -40.0, deg_to_rad(37.0)};
  const Pose2 b{-5.0, 300.0, deg_to_rad(-170.0)};
  const Pose2 ab = compose(a, b);
  const Pose2 back = compose(inverse(a), ab);
  EXPECT_NEAR(back.x_mm, b.x_mm, 1e-9);
  EXPECT_NEAR(back.y_mm, b.y_mm, 1e-9);
  EXPECT_NEAR(back.theta_rad, b.theta_rad, 1e-12);
  const Pose2 id = compose(a, inverse(a));
  EXPECT_NEAR(id.x_mm, 0.0, 1e-9);
  EXPECT_NEAR(id.y_mm, 0.0, 1e-9);
  EXPECT_NEAR(id.theta_rad, 0.0, 1e-12);
}

TEST(Geometry, TransformMatchesCompose) {
  const Pose2 a{10.0, 20.0, deg_to_rad(90.0)};
  const Vec2 p = transform(a, {1.0, 0.0});
  EXPECT_NEAR(p.x, 10.0, 1e-12);
  EXPECT_NEAR(p.y, 21.0, 1e-12);
}
