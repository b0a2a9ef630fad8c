#include <gtest/gtest.h>

#include <cmath>

#include "agv/common/geometry.hpp"
#include "agv/fusion/chi2.hpp"
#include "agv/fusion/motion_model.hpp"

using namespace agv;
using namespace agv::fusion;

namespace {

StateVec make_state(double x, double y, double th, double v, double w) {
  StateVec s;
  s << x, y, th, v, w;
  return s;
}

// Central differences of motion_predict; the heading row is differenced with wrapping.
StateCov numeric_jacobian(const StateVec& x, double dt) {
  StateCov J;
  const double h[5] = {1e-3, 1e-3, 1e-6, 1e-5, 1e-5};
  for (int j = 0; j < 5; ++j) {
    StateVec xp = x, xm = x;
    xp(j) += h[j];
    xm(j) -= h[j];
    StateVec d = motion_predict(xp, dt) - motion_predict(xm, dt);
    d(kItheta) = wrap_angle_rad(d(kItheta));
    J.col(j) = d / (2.0 * h[j]);
  }
  return J;
}

void expect_jacobian_matches(const StateVec& x, double dt) {
  const StateCov A = motion_jacobian(x, dt);
  const StateCov N = numeric_jacobian(x, dt);
  for (int r = 0; r < 5; ++r) {
    for (int c = 0; c < 5; ++c) {
      const double tol = 1e-6 * (1.0 + std::abs(N(r, c)));
      EXPECT_NEAR(A(r, c), N(r, c), tol)
          << "F(" << r << "," << c << ") at omega=" << x(kIomega) << " dt=" << dt;
    }
  }
}

}  // namespace

TEST(FusionMotionModel, JacobianMatchesNumericalAcrossTurnRates) {
  const double omegas[] = {0.0, 1e-9, -1e-6, 3e-3, -9.99e-3 / 0.01, 1e-2 / 0.01, 0.3, -2.0, 8.0};
  for (double w : omegas) {
    for (double dt : {0.01, 0.05, 0.5}) {
      for (double th : {0.0, 0.7, -2.9, kPi}) {
        expect_jacobian_matches(make_state(120.0, -3400.0, th, 1.3, w), dt);
        expect_jacobian_matches(make_state(0.0, 0.0, th, -0.4, w), dt);
      }
    }
  }
}

TEST(FusionMotionModel, ArcCoefficientsContinuousAtSeriesSwitch) {
  // The series (|a| < 1e-2) and the closed form must agree where they meet.
  for (double a : {1e-2 * (1 - 1e-12), -1e-2 * (1 - 1e-12)}) {
    const ArcCoefficients lo = arc_coefficients(a);
    const ArcCoefficients hi = arc_coefficients(a * (1 + 2e-12));
    EXPECT_NEAR(lo.s, hi.s, 1e-13);
    EXPECT_NEAR(lo.c, hi.c, 1e-13);
    EXPECT_NEAR(lo.ds, hi.ds, 1e-11);
    EXPECT_NEAR(lo.dc, hi.dc, 1e-11);
  }
  const ArcCoefficients z = arc_coefficients(0.0);
  EXPECT_EQ(z.s, 1.0);
  EXPECT_EQ(z.c, 0.0);
  EXPECT_EQ(z.ds, 0.0);
  EXPECT_EQ(z.dc, 0.5);
}

TEST(FusionMotionModel, StraightLineMatchesEq14) {
  // omega = 0: eq. 14 of Yang et al. exactly.
  const StateVec x = make_state(100.0, 200.0, deg_to_rad(30.0), 1.0, 0.0);
  const StateVec y = motion_predict(x, 0.5);
  EXPECT_NEAR(y(kIx), 100.0 + 500.0 * std::cos(deg_to_rad(30.0)), 1e-9);
  EXPECT_NEAR(y(kIy), 200.0 + 500.0 * std::sin(deg_to_rad(30.0)), 1e-9);
  EXPECT_DOUBLE_EQ(y(kItheta), deg_to_rad(30.0));
  EXPECT_EQ(y(kIv), 1.0);
  EXPECT_EQ(y(kIomega), 0.0);
}

TEST(FusionMotionModel, ConstantTurnStaysOnCircle) {
  // v = 0.5 m/s, omega = 0.5 rad/s: radius 1000 mm around (0, 1000) starting at the origin
  // heading +x. Many small steps and one big step both land on the exact circle point.
  const double v = 0.5, w = 0.5, T = kPi / w;  // half a circle
  StateVec s = make_state(0.0, 0.0, 0.0, v, w);
  for (int i = 0; i < 1000; ++i) s = motion_predict(s, T / 1000.0);
  EXPECT_NEAR(s(kIx), 0.0, 1e-6);
  EXPECT_NEAR(s(kIy), 2000.0, 1e-6);
  EXPECT_NEAR(std::abs(s(kItheta)), kPi, 1e-12);
  const StateVec one = motion_predict(make_state(0.0, 0.0, 0.0, v, w), T / 2.0);  // quarter
  EXPECT_NEAR(one(kIx), 1000.0, 1e-9);
  EXPECT_NEAR(one(kIy), 1000.0, 1e-9);
  EXPECT_NEAR(one(kItheta), kPi / 2.0, 1e-12);
}

TEST(FusionMotionModel, HeadingWrapsAcrossPi) {
  const StateVec s = motion_predict(make_state(0.0, 0.0, kPi - 0.01, 0.0, 1.0), 0.02);
  EXPECT_NEAR(s(kItheta), -kPi + 0.01, 1e-12);
}

TEST(FusionChi2, QuantileMatchesTables) {
  EXPECT_NEAR(chi2_3dof_quantile(0.999), 16.266, 1e-3);
  EXPECT_NEAR(chi2_3dof_quantile(0.99), 11.345, 1e-3);
  EXPECT_NEAR(chi2_3dof_quantile(0.95), 7.815, 1e-3);
  EXPECT_NEAR(chi2_3dof_quantile(0.5), 2.366, 1e-3);
  for (double p : {0.01, 0.3, 0.9, 0.9999, 1.0 - 1e-9}) {
    EXPECT_NEAR(chi2_3dof_cdf(chi2_3dof_quantile(p)), p, 1e-12);
  }
  EXPECT_TRUE(std::isnan(chi2_3dof_quantile(0.0)));
  EXPECT_TRUE(std::isnan(chi2_3dof_quantile(1.0)));
  EXPECT_TRUE(std::isnan(chi2_3dof_quantile(std::nan(""))));
}
