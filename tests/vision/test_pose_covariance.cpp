// vehicle_in_world_covariance (agv/vision/pose_covariance.hpp), the one propagation of the vision
// covariance used by LandmarkLocalizer and by tools/eval/fusion: against the analytic Jacobian of
// W<-V = (W<-L) (+) inverse(V<-L), and against the fix LandmarkLocalizer reports.
#include <gtest/gtest.h>

#include <Eigen/Dense>
#include <cmath>
#include <opencv2/core.hpp>
#include <random>
#include <string>

#include "../support/one_landmark_frame.hpp"
#include "agv/common/geometry.hpp"
#include "agv/sim/render.hpp"
#include "agv/vision/landmark_localizer.hpp"
#include "agv/vision/pose_covariance.hpp"

using namespace agv;
using agv::vision::vehicle_in_world_covariance;

namespace {

// d(W<-V)/d(V<-L): with V<-L = (t, theta) and W<-L = (T, phi), W<-V = (T - R(phi - theta) t,
// phi - theta).
Eigen::Matrix3d analytic_jacobian(const Pose2& w_l, const Pose2& v_l) {
  const double a = w_l.theta_rad - v_l.theta_rad;
  const double ca = std::cos(a), sa = std::sin(a);
  const double x = v_l.x_mm, y = v_l.y_mm;
  Eigen::Matrix3d j;
  // d/dtheta of -R(a) t with da/dtheta = -1: R'(a) t.
  j << -ca, sa, -sa * x - ca * y,  //
      -sa, -ca, ca * x - sa * y,   //
      0.0, 0.0, -1.0;
  return j;
}

TEST(VisionPoseCovariance, MatchesAnalyticJacobianPropagation) {
  std::mt19937_64 rng(3);
  std::uniform_real_distribution<double> pos(-5e4, 5e4), ang(-kPi, kPi), lever(-60.0, 60.0);
  std::uniform_real_distribution<double> sig_mm(0.05, 0.5), sig_rad(1.7e-4, 1e-3), rho(-0.9, 0.9);
  for (int i = 0; i < 200; ++i) {
    const Pose2 w_l{pos(rng), pos(rng), ang(rng)};
    const Pose2 v_l{lever(rng), lever(rng), ang(rng)};
    const double sx = sig_mm(rng), sy = sig_mm(rng), st = sig_rad(rng), r = rho(rng);
    Eigen::Matrix3d c;
    c << sx * sx, r * sx * sy, 0.3 * r * sx * st,  //
        r * sx * sy, sy * sy, -0.2 * r * sy * st,  //
        0.3 * r * sx * st, -0.2 * r * sy * st, st * st;
    const Eigen::Matrix3d j = analytic_jacobian(w_l, v_l);
    const Eigen::Matrix3d want = j * c * j.transpose();
    const Eigen::Matrix3d got = vehicle_in_world_covariance(w_l, v_l, c);
    // Central differences of a rotation: relative error ~ step^2, far below 1e-6.
    for (int a = 0; a < 3; ++a) {
      for (int b = 0; b < 3; ++b) {
        const double scale = std::sqrt(want(a, a) * want(b, b));
        EXPECT_NEAR(got(a, b), want(a, b), 1e-6 * scale) << "entry " << a << "," << b << " i=" << i;
      }
    }
  }
}

TEST(VisionPoseCovariance, HeadingVarianceMovesToPositionThroughTheLeverArm) {
  // Only heading uncertainty, landmark 50 mm ahead: the world position varies across that arm.
  const Pose2 w_l{1000.0, -2000.0, 0.0};
  const Pose2 v_l{50.0, 0.0, 0.0};
  Eigen::Matrix3d c = Eigen::Matrix3d::Zero();
  const double st = 1e-3;
  c(2, 2) = st * st;
  const Eigen::Matrix3d got = vehicle_in_world_covariance(w_l, v_l, c);
  EXPECT_NEAR(got(2, 2), st * st, 1e-12);
  EXPECT_NEAR(got(0, 0), 0.0, 1e-9);
  EXPECT_NEAR(std::sqrt(got(1, 1)), 50.0 * st, 1e-6);
}

TEST(VisionPoseCovariance, LocalizerReportsThePropagatedCovariance) {
  // The fix's world covariance is this function of its own landmark-in-vehicle pose and
  // covariance (the map pose is exact), bit for bit: the product has no second copy.
  const Pose2 world_landmark{1000.0, -2000.0, deg_to_rad(90.0)};
  const Pose2 e{6.0, -4.0, deg_to_rad(37.0)};
  sim::RenderOptions o;
  o.defocus_sigma_px = 1.5;  // a non-trivial fit covariance
  testsupport::OneLandmarkFrame f;
  std::string err;
  ASSERT_TRUE(testsupport::render_one_landmark(world_landmark, e, o, &f, &err)) << err;
  vision::LandmarkLocalizer loc(vision::VisionConfig{}, f.cam, LandmarkGeometry{}, &f.map);
  vision::LandmarkFix fix;
  ASSERT_EQ(loc.process(f.img, &fix), vision::FixStatus::kOk) << vision::to_string(fix.status);
  const Eigen::Matrix3d want = vehicle_in_world_covariance(world_landmark, fix.landmark_in_vehicle,
                                                           fix.cov_landmark_in_vehicle);
  EXPECT_EQ(fix.cov_world, want);
  EXPECT_GT(fix.cov_landmark_in_vehicle(2, 2), 0.0);
}

}  // namespace
