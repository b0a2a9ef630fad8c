// The whole localizer on simulator frames: the four 90-degree turns, map checks, bad input,
// a landmark cut by the image border, the overlay, timings, and golden frames (stored PNGs and
// results in tests/data/vision/golden.csv; regenerate with AGV_VISION_REGEN_GOLDEN=1).
#include <gtest/gtest.h>

#include <Eigen/Dense>
#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <random>
#include <sstream>
#include <string>

#include "agv/sim/render.hpp"
#include "agv/vision/landmark_localizer.hpp"

using namespace agv;
using namespace agv::vision;

namespace {

const Pose2 kLandmarkWorld{1000.0, -2000.0, deg_to_rad(90.0)};
constexpr std::uint32_t kId = 17;

LandmarkMap one_map(Pose2 pose = kLandmarkWorld) {
  LandmarkMap m;
  m.entries[kId] = {kId, pose};
  return m;
}

// Renders the landmark seen from vehicle pose e (vehicle in the landmark frame).
cv::Mat render(const Pose2& e, sim::PayloadMode mode = sim::PayloadMode::kFull,
               const sim::RenderOptions& o = {},
               const CameraModel& cam = CameraModel::default_640x480()) {
  sim::Scene scene;
  std::string err;
  EXPECT_TRUE(sim::make_scene(one_map(), LandmarkGeometry{}, mode, &scene, &err)) << err;
  std::mt19937_64 rng(5);
  return sim::render_frame(scene, cam, compose(kLandmarkWorld, e), o, rng);
}

double heading_err_deg(double a_deg, double b_rad) {
  return std::abs(rad_to_deg(wrap_angle_rad(deg_to_rad(a_deg) - b_rad)));
}

}  // namespace

TEST(VisionLocalizer, FourQuarterTurnsGiveTheRightQuadrant) {
  const LandmarkMap map = one_map();
  LandmarkLocalizer loc(VisionConfig{}, CameraModel::default_640x480(), LandmarkGeometry{}, &map);
  for (int q = 0; q < 4; ++q) {
    const Pose2 e{6.0, -4.0, deg_to_rad(7.0 + 90.0 * q)};
    const cv::Mat img = render(e);
    LandmarkFix fix;
    ASSERT_EQ(loc.process(img, &fix), FixStatus::kOk)
        << "turn " << q << ": " << to_string(fix.status);
    EXPECT_LT(heading_err_deg(fix.e_phi_deg, e.theta_rad), 0.02) << "turn " << q;
    EXPECT_NEAR(fix.e_x_mm, e.x_mm, 0.02);
    EXPECT_NEAR(fix.e_y_mm, e.y_mm, 0.02);
    EXPECT_EQ(fix.landmark_id, kId);
    EXPECT_STREQ(fix.payload, "AGV1/00017/+001000.0/-002000.0/+090.00");
    // World pose: W<-V = (W<-L) (+) e.
    const Pose2 w = compose(kLandmarkWorld, e);
    EXPECT_NEAR(fix.vehicle_in_world.x_mm, w.x_mm, 0.03);
    EXPECT_NEAR(fix.vehicle_in_world.y_mm, w.y_mm, 0.03);
    EXPECT_EQ(fix.sides_used, 4);
    EXPECT_FALSE(fix.partly_outside);
    // Covariance: symmetric positive definite and not absurd.
    EXPECT_TRUE(fix.cov_world.allFinite());
    EXPECT_GT(fix.cov_world.determinant(), 0.0);
    EXPECT_LT(std::sqrt(fix.cov_world(0, 0)), 1.0);
  }
}

TEST(VisionLocalizer, MapChecks) {
  const Pose2 e{3.0, 2.0, deg_to_rad(-20.0)};
  const cv::Mat id_only = render(e, sim::PayloadMode::kIdOnly);
  const cv::Mat full = render(e, sim::PayloadMode::kFull);
  LandmarkFix fix;
  {
    // Id-only payload: the pose comes from the map.
    const LandmarkMap map = one_map();
    LandmarkLocalizer loc(VisionConfig{}, CameraModel::default_640x480(), LandmarkGeometry{}, &map);
    ASSERT_EQ(loc.process(id_only, &fix), FixStatus::kOk) << to_string(fix.status);
    EXPECT_STREQ(fix.payload, "AGV1/00017/MAP");
    EXPECT_NEAR(fix.vehicle_in_world.x_mm, compose(kLandmarkWorld, e).x_mm, 0.05);
  }
  {
    // Id-only payload without a map: unknown.
    LandmarkLocalizer loc(VisionConfig{}, CameraModel::default_640x480(), LandmarkGeometry{},
                          nullptr);
    EXPECT_EQ(loc.process(id_only, &fix), FixStatus::kUnknownLandmark);
    // Full payload without a map: fine.
    EXPECT_EQ(loc.process(full, &fix), FixStatus::kOk);
  }
  {
    // Full payload disagreeing with the map by 5 mm: invalid.
    const LandmarkMap map = one_map({1005.0, -2000.0, deg_to_rad(90.0)});
    LandmarkLocalizer loc(VisionConfig{}, CameraModel::default_640x480(), LandmarkGeometry{}, &map);
    EXPECT_EQ(loc.process(full, &fix), FixStatus::kPayloadInvalid);
  }
  {
    // Full payload whose id is not in the map: unknown.
    LandmarkMap map;
    map.entries[99] = {99, kLandmarkWorld};
    LandmarkLocalizer loc(VisionConfig{}, CameraModel::default_640x480(), LandmarkGeometry{}, &map);
    EXPECT_EQ(loc.process(full, &fix), FixStatus::kUnknownLandmark);
  }
}

TEST(VisionLocalizer, BadInputReturnsAReason) {
  LandmarkLocalizer loc(VisionConfig{}, CameraModel::default_640x480(), LandmarkGeometry{},
                        nullptr);
  LandmarkFix fix;
  EXPECT_EQ(loc.process(cv::Mat(), &fix), FixStatus::kBadInput);
  EXPECT_EQ(fix.status, FixStatus::kBadInput);
  EXPECT_EQ(loc.process(cv::Mat(480, 640, CV_8UC3, cv::Scalar(128, 128, 128)), &fix),
            FixStatus::kBadInput);
  EXPECT_EQ(loc.process(cv::Mat(480, 640, CV_16UC1, cv::Scalar(1000)), &fix), FixStatus::kBadInput);
  EXPECT_EQ(loc.process(cv::Mat(240, 320, CV_8UC1, cv::Scalar(128)), &fix), FixStatus::kBadInput);
  EXPECT_EQ(loc.process(cv::Mat(480, 640, CV_8UC1, cv::Scalar(0)), &fix), FixStatus::kNoLandmark);
  EXPECT_EQ(loc.process(cv::Mat(480, 640, CV_8UC1, cv::Scalar(255)), &fix), FixStatus::kNoLandmark);
  EXPECT_EQ(loc.process(cv::Mat(480, 640, CV_8UC1, cv::Scalar(128)), nullptr),
            FixStatus::kBadInput);
  // Noise and a non-continuous view (ROI of a bigger image) must not crash.
  cv::Mat noise(480, 640, CV_8UC1);
  cv::randu(noise, 0, 256);
  EXPECT_NE(loc.process(noise, &fix), FixStatus::kOk);
  cv::Mat big(600, 800, CV_8UC1, cv::Scalar(200));
  EXPECT_NE(loc.process(big(cv::Rect(10, 10, 640, 480)), &fix), FixStatus::kOk);
  // Overlay on bad input: no crash, empty output for a wrong type.
  cv::Mat ov;
  loc.draw_overlay(cv::Mat(), fix, &ov);
  EXPECT_TRUE(ov.empty());
  EXPECT_STREQ(to_string(FixStatus::kPartlyOutside), "landmark partly outside the image");
}

TEST(VisionLocalizer, LandmarkCutByTheImageBorder) {
  const LandmarkMap map = one_map();
  LandmarkLocalizer loc(VisionConfig{}, CameraModel::default_640x480(), LandmarkGeometry{}, &map);
  LandmarkFix fix;
  // Centre 70 mm to the side: a third of the landmark and a strip of the QR are outside. The
  // guided reader fills the missing modules in (Reed-Solomon corrects them) and three sides give
  // the pose; without the fill-in the code is unreadable.
  {
    const cv::Mat img = render({0.0, 70.0, 0.0});
    ASSERT_EQ(loc.process(img, &fix), FixStatus::kOk);
    EXPECT_TRUE(fix.partly_outside);
    EXPECT_EQ(fix.qr_method, 1);
    EXPECT_EQ(fix.sides_used, 3);
    EXPECT_NEAR(fix.e_x_mm, 0.0, 0.05);
    EXPECT_NEAR(fix.e_y_mm, 70.0, 0.05);
    EXPECT_LT(heading_err_deg(fix.e_phi_deg, 0.0), 0.02);
    VisionConfig whole;
    whole.qr_max_missing_modules = 0;
    LandmarkLocalizer loc_whole(whole, CameraModel::default_640x480(), LandmarkGeometry{}, &map);
    EXPECT_EQ(loc_whole.process(img, &fix), FixStatus::kPartlyOutside);
  }
  // Centre 85 mm to the side: more than half of the landmark (and of the QR) is outside.
  EXPECT_EQ(loc.process(render({0.0, 85.0, 0.0}), &fix), FixStatus::kPartlyOutside);
  EXPECT_TRUE(fix.partly_outside);
  // Centre 35 mm ahead: the front of the border is cut but the QR, both side edges and the rear
  // edge are visible, so the pose is measured from what is visible and flagged.
  const Pose2 e{-35.0, 3.0, deg_to_rad(2.0)};
  const FixStatus st = loc.process(render(e), &fix);
  EXPECT_TRUE(fix.partly_outside);
  if (st == FixStatus::kOk) {
    EXPECT_LT(fix.sides_used, 4);
    EXPECT_NEAR(fix.e_x_mm, e.x_mm, 0.1);
    EXPECT_NEAR(fix.e_y_mm, e.y_mm, 0.1);
    EXPECT_LT(heading_err_deg(fix.e_phi_deg, e.theta_rad), 0.05);
  } else {
    EXPECT_EQ(st, FixStatus::kPartlyOutside);
  }
  // With partly-outside poses disabled, the same frame is rejected.
  VisionConfig strict;
  strict.allow_partly_outside = false;
  LandmarkLocalizer loc2(strict, CameraModel::default_640x480(), LandmarkGeometry{}, &map);
  EXPECT_EQ(loc2.process(render(e), &fix), FixStatus::kPartlyOutside);
}

// vision.edge_row_step: points only on rows (columns) that are multiples of the step, about
// 1/step of them, the fix still at the truth; the point minimums count rows covered, so a
// minimum that step 1 just meets is met at every step.
TEST(VisionLocalizer, EdgeRowStepTakesEveryNthRowAndKeepsTheMinimumsInRows) {
  const LandmarkMap map = one_map();
  const Pose2 e{12.0, -8.0, deg_to_rad(33.0)};
  const cv::Mat img = render(e, sim::PayloadMode::kFull, sim::realistic_options());
  VisionConfig one;
  one.edge_row_step = 1;
  LandmarkLocalizer loc1(one, CameraModel::default_640x480(), LandmarkGeometry{}, &map);
  LandmarkFix fix1;
  ASSERT_EQ(loc1.process(img, &fix1), FixStatus::kOk);
  std::array<size_t, LandmarkLocalizer::kEdgeLines> n1{};
  for (int l = 0; l < LandmarkLocalizer::kEdgeLines; ++l) n1[l] = loc1.edge_points_px(l).size();
  for (int step : {2, 3, 4}) {
    VisionConfig c;
    c.edge_row_step = step;
    // Just met at step 1: without counting rows, step >= 2 would fall below both.
    c.min_points_total = fix1.edge_points_used * 9 / 10;
    c.min_points_per_line = static_cast<int>(*std::min_element(n1.begin(), n1.end())) * 9 / 10;
    LandmarkLocalizer loc(c, CameraModel::default_640x480(), LandmarkGeometry{}, &map);
    LandmarkFix fix;
    ASSERT_EQ(loc.process(img, &fix), FixStatus::kOk) << step;
    EXPECT_EQ(fix.sides_used, 4) << step;
    for (int l = 0; l < LandmarkLocalizer::kEdgeLines; ++l) {
      const auto& pts = loc.edge_points_px(l);
      // Rows (or columns) on the step's grid: the subpixel offset is across the line only.
      int on_rows = 0, on_cols = 0;
      for (const Vec2& p : pts) {
        on_rows += p.y == std::round(p.y) && static_cast<int>(p.y) % step == 0;
        on_cols += p.x == std::round(p.x) && static_cast<int>(p.x) % step == 0;
      }
      EXPECT_EQ(std::max(on_rows, on_cols), static_cast<int>(pts.size())) << step << " " << l;
      const double ratio = static_cast<double>(pts.size()) * step / static_cast<double>(n1[l]);
      EXPECT_NEAR(ratio, 1.0, 0.15) << step << " " << l;
    }
    EXPECT_NEAR(fix.e_x_mm, e.x_mm, 0.02) << step;
    EXPECT_NEAR(fix.e_y_mm, e.y_mm, 0.02) << step;
    EXPECT_LT(heading_err_deg(fix.e_phi_deg, e.theta_rad), 0.01) << step;
  }
}

TEST(VisionLocalizer, OverlayAndTimings) {
  const LandmarkMap map = one_map();
  VisionConfig cfg;
  std::int64_t fake_ns = 0;
  cfg.now_ns = [&fake_ns]() { return fake_ns += 1000; };  // 1 us per call
  LandmarkLocalizer loc(cfg, CameraModel::default_640x480(), LandmarkGeometry{}, &map);
  const cv::Mat img = render({10.0, 5.0, deg_to_rad(30.0)});
  LandmarkFix fix;
  ASSERT_EQ(loc.process(img, &fix), FixStatus::kOk);
  EXPECT_GT(fix.timings.detect_ms, 0.0);
  EXPECT_GT(fix.timings.decode_ms, 0.0);
  EXPECT_GT(fix.timings.pose_ms, 0.0);
  EXPECT_GT(fix.timings.direction_ms, 0.0);
  EXPECT_GE(fix.timings.total_ms, fix.timings.detect_ms + fix.timings.pose_ms);
  cv::Mat ov;
  loc.draw_overlay(img, fix, &ov);
  ASSERT_EQ(ov.type(), CV_8UC3);
  ASSERT_EQ(ov.size(), img.size());
  // Edge points are coloured: many pixels are no longer grey.
  int coloured = 0;
  for (int y = 0; y < ov.rows; ++y) {
    for (int x = 0; x < ov.cols; ++x) {
      const cv::Vec3b p = ov.at<cv::Vec3b>(y, x);
      if (p[0] != p[1] || p[1] != p[2]) ++coloured;
    }
  }
  EXPECT_GT(coloured, 500);
  // Without a clock the timings stay zero.
  LandmarkLocalizer loc2(VisionConfig{}, CameraModel::default_640x480(), LandmarkGeometry{}, &map);
  ASSERT_EQ(loc2.process(img, &fix), FixStatus::kOk);
  EXPECT_EQ(fix.timings.total_ms, 0.0);
}

// Golden frames: stored PNGs (clean, realistic, occluded + scratched, cut) and the stored results.
TEST(VisionGolden, StoredFramesGiveStoredResults) {
  struct Case {
    const char* name;
    Pose2 e;
    sim::RenderOptions o;
  };
  sim::RenderOptions realistic = sim::realistic_options();
  sim::RenderOptions damaged = sim::realistic_options();
  damaged.occluder_border_fraction = 0.12;
  damaged.scratches_per_landmark = 2;
  damaged.dirt_spots_per_landmark = 2;
  const Case cases[] = {
      {"golden_clean", {12.0, -8.0, deg_to_rad(33.0)}, {}},
      {"golden_realistic", {-20.0, 10.0, deg_to_rad(-120.0)}, realistic},
      {"golden_damaged", {5.0, 15.0, deg_to_rad(170.0)}, damaged},
      {"golden_cut", {0.0, 60.0, deg_to_rad(10.0)}, realistic},
  };
  const std::string dir = std::string(AGV_TEST_DATA_DIR) + "/vision/";
  const LandmarkMap map = one_map();
  LandmarkLocalizer loc(VisionConfig{}, CameraModel::default_640x480(), LandmarkGeometry{}, &map);
  if (std::getenv("AGV_VISION_REGEN_GOLDEN")) {
    std::ofstream out(dir + "golden.csv");
    out << "# name,status,e_x_mm,e_y_mm,e_phi_deg,true_e_x_mm,true_e_y_mm,true_e_phi_deg\n";
    for (const Case& c : cases) {
      const cv::Mat img = render(c.e, sim::PayloadMode::kFull, c.o);
      ASSERT_TRUE(cv::imwrite(dir + c.name + ".png", img));
      LandmarkFix fix;
      loc.process(img, &fix);
      char line[256];
      std::snprintf(line, sizeof line, "%s,%d,%.4f,%.4f,%.4f,%.4f,%.4f,%.4f\n", c.name,
                    static_cast<int>(fix.status), fix.e_x_mm, fix.e_y_mm, fix.e_phi_deg, c.e.x_mm,
                    c.e.y_mm, rad_to_deg(c.e.theta_rad));
      out << line;
    }
  }
  std::ifstream in(dir + "golden.csv");
  ASSERT_TRUE(in.good()) << dir << "golden.csv";
  std::string line;
  int n = 0;
  while (std::getline(in, line)) {
    if (line.empty() || line[0] == '#') continue;
    std::stringstream ss(line);
    std::string name, f;
    std::getline(ss, name, ',');
    double v[7];
    for (double& x : v) {
      std::getline(ss, f, ',');
      x = std::stod(f);
    }
    const cv::Mat img = cv::imread(dir + name + ".png", cv::IMREAD_GRAYSCALE);
    ASSERT_FALSE(img.empty()) << name;
    LandmarkFix fix;
    loc.process(img, &fix);
    ASSERT_EQ(static_cast<int>(fix.status), static_cast<int>(v[0])) << name;
    if (fix.status == FixStatus::kOk) {
      // Against the stored result (regression) and against the truth (accuracy).
      EXPECT_NEAR(fix.e_x_mm, v[1], 0.01) << name;
      EXPECT_NEAR(fix.e_y_mm, v[2], 0.01) << name;
      EXPECT_NEAR(fix.e_phi_deg, v[3], 0.005) << name;
      EXPECT_NEAR(fix.e_x_mm, v[4], 0.1) << name;
      EXPECT_NEAR(fix.e_y_mm, v[5], 0.1) << name;
      EXPECT_LT(heading_err_deg(fix.e_phi_deg, deg_to_rad(v[6])), 0.1) << name;
    }
    ++n;
  }
  EXPECT_EQ(n, 4);
}

// Camera tilt (docs/design/frames.md "Camera tilt"): frames rendered by a tilted camera give
// sub-0.1 mm deviations when the localizer knows the tilt, and a clear bias (about height *
// tan(tilt)) when it assumes a perpendicular camera.
TEST(VisionLocalizer, TiltedCameraNeedsTheTiltInTheModel) {
  const LandmarkMap map = one_map();
  CameraModel tilted = CameraModel::default_640x480();
  tilted.mount = {30.0, -8.0, deg_to_rad(2.0), 200.0, deg_to_rad(1.2), deg_to_rad(-0.8)};
  CameraModel flat = tilted;
  flat.mount.roll_rad = flat.mount.pitch_rad = 0.0;
  LandmarkLocalizer right(VisionConfig{}, tilted, LandmarkGeometry{}, &map);
  LandmarkLocalizer wrong(VisionConfig{}, flat, LandmarkGeometry{}, &map);
  double worst_right = 0.0, least_wrong = 1e9;
  for (const double th_deg : {3.0, 97.0, -120.0}) {
    // Vehicle pose in the landmark frame with the optical centre 4 mm / -3 mm off the landmark.
    const double th = deg_to_rad(th_deg), c = std::cos(th), s = std::sin(th);
    const Pose2 e{4.0 - (c * 30.0 + s * 8.0), -3.0 - (s * 30.0 - c * 8.0), th};
    const cv::Mat img = render(e, sim::PayloadMode::kFull, {}, tilted);
    LandmarkFix fr, fw;
    ASSERT_EQ(right.process(img, &fr), FixStatus::kOk) << to_string(fr.status);
    ASSERT_EQ(wrong.process(img, &fw), FixStatus::kOk) << to_string(fw.status);
    worst_right = std::max(worst_right, std::hypot(fr.e_x_mm - e.x_mm, fr.e_y_mm - e.y_mm));
    EXPECT_LT(heading_err_deg(fr.e_phi_deg, e.theta_rad), 0.02);
    least_wrong = std::min(least_wrong, std::hypot(fw.e_x_mm - e.x_mm, fw.e_y_mm - e.y_mm));
  }
  EXPECT_LT(worst_right, 0.1);
  // 200 mm * tan(hypot(1.2, 0.8) deg) = 5.0 mm
  EXPECT_GT(least_wrong, 3.0);
  std::printf(
      "tilt roll 1.2 pitch -0.8 deg: worst error with tilt %.4f mm, least error without "
      "%.2f mm\n",
      worst_right, least_wrong);
}
