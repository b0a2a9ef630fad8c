// Ceiling camera pose calibration (tools/desk/src/calib_ceiling.*, `agvloc-desk calibrate ceiling`
// and `ceiling-check`) on frames rendered by the site renderer: fleet vehicles standing still
// are the surveyed tags (each tray tag lies flat at its tray height, at the vehicle's pose).
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <random>
#include <string>
#include <vector>

#include "agv/recording/png_io.hpp"
#include "agv/sim/site_render.hpp"
#include "agv/site/site_file.hpp"
#include "calib_ceiling.hpp"
#include "ceiling_world.hpp"
#include "commands.hpp"
#include "site_io.hpp"

namespace agv::desk {
namespace {

using namespace test;  // NOLINT: the shared scene

std::vector<ccal::TagSighting> all_sightings(const World& w) {
  std::vector<ccal::TagSighting> out;
  for (std::size_t f = 0; f < w.frames.size(); ++f) {
    const auto s = ccal::detect_tags(w.frames[f], static_cast<int>(f));
    out.insert(out.end(), s.begin(), s.end());
  }
  return out;
}

struct PoseError {
  double d[6];  // x, y, z (mm), roll, pitch, yaw (rad): the Result's sigma order
};
PoseError pose_error(const ccal::CameraPose& a, const ccal::CameraPose& b) {
  auto wrap = [](double r) { return std::remainder(r, 2.0 * kPi); };
  return {{a.x_mm - b.x_mm, a.y_mm - b.y_mm, a.z_mm - b.z_mm, wrap(a.roll_rad - b.roll_rad),
           wrap(a.pitch_rad - b.pitch_rad), wrap(a.yaw_rad - b.yaw_rad)}};
}

TEST(CalibCeiling, RotationMatchesTheSiteConvention) {
  site::CeilingCamera cam;
  ccal::set_pose(true_pose(), &cam);
  const ccal::CameraPose back = ccal::pose_of(cam);
  const PoseError e = pose_error(back, true_pose());
  for (double v : e.d) EXPECT_NEAR(v, 0.0, 1e-9);
  // project() against the renderer's own projection.
  const auto corners = ccal::tag_corners_site({5, 900.0, 600.0, 400.0, 0.3, 200.0});
  cam.intrinsics = intrinsics();
  const sim::RenderCamera rc = sim::RenderCamera::from_ceiling(cam);
  for (const auto& c : corners) {
    Vec2 ours;
    ASSERT_TRUE(ccal::project(cam.intrinsics, true_pose(), c, &ours));
    const auto theirs = sim::project_points(rc, {{c[0], c[1], c[2]}});
    EXPECT_NEAR(ours.x, theirs[0].x, 1e-6);
    EXPECT_NEAR(ours.y, theirs[0].y, 1e-6);
  }
}

TEST(CalibCeiling, DetectsEveryTagWithCornersInPageOrder) {
  const World& w = world();
  const auto s = ccal::detect_tags(w.frames[0], 0);
  ASSERT_EQ(s.size(), 7u);
  double se = 0.0, worst = 0.0;
  for (const auto& t : s) {
    const sim::AgvTruth& truth = w.truth[0].agvs[t.id - 1];
    ASSERT_EQ(truth.tag_id, t.id);
    for (int c = 0; c < 4; ++c) {
      const double e = std::hypot(t.corners_px[c].x - truth.tag_corners_px[c].x,
                                  t.corners_px[c].y - truth.tag_corners_px[c].y);
      se += e * e;
      worst = std::max(worst, e);
    }
  }
  std::printf("corner error against the renderer's truth: RMS %.3f px, max %.3f px\n",
              std::sqrt(se / 28.0), worst);
  // libapriltag's half-pixel convention left uncorrected puts every corner 0.71 px off.
  EXPECT_LT(std::sqrt(se / 28.0), 0.15);
  EXPECT_LT(worst, 0.35);
}

TEST(CalibCeiling, SolvesThePoseAndItsSigmaCoversTheError) {
  const World& w = world();
  const auto survey = survey_of(w);
  const ccal::Result r = ccal::solve_camera_pose(intrinsics(), survey, all_sightings(w));
  ASSERT_EQ(r.error, ccal::Error::kNone) << r.message;
  EXPECT_EQ(r.tags_used, 7);
  EXPECT_EQ(r.corners_used, 56);
  const PoseError e = pose_error(r.pose, true_pose());
  const char* names[6] = {"x_mm", "y_mm", "z_mm", "roll_deg", "pitch_deg", "yaw_deg"};
  for (int i = 0; i < 6; ++i) {
    const double scale = i < 3 ? 1.0 : 1.0 / kDeg;
    std::printf("%-9s error %+8.4f sigma %.4f\n", names[i], e.d[i] * scale, r.sigma[i] * scale);
    EXPECT_LE(std::abs(e.d[i]), 3.0 * r.sigma[i]) << names[i];
  }
  // Measured: 0.5 mm, 0.06 mm, 0.006 deg at most.
  EXPECT_LT(std::hypot(e.d[0], e.d[1]), 2.0);
  EXPECT_LT(std::abs(e.d[2]), 1.0);
  for (int i = 3; i < 6; ++i) EXPECT_LT(std::abs(e.d[i]), 0.02 * kDeg);
  std::printf("reprojection RMS %.3f px, largest floor residual %.2f mm\n", r.eval.rms_px,
              r.eval.max_floor_mm);
  EXPECT_LT(r.eval.rms_px, 0.2);
  EXPECT_LT(r.eval.max_floor_mm, 1.5);
}

// A survey off by millimetres moves all of a tag's corners alike, in every frame: the sigmas come
// from the residuals' spread between tags (not between corners) and cover the pose's error; a
// sideways shift and a tilt of a camera looking down come out strongly correlated.
TEST(CalibCeiling, SurveyErrorIsCoveredAndShiftAndTiltCorrelate) {
  const World& w = world();
  const auto sightings = all_sightings(w);
  const ccal::Result clean = ccal::solve_camera_pose(intrinsics(), survey_of(w), sightings);
  auto survey = survey_of(w);
  std::mt19937 rng(3);
  std::normal_distribution<double> n(0.0, 3.0);
  for (auto& [id, t] : survey) {
    t.x_mm += n(rng);
    t.y_mm += n(rng);
    t.z_mm += n(rng);
  }
  const ccal::Result off = ccal::solve_camera_pose(intrinsics(), survey, sightings);
  ASSERT_EQ(off.error, ccal::Error::kNone) << off.message;
  const PoseError e = pose_error(off.pose, true_pose());
  for (std::size_t i = 0; i < 6; ++i) {
    std::printf("parameter %zu: error %+.5f sigma %.5f (clean survey %.5f)\n", i, e.d[i],
                off.sigma[i], clean.sigma[i]);
    EXPECT_LE(std::abs(e.d[i]), 3.0 * off.sigma[i]) << i;
  }
  EXPECT_GT(off.sigma[0], 2.0 * clean.sigma[0]);
  EXPECT_GT(off.sigma[1], 2.0 * clean.sigma[1]);
  // (x, roll), (x, pitch), (y, roll), (y, pitch) in pose_correlation's order.
  double strongest = 0.0;
  for (std::size_t k : {2u, 3u, 6u, 7u})
    strongest = std::max(strongest, std::abs(off.correlation[k]));
  EXPECT_GT(strongest, 0.5);
  for (double r : off.correlation) EXPECT_LE(std::abs(r), 1.0);
}

// A lens calibrated wrong (here k1 off by 0.01, about what a bowed board leaves at the image's
// edge) is an error field on the floor that no pose absorbs: the tags' floor residual beyond the
// pose grows with it, and with it what the tracker is told of every fix between the tags.
TEST(CalibCeiling, ALensErrorShowsInTheFloorSigma) {
  const World& w = world();
  const auto sightings = all_sightings(w);
  const ccal::Result exact = ccal::solve_camera_pose(intrinsics(), survey_of(w), sightings);
  CameraIntrinsics wrong = intrinsics();
  wrong.k1 += 0.01;
  const ccal::Result off = ccal::solve_camera_pose(wrong, survey_of(w), sightings);
  ASSERT_EQ(exact.error, ccal::Error::kNone) << exact.message;
  ASSERT_EQ(off.error, ccal::Error::kNone) << off.message;
  std::printf("floor sigma: true lens %.3f mm, k1 off by 0.01 %.3f mm (largest residual %.2f)\n",
              exact.eval.floor_sigma_mm, off.eval.floor_sigma_mm, off.eval.max_floor_mm);
  EXPECT_GT(exact.eval.floor_sigma_mm, 0.0);
  EXPECT_LT(exact.eval.floor_sigma_mm, 1.0);
  EXPECT_GT(off.eval.floor_sigma_mm, 2.0 * exact.eval.floor_sigma_mm);
  // Per axis, over the 2 n - 6 degrees of freedom: about the largest residual's scale.
  EXPECT_GT(off.eval.floor_sigma_mm, 0.3 * off.eval.max_floor_mm);
}

TEST(CalibCeiling, RecoversFromAStartOff50MmAndOneDegree) {
  const World& w = world();
  const auto sightings = all_sightings(w);
  const auto survey = survey_of(w);
  const ccal::Result from_pnp = ccal::solve_camera_pose(intrinsics(), survey, sightings);
  ccal::CameraPose start = true_pose();
  start.x_mm += 50.0;
  start.y_mm -= 50.0;
  start.z_mm += 50.0;
  start.yaw_rad += kDeg;
  start.pitch_rad -= kDeg;
  start.roll_rad += kDeg;
  ccal::Options opt;
  opt.initial = &start;
  const ccal::Result r = ccal::solve_camera_pose(intrinsics(), survey, sightings, opt);
  ASSERT_EQ(r.error, ccal::Error::kNone) << r.message;
  const PoseError e = pose_error(r.pose, from_pnp.pose);
  for (int i = 0; i < 3; ++i) EXPECT_NEAR(e.d[i], 0.0, 0.01);
  for (int i = 3; i < 6; ++i) EXPECT_NEAR(e.d[i], 0.0, 1e-5);
}

TEST(CalibCeiling, AMisSurveyedTagIsRejected) {
  const World& w = world();
  const auto sightings = all_sightings(w);
  auto survey = survey_of(w);
  survey.at(5).x_mm += 50.0;
  // Kept, the robust loss only lessens its pull.
  ccal::Options keep;
  keep.reject_min_px = 1e9;
  ccal::Result r = ccal::solve_camera_pose(intrinsics(), survey, sightings, keep);
  ASSERT_EQ(r.error, ccal::Error::kNone) << r.message;
  PoseError e = pose_error(r.pose, true_pose());
  const double kept_mm = std::hypot(e.d[0], e.d[1]);
  EXPECT_TRUE(r.rejected_ids.empty());
  // Rejected, the pose is as good as without it; its residuals show why.
  r = ccal::solve_camera_pose(intrinsics(), survey, sightings);
  ASSERT_EQ(r.error, ccal::Error::kNone) << r.message;
  ASSERT_EQ(r.rejected_ids, std::vector<std::uint32_t>{5});
  EXPECT_EQ(r.tags_used, 6);
  e = pose_error(r.pose, true_pose());
  std::printf("tag 5 surveyed 50 mm off: pose off by %.2f mm kept, %.2f mm rejected\n", kept_mm,
              std::hypot(e.d[0], e.d[1]));
  EXPECT_GT(kept_mm, 5.0);
  EXPECT_LT(std::hypot(e.d[0], e.d[1]), 2.0);
  EXPECT_LT(r.eval.rms_px, 0.2);  // over the tags used
  EXPECT_EQ(r.eval.tags.size(), 7u);
  for (const auto& t : r.eval.tags) {
    if (t.id == 5) {
      EXPECT_NEAR(t.floor_mm, 50.0, 2.0);
    } else {
      EXPECT_LT(t.floor_mm, 1.5);
    }
  }
}

TEST(CalibCeiling, NamedErrorsOfTheSolver) {
  const World& w = world();
  const auto sightings = all_sightings(w);
  // Two tags always lie on a line.
  ccal::Result r = ccal::solve_camera_pose(intrinsics(), survey_of(w, 0, 2), sightings);
  EXPECT_EQ(r.error, ccal::Error::kTooFewTags);
  EXPECT_EQ(r.unsurveyed_ids.size(), 5u);
  // Tags 1..3 lie on one line of the tray plane.
  r = ccal::solve_camera_pose(intrinsics(), survey_of(w, 0, 3), sightings);
  EXPECT_EQ(r.error, ccal::Error::kDegenerate) << r.message;
  // One more off the line fixes it.
  r = ccal::solve_camera_pose(intrinsics(), survey_of(w, 0, 4), sightings);
  EXPECT_EQ(r.error, ccal::Error::kNone) << r.message;
  EXPECT_STREQ(ccal::to_string(ccal::Error::kDegenerate), "degenerate-geometry");
  // A start with every tag behind the camera: no residual can be evaluated.
  ccal::CameraPose below = true_pose();
  below.z_mm = -4500.0;
  ccal::Options opt;
  opt.initial = &below;
  r = ccal::solve_camera_pose(intrinsics(), survey_of(w), sightings, opt);
  EXPECT_EQ(r.error, ccal::Error::kSolveFailed);
  EXPECT_FALSE(r.message.empty());
}

TEST(CalibCeiling, SurveyCsvIsCheckedLineByLine) {
  std::map<std::uint32_t, ccal::SurveyedTag> s;
  std::string err;
  EXPECT_TRUE(ccal::parse_survey_csv(
      "# surveyed\nid,x_mm,y_mm,z_mm,yaw_deg,size_mm\n4,100,200,400,90,160\n", &s, &err))
      << err;
  ASSERT_EQ(s.size(), 1u);
  EXPECT_NEAR(s.at(4).yaw_rad, kPi / 2, 1e-12);
  EXPECT_FALSE(ccal::parse_survey_csv("id,x,y\n", &s, &err));
  EXPECT_NE(err.find("header"), std::string::npos);
  EXPECT_FALSE(
      ccal::parse_survey_csv("id,x_mm,y_mm,z_mm,yaw_deg,size_mm\n9,1,2,3,nan,160\n", &s, &err));
  EXPECT_EQ(err.rfind("line 2:", 0), 0u) << err;
  EXPECT_FALSE(ccal::parse_survey_csv(
      "id,x_mm,y_mm,z_mm,yaw_deg,size_mm\n9,1,2,3,0,160\n9,1,2,3,0,160\n", &s, &err));
  EXPECT_NE(err.find("twice"), std::string::npos);
  EXPECT_FALSE(
      ccal::parse_survey_csv("id,x_mm,y_mm,z_mm,yaw_deg,size_mm\n600,1,2,3,0,160\n", &s, &err));
  EXPECT_TRUE(s.empty());
}

}  // namespace
}  // namespace agv::desk
