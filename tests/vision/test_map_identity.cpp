// Map-guided identity (docs/design/map_identity.md): the pose gate, the module check, and the whole
// localizer on rendered frames whose QR code is covered.
#include <gtest/gtest.h>

#include <Eigen/Dense>
#include <cmath>
#include <random>
#include <string>

#include "../support/prediction.hpp"
#include "agv/sim/render.hpp"
#include "agv/vision/landmark_localizer.hpp"
#include "agv/vision/map_identity.hpp"

using namespace agv;
using namespace agv::vision;

namespace {

Eigen::Matrix3d diag_cov(double sigma_mm, double sigma_deg) {
  Eigen::Matrix3d c = Eigen::Matrix3d::Zero();
  c(0, 0) = c(1, 1) = sigma_mm * sigma_mm;
  c(2, 2) = deg_to_rad(sigma_deg) * deg_to_rad(sigma_deg);
  return c;
}

LandmarkMap two_landmarks(double spacing_mm) {
  LandmarkMap m;
  m.entries[1] = {1, {0.0, 0.0, 0.0}};
  m.entries[2] = {2, {spacing_mm, 0.0, 0.0}};
  return m;
}

using testsupport::predict;

// The fitted square as the vision stage reports it for a landmark seen at `l_in_v` at turn q:
// beta = forward + q * 90 deg.
struct Measured {
  Vec2 c;
  double beta;
};
Measured measure(const Pose2& l_in_v, int q) {
  return {{l_in_v.x_mm, l_in_v.y_mm}, l_in_v.theta_rad + q * kPi / 2.0};
}

const std::array<bool, 4> kOnlyTurn0{true, false, false, false};
const std::array<bool, 4> kAllTurns{true, true, true, true};

}  // namespace

TEST(MapIdentityGate, UniqueCandidateAccepted) {
  const LandmarkMap map = two_landmarks(150.0);
  const Pose2 v{-10.0, 5.0, deg_to_rad(30.0)};
  const Pose2 l = compose(inverse(v), map.entries.at(1).pose);
  const Measured m = measure(l, 0);
  const auto d = gate_identity(m.c, m.beta, diag_cov(0.05, 0.01), kOnlyTurn0, predict(v, 3.0, 0.3),
                               map, MapIdentityConfig{});
  EXPECT_EQ(d.result, MapIdentityResult::kAccepted) << to_string(d.result);
  EXPECT_EQ(d.id, 1u);
  EXPECT_EQ(d.turn, 0);
  EXPECT_LT(d.d2_best, 1e-6);
  EXPECT_GT(d.d2_second, 1000.0);  // 150 mm at ~4.3 mm sigma
}

TEST(MapIdentityGate, TwoPlausibleRefused) {
  // 12 mm apart with 3 mm prediction sigma: both within a few sigma.
  const LandmarkMap map = two_landmarks(12.0);
  const Pose2 v{6.0, 0.0, 0.0};
  const Pose2 l = compose(inverse(v), map.entries.at(1).pose);
  const Measured m = measure(l, 0);
  const auto d = gate_identity(m.c, m.beta, diag_cov(0.05, 0.01), kOnlyTurn0,
                               predict({0.0, 0.0, 0.0}, 3.0, 0.3), map, MapIdentityConfig{});
  EXPECT_EQ(d.result, MapIdentityResult::kTwoPlausible) << to_string(d.result);
}

TEST(MapIdentityGate, NothingInGateRefused) {
  const LandmarkMap map = two_landmarks(1000.0);
  const Pose2 truth{0.0, 0.0, 0.0};
  const Measured m = measure(compose(inverse(truth), map.entries.at(1).pose), 0);
  // The prediction is 60 mm off with a 3 mm sigma: neither landmark fits.
  const auto d = gate_identity(m.c, m.beta, diag_cov(0.05, 0.01), kOnlyTurn0,
                               predict({60.0, 0.0, 0.0}, 3.0, 0.3), map, MapIdentityConfig{});
  EXPECT_EQ(d.result, MapIdentityResult::kNoneInGate) << to_string(d.result);
  // No prediction: nothing is tried.
  EXPECT_EQ(gate_identity(m.c, m.beta, diag_cov(0.05, 0.01), kOnlyTurn0, Prediction{}, map,
                          MapIdentityConfig{})
                .result,
            MapIdentityResult::kNoPrediction);
}

TEST(MapIdentityGate, TurnFromHeadingWhenLogoUnclear) {
  const LandmarkMap map = two_landmarks(1000.0);
  const Pose2 v{3.0, -2.0, deg_to_rad(-40.0)};
  const Pose2 l = compose(inverse(v), map.entries.at(1).pose);
  for (int q = 0; q < 4; ++q) {
    const Measured m = measure(l, q);
    const auto d = gate_identity(m.c, m.beta, diag_cov(0.05, 0.01), kAllTurns, predict(v, 3.0, 0.3),
                                 map, MapIdentityConfig{});
    EXPECT_EQ(d.result, MapIdentityResult::kAccepted) << q << " " << to_string(d.result);
    EXPECT_EQ(d.turn, q);
  }
  // A heading so uncertain that two turns fit: refused, never guessed.
  const Measured m = measure(l, 1);
  const auto d = gate_identity(m.c, m.beta, diag_cov(0.05, 0.01), kAllTurns, predict(v, 3.0, 50.0),
                               map, MapIdentityConfig{});
  EXPECT_EQ(d.result, MapIdentityResult::kTwoPlausible) << to_string(d.result);
  // The logo allowing only a wrong turn: nothing in the gate.
  const auto d2 = gate_identity(m.c, m.beta, diag_cov(0.05, 0.01), kOnlyTurn0, predict(v, 3.0, 0.3),
                                map, MapIdentityConfig{});
  EXPECT_EQ(d2.result, MapIdentityResult::kNoneInGate);
}

TEST(MapIdentityGate, PredictedCovariancePropagates) {
  // A landmark 100 mm ahead: a heading error of the vehicle moves it sideways by 100 mm * dtheta.
  Prediction p = predict({0.0, 0.0, 0.0}, 0.0, 1.0);
  Eigen::Matrix3d c;
  predicted_landmark_in_vehicle(p, {100.0, 0.0, 0.0}, &c);
  EXPECT_NEAR(c(1, 1), std::pow(100.0 * deg_to_rad(1.0), 2), 1e-9);
  EXPECT_NEAR(c(0, 0), 0.0, 1e-12);
  EXPECT_NEAR(c(2, 2), std::pow(deg_to_rad(1.0), 2), 1e-12);
}

TEST(MapIdentityModules, RightCodeAgreesWrongCodeDoesNot) {
  LandmarkMap map;
  map.entries[17] = {17, {1000.0, -2000.0, 0.0}};
  map.entries[18] = {18, {1150.0, -2000.0, 0.0}};
  QrBits a, b;
  ASSERT_TRUE(encode_qr_bits(map_full_payload(map.entries[17]), &a));
  ASSERT_TRUE(encode_qr_bits(map_full_payload(map.entries[18]), &b));
  ASSERT_EQ(a.n, 25);
  ASSERT_EQ(b.n, 25);
  // What the camera sees: code 17 with its upper third replaced by noise (a covered strip).
  std::mt19937_64 rng(3);
  std::vector<std::uint8_t> bits = a.dark;
  for (int i = 0; i < 25 * 8; ++i) bits[static_cast<size_t>(i)] = rng() & 1;
  const MapIdentityConfig cfg;
  const auto right = check_modules(bits, a, {{18, &b}}, cfg);
  EXPECT_TRUE(right.ok) << right.agree << " " << right.worst_pair;
  EXPECT_GT(right.agree, 0.8);
  const auto wrong = check_modules(bits, b, {{17, &a}}, cfg);
  EXPECT_FALSE(wrong.ok);
  EXPECT_LT(wrong.worst_pair, 0.35);
  EXPECT_EQ(wrong.worst_pair_id, 17u);
  // Unknown modules (outside the image) are not counted.
  std::vector<std::uint8_t> none(bits.size(), 2);
  EXPECT_FALSE(check_modules(none, a, {{18, &b}}, cfg).ok);
  // The id-only form is a version-1 code.
  QrBits v1;
  ASSERT_TRUE(encode_qr_bits(map_id_payload(17), &v1));
  EXPECT_EQ(v1.n, 21);
}

TEST(MapIdentityModules, FlatPatchIsLeftOutCleanModulesAreRead) {
  QrBits code;
  ASSERT_TRUE(encode_qr_bits("AGV1/00017/+001000.0/-002000.0/+090.00", &code));
  QrSamples s;
  s.n = code.n;
  s.ring = 2;
  const int side = s.side();
  s.v.assign(static_cast<size_t>(side * side), 200.0f);  // paper
  for (int r = 0; r < s.n; ++r) {
    for (int c = 0; c < s.n; ++c) {
      float v = code.dark[static_cast<size_t>(r * s.n + c)] ? 40.0f : 200.0f;
      if (r >= 12 && r < 22 && c >= 12 && c < 22) v = 120.0f;  // a floor-grey patch, 10 x 10
      s.v[static_cast<size_t>((r + s.ring) * side + c + s.ring)] = v;
    }
  }
  std::vector<std::uint8_t> bits;
  binarize_samples(s, &bits);
  int unknown_inside = 0, wrong_outside = 0, inside = 0;
  for (int r = 0; r < s.n; ++r) {
    for (int c = 0; c < s.n; ++c) {
      const size_t i = static_cast<size_t>(r * s.n + c);
      // Two modules in from the patch edge its 5 x 5 neighbourhood is flat.
      if (r >= 14 && r < 20 && c >= 14 && c < 20) {
        ++inside;
        unknown_inside += bits[i] == 2 ? 1 : 0;
      } else if (!(r >= 12 && r < 22 && c >= 12 && c < 22) && bits[i] != 2) {
        wrong_outside += bits[i] != code.dark[i] ? 1 : 0;
      }
    }
  }
  EXPECT_EQ(unknown_inside, inside);
  EXPECT_EQ(wrong_outside, 0);
  // A sample outside the image is unknown.
  s.v[static_cast<size_t>((s.ring + 3) * side + s.ring + 10)] = -1.0f;
  binarize_samples(s, &bits);
  EXPECT_EQ(bits[static_cast<size_t>(3 * s.n + 10)], 2);
}

// ---- The whole localizer on rendered frames -------------------------------------------------

namespace {

struct CoveredScene {
  LandmarkMap map;
  sim::Scene scene;
};

// Two landmarks 150 mm apart with the same heading (the hardest case for the gate alone).
CoveredScene covered_scene() {
  CoveredScene s;
  s.map.entries[17] = {17, {1000.0, -2000.0, deg_to_rad(90.0)}};
  s.map.entries[18] = {18, {1000.0, -1850.0, deg_to_rad(90.0)}};
  std::string err;
  EXPECT_TRUE(sim::make_scene(s.map, LandmarkGeometry{}, sim::PayloadMode::kFull, &s.scene, &err))
      << err;
  return s;
}

}  // namespace

TEST(MapIdentityLocalizer, CoveredCodeIdentifiedFromTheMap) {
  const CoveredScene s = covered_scene();
  const CameraModel cam = CameraModel::default_640x480();
  LandmarkLocalizer loc(VisionConfig{}, cam, LandmarkGeometry{}, &s.map);
  const Pose2 truth = compose(s.map.entries.at(17).pose, {4.0, -3.0, deg_to_rad(12.0)});
  sim::RenderOptions o;
  o.qr_cover_fraction = 1.0 / 3.0;
  // Find a cover (seed) the QR reader cannot read through: the test needs one.
  cv::Mat img;
  LandmarkFix plain;
  for (std::uint64_t seed = 1; seed < 60; ++seed) {
    o.degradation_seed = seed;
    std::mt19937_64 rng(seed);
    img = sim::render_frame(s.scene, cam, truth, o, rng);
    if (loc.process(img, &plain) == FixStatus::kQrUnreadable) break;
  }
  ASSERT_EQ(plain.status, FixStatus::kQrUnreadable);
  EXPECT_EQ(plain.identity, FixIdentity::kNone);

  LandmarkFix fix;
  Prediction p = predict(compose(truth, {2.0, -1.5, deg_to_rad(0.2)}), 3.0, 0.3);
  ASSERT_EQ(loc.process(img, p, &fix), FixStatus::kOk) << to_string(fix.status);
  EXPECT_EQ(fix.identity, FixIdentity::kMapGuided);
  EXPECT_FALSE(fix.map_verified);
  EXPECT_EQ(fix.landmark_id, 17u);
  EXPECT_NEAR(fix.vehicle_in_world.x_mm, truth.x_mm, 0.1);
  EXPECT_NEAR(fix.vehicle_in_world.y_mm, truth.y_mm, 0.1);
  EXPECT_LT(std::abs(rad_to_deg(wrap_angle_rad(fix.vehicle_in_world.theta_rad - truth.theta_rad))),
            0.05);
  EXPECT_TRUE(fix.cov_world.allFinite());
  EXPECT_GT(fix.cov_world.determinant(), 0.0);

  // Kidnapped: the prediction is exactly one landmark spacing off (it puts the vehicle over 18).
  // The gate alone would take 18; the modules show 17's code.
  const Pose2 shifted{truth.x_mm, truth.y_mm + 150.0, truth.theta_rad};
  LandmarkFix kid;
  loc.process(img, predict(shifted, 3.0, 0.3), &kid);
  EXPECT_NE(kid.status, FixStatus::kOk);
  EXPECT_EQ(kid.status, FixStatus::kQrUnreadable);

  // An invalid prediction: exactly today's result.
  LandmarkFix again;
  loc.process(img, Prediction{}, &again);
  EXPECT_EQ(again.status, FixStatus::kQrUnreadable);
  EXPECT_EQ(again.landmark_id, plain.landmark_id);
  EXPECT_EQ(again.e_x_mm, plain.e_x_mm);

  // The configured gate (keys vision.identity.*) is the one the stage applies: the same
  // prediction (~1 in chi2) outside a gate of 0.01 gives no identity.
  VisionConfig strict;
  strict.identity.gate_chi2 = 0.01;
  strict.identity.clear_chi2 = 0.02;
  LandmarkLocalizer strict_loc(strict, cam, LandmarkGeometry{}, &s.map);
  LandmarkFix refused;
  strict_loc.process(img, p, &refused);
  EXPECT_EQ(refused.status, FixStatus::kQrUnreadable);
  EXPECT_EQ(refused.identity, FixIdentity::kNone);
}

TEST(MapIdentityLocalizer, ReadableCodeIsUnchangedByThePrediction) {
  const CoveredScene s = covered_scene();
  const CameraModel cam = CameraModel::default_640x480();
  LandmarkLocalizer loc(VisionConfig{}, cam, LandmarkGeometry{}, &s.map);
  const Pose2 truth = compose(s.map.entries.at(17).pose, {-5.0, 2.0, deg_to_rad(-33.0)});
  std::mt19937_64 rng(1);
  const cv::Mat img = sim::render_frame(s.scene, cam, truth, sim::RenderOptions{}, rng);
  LandmarkFix a, b;
  ASSERT_EQ(loc.process(img, &a), FixStatus::kOk);
  ASSERT_EQ(loc.process(img, predict(truth, 3.0, 0.3), &b), FixStatus::kOk);
  EXPECT_EQ(a.identity, FixIdentity::kQrCode);
  EXPECT_EQ(b.identity, FixIdentity::kQrCode);
  // The prediction places the pose stage's bands (edge probes, docs/design/tracking.md), the full
  // search its detection: the fits agree within the tracking tests' tolerance, not bit for bit.
  EXPECT_NEAR(a.vehicle_in_world.x_mm, b.vehicle_in_world.x_mm, 0.01);
  EXPECT_NEAR(a.vehicle_in_world.y_mm, b.vehicle_in_world.y_mm, 0.01);
  EXPECT_TRUE(b.map_verified);
}

TEST(SimQrCover, CoversOnlyTheCodeAndIsDeterministic) {
  const CoveredScene s = covered_scene();
  const CameraModel cam = CameraModel::default_640x480();
  const Pose2 truth = compose(s.map.entries.at(17).pose, {0.0, 0.0, 0.0});
  sim::RenderOptions o;
  std::mt19937_64 r0(1), r1(1), r2(1);
  const cv::Mat clean = sim::render_frame(s.scene, cam, truth, o, r0);
  o.qr_cover_fraction = 0.25;
  const cv::Mat a = sim::render_frame(s.scene, cam, truth, o, r1);
  const cv::Mat b = sim::render_frame(s.scene, cam, truth, o, r2);
  EXPECT_EQ(cv::norm(a, b, cv::NORM_INF), 0.0);
  cv::Mat diff;
  cv::absdiff(a, clean, diff);
  const int changed = cv::countNonZero(diff > 30);
  // A quarter of the 30 x 30 mm code at 0.26 mm/px is ~3300 px; a third of them change at least
  // (the cover matches the modules of its own colour).
  EXPECT_GT(changed, 800);
  EXPECT_LT(changed, 3600);
  // The border is untouched: a ring 1.5 mm inside the outer edge.
  LandmarkLocalizer loc(VisionConfig{}, cam, LandmarkGeometry{}, &s.map);
  LandmarkFix fa, fc;
  loc.process(clean, &fc);
  loc.process(a, &fa);
  EXPECT_EQ(fa.sides_used, 4);
  EXPECT_NEAR(fa.e_x_mm, fc.e_x_mm, 0.05);
}
