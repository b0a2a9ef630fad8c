// Face yaws in the prior-free fix: each landmark seen by its full tag pose also says the direction
// of its face normal in the vehicle frame, which with the landmark's surveyed facing says the
// heading. Simulated from the ranging library's own corner-noise model (150 mm tag, f = 1000 px,
// 0.3 px corners, a full tag pose drawn from its covariance) at 2-8 m: the fix with face yaws
// against the same observations without them, on a correct map and with one landmark's map entry
// 0.5 m off in 36 directions. Measured figures are in docs/design/ranging.md.
#include <gtest/gtest.h>

#include <Eigen/Cholesky>
#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <random>
#include <vector>

#include "agv/ranging/fix.hpp"
#include "agv/ranging/observe.hpp"
#include "agv/ranging/range_models.hpp"

namespace agv::ranging {
namespace {

constexpr double kFocalPx = 1000.0;
constexpr double kTagMm = 150.0;
constexpr double kCornerSigmaPx = 0.3;
constexpr double kGate3Sigma3Dof = 14.16;  // chi2(3) quantile at 0.9973

struct Landmark {
  Vec2 xy_mm;
  double facing_rad = 0.0;     // face normal in W, out of the printed face
  double mount_yaw_rad = 0.0;  // the camera that sees it, yawed on the vehicle towards it
};

// The landmark (1.2 m up) seen from truth by a camera 1 m up and 300 mm ahead of the reference
// point, yawed by lm.mount_yaw_rad: the true tag pose, its corner-noise covariance, a pose drawn
// from it (noisy), and the fix's input from that through fix_observation, with the map saying
// map_xy_mm.
Observation observe_tag(const Pose2& truth, const Landmark& lm, Vec2 map_xy_mm, bool noisy,
                        std::mt19937_64* rng) {
  RangingMount mount;
  mount.x_mm = 300.0;
  mount.z_mm = 1000.0;
  mount.yaw_rad = lm.mount_yaw_rad;
  const double c = std::cos(lm.facing_rad), s = std::sin(lm.facing_rad);
  Eigen::Matrix3d R_WT;  // x page right, y page down, z into the face
  R_WT.col(0) = Eigen::Vector3d(-s, c, 0.0);
  R_WT.col(1) = Eigen::Vector3d(0.0, 0.0, -1.0);
  R_WT.col(2) = Eigen::Vector3d(-c, -s, 0.0);
  const Eigen::Matrix3d R_VW =
      Eigen::AngleAxisd(-truth.theta_rad, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  const Eigen::Vector3d p_V =
      R_VW * Eigen::Vector3d(lm.xy_mm.x - truth.x_mm, lm.xy_mm.y - truth.y_mm, 1200.0);
  const Eigen::Matrix3d R_VC = rotation_vehicle_from_camera(mount);
  Eigen::Vector3d t_C = R_VC.transpose() * (p_V - Eigen::Vector3d(mount.x_mm, 0.0, mount.z_mm));
  Eigen::Matrix3d R_CT = R_VC.transpose() * R_VW * R_WT;
  const Eigen::Matrix<double, 6, 6> cov6 =
      tag_pose_covariance(kFocalPx, kTagMm, t_C, R_CT, kCornerSigmaPx);
  if (noisy) {
    std::normal_distribution<double> n01(0.0, 1.0);
    Eigen::Matrix<double, 6, 1> e;
    for (int i = 0; i < 6; ++i) e(i) = n01(*rng);
    const Eigen::Matrix<double, 6, 1> d = Eigen::Matrix<double, 6, 6>(cov6.llt().matrixL()) * e;
    const Eigen::Vector3d w = d.head<3>();
    if (w.norm() > 0.0) R_CT = Eigen::AngleAxisd(w.norm(), w.normalized()) * R_CT;
    t_C += d.tail<3>();
  }
  LandmarkObservation seen;
  seen.landmark_xy_mm = map_xy_mm;
  seen.landmark_facing_rad = lm.facing_rad;
  seen.pose = range_bearing_from_tag_pose(mount, t_C, R_CT, cov6);
  return fix_observation(seen, true);
}

std::vector<Observation> without_face_yaw(std::vector<Observation> obs) {
  for (Observation& o : obs) o.has_face_yaw = false;
  return obs;
}

// A random pose with n landmarks 2-8 m away spread over a 140-degree field (as the fix tests'
// trials), each seen min_oblique_deg to max_oblique_deg off face-on, to either side, by a camera
// yawed towards it within +-20 degrees. Face-on a tag's yaw is nearly unobservable (the two IPPE
// solutions), obliquely it is good to a degree or two.
struct Scene {
  Pose2 truth;
  std::vector<Landmark> lms;
};

Scene random_scene(std::mt19937_64& rng, int n, double min_oblique_deg = 0.0,
                   double max_oblique_deg = 45.0) {
  std::uniform_real_distribution<double> uni(0.0, 1.0);
  Scene sc;
  sc.truth = {20000.0 * uni(rng), 20000.0 * uni(rng), kPi * (2 * uni(rng) - 1)};
  for (int i = 0; i < n; ++i) {
    const double dir =
        sc.truth.theta_rad + deg_to_rad(-70.0 + 140.0 * (i + 0.2 + 0.6 * uni(rng)) / n);
    const double range = 2000.0 + 6000.0 * uni(rng);
    Landmark lm;
    lm.xy_mm = {sc.truth.x_mm + range * std::cos(dir), sc.truth.y_mm + range * std::sin(dir)};
    const double oblique = min_oblique_deg + (max_oblique_deg - min_oblique_deg) * uni(rng);
    lm.facing_rad = wrap_angle_rad(dir + kPi + deg_to_rad(uni(rng) < 0.5 ? oblique : -oblique));
    lm.mount_yaw_rad = wrap_angle_rad(dir - sc.truth.theta_rad + deg_to_rad(40.0 * uni(rng) - 20));
    sc.lms.push_back(lm);
  }
  return sc;
}

std::vector<Observation> observe_scene(const Scene& sc, const std::vector<Vec2>& map, bool noisy,
                                       std::mt19937_64* rng) {
  std::vector<Observation> obs;
  for (std::size_t i = 0; i < sc.lms.size(); ++i) {
    obs.push_back(observe_tag(sc.truth, sc.lms[i], map[i], noisy, rng));
  }
  return obs;
}

std::vector<Vec2> true_map(const Scene& sc) {
  std::vector<Vec2> m;
  for (const Landmark& l : sc.lms) m.push_back(l.xy_mm);
  return m;
}

double nees(const FixResult& f, const Pose2& truth) {
  const Eigen::Vector3d e(f.pose.x_mm - truth.x_mm, f.pose.y_mm - truth.y_mm,
                          wrap_angle_rad(f.pose.theta_rad - truth.theta_rad));
  return e.dot(f.cov.ldlt().solve(e));
}

double percentile(std::vector<double> v, double q) {
  if (v.empty()) return 0.0;
  std::sort(v.begin(), v.end());
  return v[static_cast<std::size_t>(q * static_cast<double>(v.size() - 1) + 0.5)];
}

TEST(RangingFaceYaw, NoiseFreeTagPosesGiveTheExactPoseWithSixMeasurements) {
  std::mt19937_64 rng(3);
  for (int trial = 0; trial < 20; ++trial) {
    const Scene sc = random_scene(rng, 2);
    const std::vector<Observation> obs = observe_scene(sc, true_map(sc), false, &rng);
    ASSERT_TRUE(obs[0].has_face_yaw && obs[1].has_face_yaw);
    // The face yaw predicted from the truth is the landmark's facing minus the heading.
    EXPECT_NEAR(
        wrap_angle_rad(obs[0].landmark_facing_rad - sc.truth.theta_rad - obs[0].face_yaw_rad), 0.0,
        1e-9);
    const FixResult f = fix_from_landmarks(obs, FixOptions{});
    ASSERT_EQ(f.status, FixStatus::kOk) << fix_status_name(f.status);
    EXPECT_EQ(f.dof, 3);
    EXPECT_LT(f.chi2, 1e-9);
    EXPECT_NEAR(f.pose.x_mm, sc.truth.x_mm, 1e-5);
    EXPECT_NEAR(f.pose.y_mm, sc.truth.y_mm, 1e-5);
    EXPECT_NEAR(wrap_angle_rad(f.pose.theta_rad - sc.truth.theta_rad), 0.0, 1e-9);
  }
}

// Two landmarks, landmark 0's map entry 0.5 m off in 36 directions, 20 scenes: without face yaws
// the errors along the circle around landmark 1 turn the pose about it unseen; the face yaws see
// the turn where they are good enough (oblique views). The same noisy observations go into both
// fixes; "strict" adds the map check at 100 sigma.
struct WrongMapCount {
  int ok = 0, wrong = 0;
  double worst_mm = 0.0;
};

void count_fix(const std::vector<Observation>& obs, const FixOptions& opt, const Pose2& truth,
               WrongMapCount* c) {
  const FixResult f = fix_from_landmarks(obs, opt);
  if (f.status != FixStatus::kOk) return;
  ++c->ok;
  if (nees(f, truth) > kGate3Sigma3Dof) {
    ++c->wrong;
    c->worst_mm =
        std::max(c->worst_mm, std::hypot(f.pose.x_mm - truth.x_mm, f.pose.y_mm - truth.y_mm));
  }
}

TEST(RangingFaceYaw, TwoLandmarksWithFaceYawsRefuseMostWrongMapEntries) {
  FixOptions strict;
  strict.max_hidden_map_shift_sigma = 100.0;
  struct Set {
    const char* name;
    double min_deg, max_deg;
    int min_wrong_without, max_wrong_with, max_wrong_strict;
  };
  for (const Set set : {Set{"0-45 deg off face-on", 0.0, 45.0, 100, 100, 5},
                        Set{"20-60 deg off face-on", 20.0, 60.0, 100, 45, 5}}) {
    std::mt19937_64 rng(54);
    WrongMapCount without, with, with_strict;
    int total = 0;
    for (int scene = 0; scene < 20; ++scene) {
      const Scene sc = random_scene(rng, 2, set.min_deg, set.max_deg);
      for (int k = 0; k < 36; ++k) {
        std::vector<Vec2> map = true_map(sc);
        const double a = 2.0 * kPi * k / 36.0;
        map[0].x += 500.0 * std::cos(a);
        map[0].y += 500.0 * std::sin(a);
        const std::vector<Observation> obs = observe_scene(sc, map, true, &rng);
        ++total;
        count_fix(without_face_yaw(obs), FixOptions{}, sc.truth, &without);
        count_fix(obs, FixOptions{}, sc.truth, &with);
        count_fix(obs, strict, sc.truth, &with_strict);
      }
    }
    std::printf(
        "%s, map 0.5 m off, %d fixes: ok / outside 3 sigma (worst mm): without face yaw"
        " %d / %d (%.0f); with %d / %d (%.0f); with, map check 100: %d / %d (%.0f)\n",
        set.name, total, without.ok, without.wrong, without.worst_mm, with.ok, with.wrong,
        with.worst_mm, with_strict.ok, with_strict.wrong, with_strict.worst_mm);
    EXPECT_GE(without.wrong, set.min_wrong_without) << set.name;
    EXPECT_LE(with.wrong, set.max_wrong_with) << set.name;
    EXPECT_LE(with_strict.wrong, set.max_wrong_strict) << set.name;
  }
}

// Correct map: the face yaws must not make the fix worse, its covariance must still cover the
// error, and its chi-square must be honest (mean chi2 / dof near 1). Also how many correct fixes
// the map check at 100 sigma costs.
void correct_map_trials(const char* name, double min_deg, double max_deg) {
  std::mt19937_64 rng(541);
  std::vector<double> pos_mm[2], head_deg[2], hidden;
  int ok[2] = {0, 0}, covered[2] = {0, 0}, chi2_fixes = 0, unverifiable = 0;
  double chi2_sum = 0.0, dof_sum = 0.0;
  FixOptions strict;
  strict.max_hidden_map_shift_sigma = 100.0;
  constexpr int kTrials = 500;
  for (int trial = 0; trial < kTrials; ++trial) {
    const Scene sc = random_scene(rng, 2, min_deg, max_deg);
    const std::vector<Observation> with = observe_scene(sc, true_map(sc), true, &rng);
    for (int use = 0; use < 2; ++use) {
      const FixResult f =
          fix_from_landmarks(use == 1 ? with : without_face_yaw(with), FixOptions{});
      if (use == 1 && (f.status == FixStatus::kOk || f.status == FixStatus::kInconsistent)) {
        ++chi2_fixes;
        chi2_sum += f.chi2;
        dof_sum += f.dof;
      }
      if (f.status != FixStatus::kOk) continue;
      ++ok[use];
      covered[use] += nees(f, sc.truth) <= kGate3Sigma3Dof;
      pos_mm[use].push_back(std::hypot(f.pose.x_mm - sc.truth.x_mm, f.pose.y_mm - sc.truth.y_mm));
      head_deg[use].push_back(
          std::abs(rad_to_deg(wrap_angle_rad(f.pose.theta_rad - sc.truth.theta_rad))));
      if (use == 1) {
        hidden.push_back(f.hidden_map_shift_sigma);
        unverifiable += fix_from_landmarks(with, strict).status == FixStatus::kUnverifiable;
      }
    }
  }
  const double chi2_per_dof = chi2_sum / dof_sum;
  for (int use = 0; use < 2; ++use) {
    std::printf(
        "%s, %s face yaw: %d of %d ok, 3-sigma coverage %d, position p50 %.1f p95 %.1f"
        " mm, heading p50 %.3f p95 %.3f deg\n",
        name, use ? "with" : "without", ok[use], kTrials, covered[use],
        percentile(pos_mm[use], 0.5), percentile(pos_mm[use], 0.95), percentile(head_deg[use], 0.5),
        percentile(head_deg[use], 0.95));
  }
  std::printf(
      "%s, with face yaw: mean chi2/dof %.3f over %d fixes; map-check figure p50 %.1f,"
      " p95 %.1f sigma; %d unverifiable at 100\n",
      name, chi2_per_dof, chi2_fixes, percentile(hidden, 0.5), percentile(hidden, 0.95),
      unverifiable);
  EXPECT_GE(ok[1], ok[0] - kTrials / 50) << name;
  EXPECT_LE(percentile(pos_mm[1], 0.95), 1.01 * percentile(pos_mm[0], 0.95)) << name;
  EXPECT_LE(percentile(head_deg[1], 0.95), 1.01 * percentile(head_deg[0], 0.95)) << name;
  EXPECT_GE(covered[1], 0.97 * ok[1]) << name;
  EXPECT_NEAR(chi2_per_dof, 1.0, 0.15) << name;
}

TEST(RangingFaceYaw, CorrectMapFixesAreNoWorseAndTheirChiSquareIsHonest) {
  correct_map_trials("0-45 deg off face-on", 0.0, 45.0);
  correct_map_trials("20-60 deg off face-on", 20.0, 60.0);
}

// Two landmarks 3-12 degrees apart as seen from the vehicle (one behind the other, 2-8 m away,
// 20-45 deg off face-on): their circles cross below 15 degrees, so they are refused unless seeded
// from their face yaws (FixOptions::face_yaw_pairs_below_crossing, on by default). Seeded, the
// position along the bisector rests on the face yaws: a wrong map entry must not be let through
// more often than by the wider pairs above, and a correct map must be covered.
TEST(RangingFaceYaw, ShallowPairsSeededFromFaceYawsLetNoMoreWrongMapEntriesThrough) {
  std::mt19937_64 rng(55);
  std::uniform_real_distribution<double> uni(0.0, 1.0);
  WrongMapCount wrong_map;
  int total = 0, correct_ok = 0, correct_covered = 0, refused_off = 0;
  for (int scene = 0; scene < 20; ++scene) {
    Scene sc = random_scene(rng, 2, 20.0, 45.0);
    // Landmark 1 moved to 3-12 degrees beside landmark 0's direction, facing the vehicle as before.
    const double d0 =
        std::atan2(sc.lms[0].xy_mm.y - sc.truth.y_mm, sc.lms[0].xy_mm.x - sc.truth.x_mm);
    const double d1 =
        d0 + deg_to_rad(uni(rng) < 0.5 ? 3.0 + 9.0 * uni(rng) : -3.0 - 9.0 * uni(rng));
    const double r1 = 2000.0 + 6000.0 * uni(rng);
    const double oblique = wrap_angle_rad(
        sc.lms[1].facing_rad -
        (std::atan2(sc.lms[1].xy_mm.y - sc.truth.y_mm, sc.lms[1].xy_mm.x - sc.truth.x_mm) + kPi));
    sc.lms[1].xy_mm = {sc.truth.x_mm + r1 * std::cos(d1), sc.truth.y_mm + r1 * std::sin(d1)};
    sc.lms[1].facing_rad = wrap_angle_rad(d1 + kPi + oblique);
    sc.lms[1].mount_yaw_rad = sc.lms[0].mount_yaw_rad;
    const std::vector<Observation> right = observe_scene(sc, true_map(sc), true, &rng);
    FixOptions off;
    off.face_yaw_pairs_below_crossing = false;
    refused_off += fix_from_landmarks(right, off).status == FixStatus::kShallowGeometry;
    const FixResult f = fix_from_landmarks(right, FixOptions{});
    if (f.status == FixStatus::kOk) {
      ++correct_ok;
      correct_covered += nees(f, sc.truth) <= kGate3Sigma3Dof;
    }
    for (int k = 0; k < 36; ++k) {
      std::vector<Vec2> map = true_map(sc);
      const double a = 2.0 * kPi * k / 36.0;
      map[0].x += 500.0 * std::cos(a);
      map[0].y += 500.0 * std::sin(a);
      ++total;
      count_fix(observe_scene(sc, map, true, &rng), FixOptions{}, sc.truth, &wrong_map);
    }
  }
  std::printf(
      "shallow pairs: %d of 20 refused as shallow without seeding; correct map %d ok, %d inside 3"
      " sigma; map 0.5 m off, %d fixes: %d ok, %d outside 3 sigma (worst %.0f mm)\n",
      refused_off, correct_ok, correct_covered, total, wrong_map.ok, wrong_map.wrong,
      wrong_map.worst_mm);
  EXPECT_GE(refused_off, 15);
  EXPECT_GE(correct_ok, 10);
  EXPECT_GE(correct_covered, correct_ok - 1);
  EXPECT_LE(wrong_map.wrong, 45);  // the wider 20-60 deg pairs' bound above
}

}  // namespace
}  // namespace agv::ranging
