// Fixes without a prior: two circles and their two choice rules, trilateration, the Gauss-Newton
// refinement, the refusals (too few, no intersection, shallow, collinear, ambiguous,
// inconsistent) and the covariance's coverage on seeded noisy trials.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <random>
#include <vector>

#include "agv/ranging/fix.hpp"

namespace agv::ranging {
namespace {

Observation observe(const Pose2& truth, Vec2 landmark, double sigma_range_mm,
                    double sigma_bearing_rad) {
  Observation o;
  o.landmark_mm = landmark;
  const double dx = landmark.x - truth.x_mm, dy = landmark.y - truth.y_mm;
  o.range_mm = std::hypot(dx, dy);
  o.bearing_rad = wrap_angle_rad(std::atan2(dy, dx) - truth.theta_rad);
  o.cov = Eigen::Vector2d(sigma_range_mm * sigma_range_mm, sigma_bearing_rad * sigma_bearing_rad)
              .asDiagonal();
  return o;
}

void expect_pose(const Pose2& got, const Pose2& want, double tol_mm, double tol_rad) {
  EXPECT_NEAR(got.x_mm, want.x_mm, tol_mm);
  EXPECT_NEAR(got.y_mm, want.y_mm, tol_mm);
  EXPECT_NEAR(wrap_angle_rad(got.theta_rad - want.theta_rad), 0.0, tol_rad);
}

TEST(RangingFix, CirclesGiveBothSolutionsLeftThenRight) {
  const CircleCrossing c = intersect_circles({0, 0}, 5.0, {8, 0}, 5.0, 0.0);
  ASSERT_EQ(c.count, 2);
  EXPECT_NEAR(c.solutions[0].x, 4.0, 1e-15);
  EXPECT_NEAR(c.solutions[0].y, 3.0, 1e-15);
  EXPECT_NEAR(c.solutions[1].x, 4.0, 1e-15);
  EXPECT_NEAR(c.solutions[1].y, -3.0, 1e-15);
  EXPECT_EQ(intersect_circles({0, 0}, 3.0, {8, 0}, 4.0, 0.5).count, 0);       // apart
  EXPECT_EQ(intersect_circles({0, 0}, 10.0, {1, 0}, 2.0, 0.5).count, 0);      // one inside
  const CircleCrossing t = intersect_circles({0, 0}, 3.0, {8, 0}, 4.5, 1.0);  // misses by 0.5
  ASSERT_EQ(t.count, 1);
  EXPECT_TRUE(t.touching);
  EXPECT_NEAR(t.solutions[0].y, 0.0, 1e-15);
}

TEST(RangingFix, TwoCirclesAreExactOnNoiseFreeInputWithEitherRule) {
  const Vec2 l0{12000.0, 5000.0}, l1{15000.0, 9000.0};
  const Pose2 truths[] = {{10000.0, 9000.0, -0.6}, {14000.0, 4000.0, 1.9}, {17000.0, 5000.0, 2.2}};
  for (const Pose2& truth : truths) {
    const Observation o0 = observe(truth, l0, 20.0, 1e-3), o1 = observe(truth, l1, 20.0, 1e-3);
    // Seen in one forward image: l0 is left of l1 when its bearing is larger.
    const bool l0_left = o0.bearing_rad > o1.bearing_rad;
    for (TwoLandmarkRule rule :
         {TwoLandmarkRule::kLeftRight, TwoLandmarkRule::kBearingDifference}) {
      const FixResult f = fix_two_circles(o0, o1, rule, l0_left, FixOptions{});
      ASSERT_EQ(f.status, FixStatus::kOk) << fix_status_name(f.status);
      expect_pose(f.pose, truth, 1e-9, 1e-12);
      EXPECT_NEAR(f.chi2, 0.0, 1e-12);
    }
    const Observation both[2] = {o0, o1};
    const FixResult r = fix_from_landmarks(both, FixOptions{});
    ASSERT_EQ(r.status, FixStatus::kOk);
    expect_pose(r.pose, truth, 1e-9, 1e-12);
    EXPECT_EQ(r.dof, 1);
  }
}

TEST(RangingFix, LeftRightRuleWithEqualX) {
  // Landmarks one above the other (equal x): the rule decides left or right of them.
  const Vec2 l0{0.0, 0.0}, l1{0.0, 6000.0};
  for (const Pose2& truth : {Pose2{-4000.0, 2500.0, 0.1}, Pose2{4000.0, 3500.0, kPi - 0.2}}) {
    const Observation o0 = observe(truth, l0, 20.0, 1e-3), o1 = observe(truth, l1, 20.0, 1e-3);
    const FixResult f = fix_two_circles(o0, o1, TwoLandmarkRule::kLeftRight,
                                        o0.bearing_rad > o1.bearing_rad, FixOptions{});
    ASSERT_EQ(f.status, FixStatus::kOk);
    expect_pose(f.pose, truth, 1e-9, 1e-12);
  }
}

TEST(RangingFix, LeftRightRuleFailsAcrossTwoCamerasWhereTheBearingDifferenceDoesNot) {
  // The front camera sees l0 slightly left of its centre; a left-looking side camera (yaw +90
  // degrees) sees l1 slightly right of its centre. Comparing image columns says l0 is left of l1,
  // but in the vehicle frame l1 (bearing ~79 degrees) is left of l0 (~11 degrees).
  const Pose2 truth{0.0, 0.0, 0.0};
  const Vec2 l0{5000.0, 1000.0}, l1{1000.0, 5000.0};
  const Observation o0 = observe(truth, l0, 20.0, 1e-3), o1 = observe(truth, l1, 20.0, 1e-3);
  const double u0_from_centre = -std::tan(o0.bearing_rad);            // left of centre: negative
  const double u1_from_centre = -std::tan(o1.bearing_rad - kPi / 2);  // right of centre: positive
  ASSERT_LT(u0_from_centre, 0.0);
  ASSERT_GT(u1_from_centre, 0.0);
  const bool columns_say_l0_left = u0_from_centre < u1_from_centre;
  const FixResult lr =
      fix_two_circles(o0, o1, TwoLandmarkRule::kLeftRight, columns_say_l0_left, FixOptions{});
  const FixResult bd =
      fix_two_circles(o0, o1, TwoLandmarkRule::kBearingDifference, false, FixOptions{});
  ASSERT_EQ(lr.status, FixStatus::kOk);
  ASSERT_EQ(bd.status, FixStatus::kOk);
  expect_pose(bd.pose, truth, 1e-9, 1e-12);
  // The mirror image of the truth in the line l0-l1.
  EXPECT_NEAR(lr.pose.x_mm, 6000.0, 1e-6);
  EXPECT_NEAR(lr.pose.y_mm, 6000.0, 1e-6);
}

TEST(RangingFix, BearingDifferenceIsAmbiguousWhenTheBearingsCannotTellTheSidesApart) {
  // 30 degrees between the landmarks as seen by the vehicle: the mirror solution predicts -30.
  // With 0.3 rad bearing noise the two are within 3 sigma of each other.
  const Pose2 truth{0.0, 0.0, 0.3};
  const Vec2 l0{6000.0, -800.0}, l1{5000.0, 2200.0};
  const Observation o0 = observe(truth, l0, 20.0, 0.3), o1 = observe(truth, l1, 20.0, 0.3);
  EXPECT_EQ(
      fix_two_circles(o0, o1, TwoLandmarkRule::kBearingDifference, false, FixOptions{}).status,
      FixStatus::kAmbiguous);
  const Observation p0 = observe(truth, l0, 20.0, 0.01), p1 = observe(truth, l1, 20.0, 0.01);
  EXPECT_EQ(
      fix_two_circles(p0, p1, TwoLandmarkRule::kBearingDifference, false, FixOptions{}).status,
      FixStatus::kOk);
}

TEST(RangingFix, CirclesThatMissAreRefusedAndNearMissesAreShallow) {
  const Pose2 truth{0.0, 0.0, 0.0};
  Observation o0 = observe(truth, {5000.0, 3000.0}, 30.0, 1e-3);
  Observation o1 = observe(truth, {5000.0, -3000.0}, 30.0, 1e-3);
  o0.range_mm = 2500.0;  // together shorter than the 6 m between the landmarks by 1 m
  o1.range_mm = 2500.0;
  const Observation miss[2] = {o0, o1};
  EXPECT_EQ(fix_from_landmarks(miss, FixOptions{}).status, FixStatus::kNoIntersection);
  o0.range_mm = 2990.0;  // short by 20 mm: within 3 sigma of the range sum -> touching
  o1.range_mm = 2990.0;
  const FixResult near =
      fix_two_circles(o0, o1, TwoLandmarkRule::kBearingDifference, false, FixOptions{});
  EXPECT_TRUE(near.touching);
  EXPECT_EQ(near.status, FixStatus::kShallowGeometry);
}

TEST(RangingFix, ShallowCrossingIsRefused) {
  // Two landmarks 1 m apart seen from 8 m: they subtend about 7 degrees.
  const Pose2 truth{0.0, 0.0, 0.0};
  const Observation obs[2] = {observe(truth, {8000.0, 500.0}, 30.0, 1e-3),
                              observe(truth, {8000.0, -500.0}, 30.0, 1e-3)};
  EXPECT_EQ(fix_from_landmarks(obs, FixOptions{}).status, FixStatus::kShallowGeometry);
  FixOptions loose;
  loose.min_crossing_angle_rad = deg_to_rad(5.0);
  EXPECT_EQ(fix_from_landmarks(obs, loose).status, FixStatus::kOk);
}

// The same shallow pair read with face yaws (the tags' full poses, 1 degree sigma): the face yaws
// constrain what the circles do not; turned on, the fix is seeded from the two single-landmark
// poses and refined over both, its covariance covering the error (the default). Off, refused.
TEST(RangingFix, ShallowPairWithFaceYawsIsSeededFromThem) {
  const Pose2 truth{0.0, 0.0, 0.1};
  Observation obs[2] = {observe(truth, {8000.0, 500.0}, 30.0, 1e-3),
                        observe(truth, {8000.0, -500.0}, 30.0, 1e-3)};
  const double yaw_sigma_rad = deg_to_rad(1.0);
  for (Observation& o : obs) {
    o.has_face_yaw = true;
    o.landmark_facing_rad = M_PI;  // facing the vehicle
    o.face_yaw_rad = wrap_angle_rad(o.landmark_facing_rad - truth.theta_rad);
    o.face_yaw_var_rad2 = yaw_sigma_rad * yaw_sigma_rad;
  }
  FixOptions off;
  off.face_yaw_pairs_below_crossing = false;
  EXPECT_EQ(fix_from_landmarks(obs, off).status, FixStatus::kShallowGeometry);
  const FixOptions on;
  EXPECT_TRUE(on.face_yaw_pairs_below_crossing);
  const FixResult exact = fix_from_landmarks(obs, on);
  ASSERT_EQ(exact.status, FixStatus::kOk) << fix_status_name(exact.status);
  expect_pose(exact.pose, truth, 1e-6, 1e-9);
  // Seeded noise: the refined pose inside its own 3 sigma (chi-square, 3 dof, 14.16 = 0.997).
  std::mt19937 rng(3);
  std::normal_distribution<double> n01(0.0, 1.0);
  int inside = 0, ok = 0;
  for (int k = 0; k < 200; ++k) {
    Observation noisy[2] = {obs[0], obs[1]};
    for (Observation& o : noisy) {
      o.range_mm += 30.0 * n01(rng);
      o.bearing_rad += 1e-3 * n01(rng);
      o.face_yaw_rad += yaw_sigma_rad * n01(rng);
    }
    const FixResult f = fix_from_landmarks(noisy, on);
    if (f.status != FixStatus::kOk) continue;
    ++ok;
    Eigen::Vector3d d(f.pose.x_mm - truth.x_mm, f.pose.y_mm - truth.y_mm,
                      wrap_angle_rad(f.pose.theta_rad - truth.theta_rad));
    inside += d.dot(f.cov.ldlt().solve(d)) <= 14.16;
  }
  EXPECT_GE(ok, 190);
  EXPECT_GE(inside, ok * 97 / 100) << inside << " of " << ok;
}

TEST(RangingFix, OneLandmarkNeverFixes) {
  const Observation o = observe({0, 0, 0}, {3000.0, 0.0}, 10.0, 1e-3);
  EXPECT_EQ(fix_from_landmarks(std::span<const Observation>(&o, 1), FixOptions{}).status,
            FixStatus::kTooFew);
  EXPECT_EQ(fix_from_landmarks({}, FixOptions{}).status, FixStatus::kTooFew);
}

TEST(RangingFix, TrilaterationIsExactOnNoiseFreeInput) {
  const Pose2 truth{52345.6, -18765.4, 2.5};
  const std::vector<Vec2> lms = {{55000.0, -15000.0},
                                 {49000.0, -14000.0},
                                 {50000.0, -23000.0},
                                 {57000.0, -21000.0},
                                 {53000.0, -12500.0}};
  for (std::size_t n = 3; n <= lms.size(); ++n) {
    std::vector<Observation> obs;
    for (std::size_t i = 0; i < n; ++i) obs.push_back(observe(truth, lms[i], 30.0, 1e-3));
    Vec2 p;
    ASSERT_EQ(trilaterate(obs, FixOptions{}, &p), FixStatus::kOk);
    EXPECT_NEAR(p.x, truth.x_mm, 1e-9);
    EXPECT_NEAR(p.y, truth.y_mm, 1e-9);
    const FixResult t = fix_trilateration(obs, FixOptions{});
    ASSERT_EQ(t.status, FixStatus::kOk);
    expect_pose(t.pose, truth, 1e-9, 1e-12);
    const FixResult f = fix_from_landmarks(obs, FixOptions{});
    ASSERT_EQ(f.status, FixStatus::kOk);
    expect_pose(f.pose, truth, 1e-9, 1e-12);
    EXPECT_EQ(f.dof, static_cast<int>(2 * n - 3));
  }
}

TEST(RangingFix, GaussNewtonConvergesFromAPoorStart) {
  const Pose2 truth{3000.0, 2000.0, -1.0};
  const Observation obs[3] = {observe(truth, {8000.0, 0.0}, 30.0, 1e-3),
                              observe(truth, {6000.0, -4000.0}, 30.0, 1e-3),
                              observe(truth, {0.0, -5000.0}, 30.0, 1e-3)};
  const FixResult f = refine_fix(obs, {3400.0, 1700.0, -0.8}, FixOptions{});
  ASSERT_EQ(f.status, FixStatus::kOk);
  expect_pose(f.pose, truth, 1e-9, 1e-12);
  EXPECT_LT(f.iterations, 10);
}

TEST(RangingFix, CovarianceSizeCheckRefusesAPoorlyDeterminedFix) {
  const Pose2 truth{0.0, 0.0, 0.0};
  const std::vector<Observation> obs = {observe(truth, {6000.0, -1500.0}, 60.0, 3e-4),
                                        observe(truth, {7000.0, 1500.0}, 70.0, 3e-4)};
  const FixResult loose = fix_from_landmarks(obs, FixOptions{});
  ASSERT_EQ(loose.status, FixStatus::kOk);
  const double worst_sd =
      std::sqrt(Eigen::SelfAdjointEigenSolver<Eigen::Matrix2d>(loose.cov.topLeftCorner<2, 2>())
                    .eigenvalues()
                    .maxCoeff());
  FixOptions strict;
  strict.max_position_sd_mm = 0.9 * worst_sd;
  EXPECT_EQ(fix_from_landmarks(obs, strict).status, FixStatus::kShallowGeometry);
  strict.max_position_sd_mm = 1.1 * worst_sd;
  EXPECT_EQ(fix_from_landmarks(obs, strict).status, FixStatus::kOk);
}

TEST(RangingFix, CollinearLandmarksRefuseTheDeterminantsNotTheBearings) {
  const Pose2 truth{0.0, 0.0, 0.0};
  std::vector<Observation> obs = {observe(truth, {4000.0, 1000.0}, 30.0, 1e-3),
                                  observe(truth, {6000.0, 2000.0}, 30.0, 1e-3),
                                  observe(truth, {8000.0, 3000.0}, 30.0, 1e-3)};
  Vec2 p;
  EXPECT_EQ(trilaterate(obs, FixOptions{}, &p), FixStatus::kCollinear);
  EXPECT_EQ(fix_trilateration(obs, FixOptions{}).status, FixStatus::kCollinear);
  obs[2] = observe(truth, {8000.0, 3050.0}, 30.0, 1e-3);  // 50 mm off the line over 4 m
  EXPECT_EQ(trilaterate(obs, FixOptions{}, &p), FixStatus::kCollinear);
  // Seen from far along the line, the widest pair crosses at 8 degrees: refused.
  EXPECT_EQ(fix_from_landmarks(obs, FixOptions{}).status, FixStatus::kShallowGeometry);
  // Landmarks along one rack face seen from 3 m in front of it: the bearings fix the side.
  const Pose2 front{1000.0, -500.0, 0.4};
  std::vector<Observation> rack = {observe(front, {4000.0, -2000.0}, 30.0, 1e-3),
                                   observe(front, {4000.0, 0.0}, 30.0, 1e-3),
                                   observe(front, {4000.0, 1500.0}, 30.0, 1e-3)};
  EXPECT_EQ(trilaterate(rack, FixOptions{}, &p), FixStatus::kCollinear);
  const FixResult f = fix_from_landmarks(rack, FixOptions{});
  ASSERT_EQ(f.status, FixStatus::kOk) << fix_status_name(f.status);
  expect_pose(f.pose, front, 1e-6, 1e-9);
}

// Seeded noisy trials: a random pose among random landmarks 2-8 m away, range noise growing with
// the square of the range (as a tag pose's does), bearing noise 0.5 mrad.
struct Trial {
  Pose2 truth;
  std::vector<Observation> obs;
};

Trial noisy_trial(std::mt19937_64& rng, int n, double map_error_mm) {
  std::uniform_real_distribution<double> uni(0.0, 1.0);
  std::normal_distribution<double> gauss(0.0, 1.0);
  Trial t;
  t.truth = {20000.0 * uni(rng), 20000.0 * uni(rng), kPi * (2 * uni(rng) - 1)};
  // Landmarks spread over a 140-degree field ahead, so no two are nearly in one direction.
  for (int i = 0; i < n; ++i) {
    const double dir =
        t.truth.theta_rad + deg_to_rad(-70.0 + 140.0 * (i + 0.2 + 0.6 * uni(rng)) / n);
    const double range = 2000.0 + 6000.0 * uni(rng);
    const Vec2 lm{t.truth.x_mm + range * std::cos(dir), t.truth.y_mm + range * std::sin(dir)};
    const double sr = 10.0 * (range / 2000.0) * (range / 2000.0), sb = 5e-4;
    Observation o = observe(t.truth, lm, sr, sb);
    o.range_mm += sr * gauss(rng);
    o.bearing_rad = wrap_angle_rad(o.bearing_rad + sb * gauss(rng));
    t.obs.push_back(o);
  }
  if (map_error_mm > 0.0) {
    const double a = 2 * kPi * uni(rng);
    t.obs[0].landmark_mm.x += map_error_mm * std::cos(a);
    t.obs[0].landmark_mm.y += map_error_mm * std::sin(a);
  }
  return t;
}

double nees(const FixResult& f, const Pose2& truth) {
  const Eigen::Vector3d e(f.pose.x_mm - truth.x_mm, f.pose.y_mm - truth.y_mm,
                          wrap_angle_rad(f.pose.theta_rad - truth.theta_rad));
  return e.dot(f.cov.ldlt().solve(e));
}

TEST(RangingFix, CovarianceCoversTheErrorOnSeededTrials) {
  const double gate_3sigma_3dof = 14.16;  // chi2(3) quantile at 0.9973
  for (int n : {2, 3, 5}) {
    std::mt19937_64 rng(1234 + static_cast<unsigned>(n));
    int ok = 0, covered = 0;
    for (int trial = 0; trial < 300; ++trial) {
      const Trial t = noisy_trial(rng, n, 0.0);
      const FixResult f = fix_from_landmarks(t.obs, FixOptions{});
      if (f.status != FixStatus::kOk) continue;
      ++ok;
      covered += nees(f, t.truth) <= gate_3sigma_3dof;
    }
    std::printf("%d landmarks: %d of 300 fixed, 3-sigma coverage %d\n", n, ok, covered);
    EXPECT_GE(ok, 270) << n << " landmarks";
    EXPECT_GE(covered, 0.97 * ok) << n << " landmarks: " << covered << " of " << ok;
  }
}

// A landmark whose map entry is 0.5 m off. The chi-square check can only see the part of the
// error that the other measurements contradict: with two landmarks (one degree of freedom) a map
// error is mostly invisible, which the map-check figure says; with three, the ranges are the only
// redundancy (three bearings already fix the pose) and most errors are refused; with four or more
// the bearings check each other. Measured rates are in docs/design/ranging.md.
TEST(RangingFix, AWrongMapEntryIsRefusedOrFlaggedAsUncheckable) {
  const double gate_3sigma_3dof = 14.16;
  struct Case {
    int n;
    int min_refused;          // of 200
    int max_confident_wrong;  // accepted with the truth outside the 3-sigma ellipsoid
  };
  for (const Case c : {Case{3, 170, 20}, Case{4, 190, 6}, Case{5, 192, 4}}) {
    std::mt19937_64 rng(99 + static_cast<unsigned>(c.n));
    int refused = 0, confident_wrong = 0;
    for (int trial = 0; trial < 200; ++trial) {
      const Trial t = noisy_trial(rng, c.n, 500.0);
      const FixResult f = fix_from_landmarks(t.obs, FixOptions{});
      if (f.status != FixStatus::kOk) {  // mostly kInconsistent; a few geometry refusals
        ++refused;
        continue;
      }
      confident_wrong += nees(f, t.truth) > gate_3sigma_3dof;
    }
    std::printf("%d landmarks, one 0.5 m off: %d of 200 refused, %d confident and wrong\n", c.n,
                refused, confident_wrong);
    EXPECT_GE(refused, c.min_refused) << c.n << " landmarks";
    EXPECT_LE(confident_wrong, c.max_confident_wrong) << c.n << " landmarks";
  }
  // Two landmarks: the map check flags every fix as uncheckable, and a consumer that asks for a
  // checkable map gets kUnverifiable instead of a pose.
  std::mt19937_64 rng(7);
  FixOptions strict;
  strict.max_hidden_map_shift_sigma = 1000.0;
  for (int trial = 0; trial < 50; ++trial) {
    const Trial t = noisy_trial(rng, 2, 500.0);
    const FixResult f = fix_from_landmarks(t.obs, FixOptions{});
    if (f.status != FixStatus::kOk) continue;
    EXPECT_GT(f.hidden_map_shift_sigma, 1000.0);
    EXPECT_EQ(fix_from_landmarks(t.obs, strict).status, FixStatus::kUnverifiable);
  }
  // Three landmarks with the map correct: the strict consumer still gets its fixes.
  std::mt19937_64 rng3(8);
  int ok3 = 0;
  for (int trial = 0; trial < 50; ++trial) {
    ok3 += fix_from_landmarks(noisy_trial(rng3, 3, 0.0).obs, strict).status == FixStatus::kOk;
  }
  EXPECT_GE(ok3, 45);
}

TEST(RangingFix, TheSystematicShareOfAFixIsItsResponseToTheRepeatedShares) {
  // A fix's covariance is its response to the observations' covariances (cov J^T W R W J cov):
  // the shares its observations say repeat give that part of it, all of them all of it, none
  // nothing; with face yaws too.
  const Pose2 truth{3000.0, 2000.0, -1.0};
  std::vector<Observation> obs = {observe(truth, {8000.0, 0.0}, 30.0, 1e-3),
                                  observe(truth, {6000.0, -4000.0}, 40.0, 2e-3),
                                  observe(truth, {0.0, -5000.0}, 20.0, 1e-3)};
  obs[1].has_face_yaw = true;
  obs[1].face_yaw_rad = wrap_angle_rad(0.4 - truth.theta_rad);
  obs[1].landmark_facing_rad = 0.4;
  obs[1].face_yaw_var_rad2 = 1e-4;
  obs[1].face_yaw_cov = Eigen::Vector2d(0.01, 1e-7);
  const FixResult f = fix_from_landmarks(obs, FixOptions{});
  ASSERT_EQ(f.status, FixStatus::kOk);
  EXPECT_TRUE(fix_systematic_cov(obs, f).isZero(0.0));
  for (const double share : {0.3, 1.0}) {
    std::vector<Observation> told = obs;
    for (Observation& o : told) {
      o.systematic_cov.topLeftCorner<2, 2>() = share * o.cov;
      if (!o.has_face_yaw) continue;
      o.systematic_cov(2, 2) = share * o.face_yaw_var_rad2;
      o.systematic_cov.block<2, 1>(0, 2) = share * o.face_yaw_cov;
      o.systematic_cov.block<1, 2>(2, 0) = share * o.face_yaw_cov.transpose();
    }
    const Eigen::Matrix3d S = fix_systematic_cov(told, f);
    EXPECT_LE((S - share * f.cov).cwiseAbs().maxCoeff(), 1e-6 * f.cov.cwiseAbs().maxCoeff())
        << share;
  }
  FixResult refused = f;
  refused.status = FixStatus::kInconsistent;
  EXPECT_TRUE(fix_systematic_cov(obs, refused).isZero(0.0));
}

// Trials whose every range is scaled by one common error (a focal length off) besides its own
// noise, the common share told per landmark: the fraction of fixes inside their 3-sigma
// ellipsoid, the median position sd and the p95 position error, with the share weighed per
// landmark (alone, or with lens_cov_change) or estimated as the one error it is.
struct ScaleCoverage {
  double inside = 0.0, median_sd_mm = 0.0, p95_mm = 0.0;
};
enum class LensWeighing { kPerLandmark, kPerLandmarkChanged, kEstimated };

double quantile(std::vector<double> v, double q) {
  const auto k = static_cast<std::ptrdiff_t>(q * static_cast<double>(v.size() - 1));
  std::nth_element(v.begin(), v.begin() + k, v.end());
  return v[static_cast<std::size_t>(k)];
}

ScaleCoverage coverage_under_common_scale(const std::vector<Vec2>& landmarks, LensWeighing how) {
  const Pose2 truth{3000.0, 2000.0, 0.3};
  constexpr double kScale = 0.002, kRangeMm = 3.0, kBearingRad = 5e-4;
  std::mt19937_64 rng(7);
  std::normal_distribution<double> n(0.0, 1.0);
  FixOptions opt;
  opt.lens_in_weights = how == LensWeighing::kEstimated;
  int inside = 0;
  std::vector<double> sd, err;
  for (int t = 0; t < 2000; ++t) {
    const double common = kScale * n(rng);
    std::vector<Observation> obs;
    for (const Vec2& l : landmarks) {
      Observation o = observe(truth, l, kRangeMm, kBearingRad);
      o.cov(0, 0) += kScale * kScale * o.range_mm * o.range_mm;
      o.systematic_cov(0, 0) = kScale * kScale * o.range_mm * o.range_mm;
      o.lens_response(0, 0) = kScale * o.range_mm;
      o.range_mm = o.range_mm * (1.0 + common) + kRangeMm * n(rng);
      o.bearing_rad += kBearingRad * n(rng);
      obs.push_back(o);
    }
    FixResult f = fix_from_landmarks(obs, opt);
    if (f.status != FixStatus::kOk) continue;
    EXPECT_EQ(f.lens_estimated, how == LensWeighing::kEstimated);
    if (how == LensWeighing::kPerLandmarkChanged) f.cov += lens_cov_change(obs, f);
    const Eigen::Vector3d e(f.pose.x_mm - truth.x_mm, f.pose.y_mm - truth.y_mm,
                            wrap_angle_rad(f.pose.theta_rad - truth.theta_rad));
    inside += e.dot(f.cov.ldlt().solve(e)) <= 14.16;
    sd.push_back(std::sqrt(f.cov.topLeftCorner<2, 2>().trace()));
    err.push_back(std::hypot(e.x(), e.y()));
  }
  if (sd.size() < 1900) return {};
  return {static_cast<double>(inside) / static_cast<double>(sd.size()), quantile(sd, 0.5),
          quantile(err, 0.95)};
}

TEST(RangingFix, ACommonRangeScaleIsOneErrorNotOnePerLandmark) {
  // Seen from (3, 2) m heading 0.3 rad. A narrow fan ahead: the bearings barely fix the distance,
  // the common scale moves the fix along the fan, which per-landmark shares average down. A wide
  // fan: the bearings fix the position and the common scale is mostly residual, which
  // per-landmark shares overstate and an estimate of it removes from the ranges.
  const std::vector<Vec2> narrow = {{7700.0, 3400.0}, {9200.0, 4000.0}, {8300.0, 4400.0}};
  const std::vector<Vec2> wide = {{7500.0, 1500.0}, {8000.0, 4500.0}, {6000.0, 5500.0}};
  ScaleCoverage c[2][3];
  for (int fan = 0; fan < 2; ++fan) {
    for (int how = 0; how < 3; ++how) {
      c[fan][how] =
          coverage_under_common_scale(fan == 0 ? narrow : wide, static_cast<LensWeighing>(how));
      std::printf("%s fan, %s: inside 3 sigma %.4f, median sd %.2f mm, p95 error %.2f mm\n",
                  fan == 0 ? "narrow" : "wide",
                  how == 0   ? "per landmark"
                  : how == 1 ? "per landmark + change"
                             : "estimated",
                  c[fan][how].inside, c[fan][how].median_sd_mm, c[fan][how].p95_mm);
    }
  }
  EXPECT_LT(c[0][0].inside, 0.98);
  for (int fan = 0; fan < 2; ++fan) {
    EXPECT_GE(c[fan][1].inside, 0.99);
    EXPECT_GE(c[fan][2].inside, 0.99);
    // The estimate is at least as accurate as either per-landmark weighing, and says so.
    EXPECT_LE(c[fan][2].p95_mm, 1.02 * std::min(c[fan][0].p95_mm, c[fan][1].p95_mm));
    EXPECT_LE(c[fan][2].median_sd_mm, 1.02 * c[fan][1].median_sd_mm);
  }
  EXPECT_LT(c[1][1].median_sd_mm, 0.7 * c[1][0].median_sd_mm);
  EXPECT_LT(c[0][2].p95_mm, 0.9 * c[0][1].p95_mm);
  EXPECT_LT(c[1][2].p95_mm, 0.8 * c[1][1].p95_mm);
}

TEST(RangingFix, AnEstimatedLensErrorIsHeldOnceAndOnlyWhereTheCovarianceHoldsIt) {
  const Pose2 truth{3000.0, 2000.0, 0.3};
  // Variances of 1e2 mm^2 beside 1e-9 rad^2, as on rendered frames: the check that the covariance
  // holds the response must not take the units' spread for a singular matrix.
  std::vector<Observation> obs = {observe(truth, {7700.0, 3400.0}, 10.0, 5e-5),
                                  observe(truth, {9200.0, 4000.0}, 10.0, 5e-5),
                                  observe(truth, {8300.0, 4400.0}, 10.0, 5e-5)};
  for (Observation& o : obs) {
    o.lens_response.col(0) << 0.002 * o.range_mm, -1e-4, 0.0;
    o.lens_response.col(1) << 0.001 * o.range_mm, 2e-4, 0.0;
    o.cov += o.lens_response.topRows<2>() * o.lens_response.topRows<2>().transpose();
    o.systematic_cov.topLeftCorner<2, 2>() = o.cov;  // everything repeats
  }
  const FixResult f = fix_from_landmarks(obs, FixOptions{});
  ASSERT_EQ(f.status, FixStatus::kOk);
  ASSERT_TRUE(f.lens_estimated);
  // All of the covariance repeats, the common lens error included once: the systematic share is
  // the whole covariance, through the gains of the estimate that held the lens error.
  const Eigen::Matrix3d S = fix_systematic_cov(obs, f);
  EXPECT_LE((S - f.cov).cwiseAbs().maxCoeff(), 1e-6 * f.cov.cwiseAbs().maxCoeff());
  // A response the covariance does not hold is not a share of it: weighed per landmark.
  std::vector<Observation> untold = obs;
  untold[1].cov = Eigen::Vector2d(100.0, 2.5e-9).asDiagonal();
  const FixResult g = fix_from_landmarks(untold, FixOptions{});
  ASSERT_EQ(g.status, FixStatus::kOk);
  EXPECT_FALSE(g.lens_estimated);
  FixOptions per_landmark;
  per_landmark.lens_in_weights = false;
  const FixResult h = fix_from_landmarks(untold, per_landmark);
  EXPECT_EQ(g.pose.x_mm, h.pose.x_mm);
  EXPECT_EQ(g.pose.y_mm, h.pose.y_mm);
}

TEST(RangingFix, LensChangeIsZeroWithoutACommonShareAndKeepsTheCovariancePositive) {
  const Pose2 truth{3000.0, 2000.0, 0.3};
  // Around the vehicle the common scale mostly cancels: the change may be negative there, never
  // by more than the per-landmark shares the covariance holds.
  std::vector<Observation> obs = {observe(truth, {8000.0, 2000.0}, 10.0, 1e-3),
                                  observe(truth, {0.0, 6000.0}, 10.0, 1e-3),
                                  observe(truth, {0.0, -2000.0}, 10.0, 1e-3)};
  FixOptions per_landmark;
  per_landmark.lens_in_weights = false;
  FixResult f = fix_from_landmarks(obs, per_landmark);
  ASSERT_EQ(f.status, FixStatus::kOk);
  EXPECT_TRUE(lens_cov_change(obs, f).isZero(0.0));
  for (Observation& o : obs) {
    o.cov(0, 0) += 1e-4 * o.range_mm * o.range_mm;
    o.lens_response(0, 0) = 1e-2 * o.range_mm;
  }
  const FixResult estimated = fix_from_landmarks(obs, FixOptions{});
  ASSERT_EQ(estimated.status, FixStatus::kOk);
  ASSERT_TRUE(estimated.lens_estimated);
  EXPECT_TRUE(lens_cov_change(obs, estimated).isZero(0.0));
  f = fix_from_landmarks(obs, per_landmark);
  ASSERT_EQ(f.status, FixStatus::kOk);
  const Eigen::Matrix3d changed = f.cov + lens_cov_change(obs, f);
  EXPECT_GT(Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d>(changed).eigenvalues().minCoeff(), 0.0);
  FixResult refused = f;
  refused.status = FixStatus::kInconsistent;
  EXPECT_TRUE(lens_cov_change(obs, refused).isZero(0.0));
}

}  // namespace
}  // namespace agv::ranging
