// Search windows from the prediction (docs/design/tracking.md): projection against the renderer,
// growth with the covariance, the trust rule, windowed fixes equal to full-search fixes, the
// fallback to the full frame, and the constant-velocity extrapolation of the threaded loop's
// snapshot.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <functional>
#include <limits>
#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>
#include <random>
#include <string>

#include "../support/prediction.hpp"
#include "agv/sim/render.hpp"
#include "agv/vision/landmark_localizer.hpp"
#include "agv/vision/tracking.hpp"

using namespace agv;
using namespace agv::vision;

namespace {

const Pose2 kLandmarkWorld{1000.0, -2000.0, deg_to_rad(90.0)};
constexpr std::uint32_t kId = 17;

LandmarkMap one_map() {
  LandmarkMap m;
  m.entries[kId] = {kId, kLandmarkWorld};
  return m;
}

// One landmark's map and the default camera; the default localizer and one with `change` made to
// its configuration: a feature on and off on the same frames.
struct OnOff {
  explicit OnOff(const std::function<void(VisionConfig*)>& change) : other(changed(change)) {}
  static VisionConfig changed(const std::function<void(VisionConfig*)>& change) {
    VisionConfig c;
    change(&c);
    return c;
  }
  const LandmarkMap map = one_map();
  const CameraModel cam = CameraModel::default_640x480();
  const VisionConfig other;
  LandmarkLocalizer loc{VisionConfig{}, cam, LandmarkGeometry{}, &map};
  LandmarkLocalizer loc_other{other, cam, LandmarkGeometry{}, &map};
};

cv::Mat render(const LandmarkMap& map, const Pose2& vehicle_in_world, const CameraModel& cam) {
  sim::Scene scene;
  std::string err;
  EXPECT_TRUE(sim::make_scene(map, LandmarkGeometry{}, sim::PayloadMode::kFull, &scene, &err))
      << err;
  std::mt19937_64 rng(5);
  return sim::render_frame(scene, cam, vehicle_in_world, sim::RenderOptions{}, rng);
}

using testsupport::predict;

// Bounding box of the dark (printed) pixels.
cv::Rect dark_box(const cv::Mat& img) {
  int x0 = img.cols, y0 = img.rows, x1 = -1, y1 = -1;
  for (int y = 0; y < img.rows; ++y) {
    for (int x = 0; x < img.cols; ++x) {
      if (img.at<std::uint8_t>(y, x) < 100) {
        x0 = std::min(x0, x);
        y0 = std::min(y0, y);
        x1 = std::max(x1, x);
        y1 = std::max(y1, y);
      }
    }
  }
  return x1 < 0 ? cv::Rect() : cv::Rect(x0, y0, x1 - x0 + 1, y1 - y0 + 1);
}

void expect_same_fix(const LandmarkFix& a, const LandmarkFix& b) {
  EXPECT_EQ(a.status, b.status);
  EXPECT_EQ(a.landmark_id, b.landmark_id);
  EXPECT_STREQ(a.payload, b.payload);
  EXPECT_EQ(a.identity, b.identity);
  EXPECT_NEAR(a.e_x_mm, b.e_x_mm, 1e-9);
  EXPECT_NEAR(a.e_y_mm, b.e_y_mm, 1e-9);
  EXPECT_NEAR(a.e_phi_deg, b.e_phi_deg, 1e-9);
  EXPECT_NEAR(a.vehicle_in_world.x_mm, b.vehicle_in_world.x_mm, 1e-9);
  EXPECT_NEAR(a.vehicle_in_world.y_mm, b.vehicle_in_world.y_mm, 1e-9);
  EXPECT_NEAR(a.vehicle_in_world.theta_rad, b.vehicle_in_world.theta_rad, 1e-11);
  EXPECT_LT((a.cov_world - b.cov_world).cwiseAbs().maxCoeff(), 1e-12);
  EXPECT_EQ(a.edge_points_used, b.edge_points_used);
  EXPECT_EQ(a.sides_used, b.sides_used);
  EXPECT_EQ(a.partly_outside, b.partly_outside);
  EXPECT_NEAR(a.detect_x_px, b.detect_x_px, 1e-9);
  EXPECT_NEAR(a.detect_y_px, b.detect_y_px, 1e-9);
  EXPECT_NEAR(a.corner_score, b.corner_score, 1e-9);
}

// Vehicle in the world with the landmark at (dx, dy, heading) from the optical centre.
Pose2 over_landmark(const CameraModel& cam, double dx, double dy, double heading_rad) {
  return compose(kLandmarkWorld, inverse(Pose2{cam.mount.offset_x_mm + dx,
                                               cam.mount.offset_y_mm + dy, heading_rad}));
}

// Tracked fix against the full search's (measured: docs/design/tracking.md).
// Measured max over the cases below: 0.0068 mm, 0.0031 deg at the default edge_row_step 3 (0.0014
// mm, 0.00086 deg at step 1: with a third of the points, the band's ends, which follow the
// detection, move the fit more). The detection's centre moves by up to a coarse pixel (4 px)
// against the full search's; both are at most 6.45 px from the fitted centre, the slack is a
// quarter coarse pixel.
constexpr double kTrackedPosTolMm = 0.01;
constexpr double kTrackedHeadingTolDeg = 0.005;
constexpr double kTrackedDetectSlackPx = 1.0;

CameraModel tilted_camera() {
  CameraModel cam = CameraModel::default_640x480();
  cam.mount.pitch_rad = deg_to_rad(4.0);
  cam.mount.roll_rad = deg_to_rad(-3.0);
  cam.mount.yaw_rad = deg_to_rad(10.0);
  cam.mount.offset_x_mm = 120.0;
  return cam;
}

}  // namespace

TEST(Tracking, WindowContainsTheRenderedLandmarkAndPredictsItsCentre) {
  const LandmarkMap map = one_map();
  for (const CameraModel& cam : {CameraModel::default_640x480(), tilted_camera()}) {
    WindowPlanner planner(VisionConfig{}, cam, LandmarkGeometry{}, &map);
    LandmarkLocalizer loc(VisionConfig{}, cam, LandmarkGeometry{}, &map);
    for (const Pose2& e : {Pose2{-5.0, 8.0, deg_to_rad(17.0)}, Pose2{6.0, -10.0, 2.0}}) {
      const Pose2 v = over_landmark(cam, e.x_mm, e.y_mm, e.theta_rad);
      const cv::Mat img = render(map, v, cam);
      std::vector<SearchWindow> w;
      planner.plan(predict(v, 0.0, 0.0), &w);
      ASSERT_EQ(w.size(), 1u);
      EXPECT_EQ(w[0].landmark_id, kId);
      const cv::Rect box = dark_box(img);
      ASSERT_GT(box.area(), 0);
      ASSERT_TRUE(box.x > 0 && box.y > 0 && box.x + box.width < img.cols &&
                  box.y + box.height < img.rows);
      // The printed square is inside the window, with at least part of the margin around it.
      EXPECT_LE(w[0].x0, box.x);
      EXPECT_LE(w[0].y0, box.y);
      EXPECT_GE(w[0].x1, box.x + box.width);
      EXPECT_GE(w[0].y1, box.y + box.height);
      // The predicted centre is the printed square's (its bounding box's centre, to the
      // perspective of the tilt), the predicted border angle the one detection measures (its
      // coarse estimate is a few degrees off).
      // Under the tilt the box's centre is not the square's (the near side images larger).
      const double tol_px = cam.mount.tilted() ? 3.0 : 1.0;
      EXPECT_NEAR(w[0].centre_px.x, box.x + (box.width - 1) / 2.0, tol_px);
      EXPECT_NEAR(w[0].centre_px.y, box.y + (box.height - 1) / 2.0, tol_px);
      LandmarkFix fix;
      ASSERT_EQ(loc.process(img, &fix), FixStatus::kOk) << to_string(fix.status);
      const double da = std::remainder(rad_to_deg(w[0].up_angle_rad) - fix.detect_angle_deg, 90.0);
      EXPECT_LT(std::abs(da), 5.0);
    }
  }
}

TEST(Tracking, WindowsGrowWithSigmaAndVanishWhenUntrusted) {
  const LandmarkMap map = one_map();
  const CameraModel cam = CameraModel::default_640x480();
  VisionConfig vc;
  WindowPlanner planner(vc, cam, LandmarkGeometry{}, &map);
  const Pose2 v = over_landmark(cam, 0.0, 0.0, 0.3);
  int prev_area = 0;
  for (double s : {0.0, 1.0, 3.0, 6.0}) {
    std::vector<SearchWindow> w;
    planner.plan(predict(v, s, s * 0.1), &w);
    ASSERT_EQ(w.size(), 1u) << s;
    const int area = (w[0].x1 - w[0].x0) * (w[0].y1 - w[0].y0);
    EXPECT_GT(area, prev_area) << s;
    prev_area = area;
  }
  // A larger heading sigma alone also grows the window (the corners are off the vehicle origin).
  std::vector<SearchWindow> a, b;
  planner.plan(predict(v, 1.0, 0.1), &a);
  planner.plan(predict(v, 1.0, 1.5), &b);
  ASSERT_EQ(a.size(), 1u);
  ASSERT_EQ(b.size(), 1u);
  EXPECT_GT(b[0].x1 - b[0].x0, a[0].x1 - a[0].x0);

  std::vector<SearchWindow> w;
  Prediction invalid = predict(v, 1.0, 0.1);
  invalid.valid = false;
  planner.plan(invalid, &w);
  EXPECT_TRUE(w.empty());
  planner.plan(predict(v, vc.tracking.max_position_sigma_mm * 1.01, 0.1), &w);
  EXPECT_TRUE(w.empty());
  planner.plan(predict(v, 1.0, vc.tracking.max_heading_sigma_deg * 1.01), &w);
  EXPECT_TRUE(w.empty());
  Prediction nan = predict(v, 1.0, 0.1);
  nan.cov(0, 1) = std::numeric_limits<double>::quiet_NaN();
  planner.plan(nan, &w);
  EXPECT_TRUE(w.empty());
  // Correlated x-y: the largest eigenvalue decides, not the diagonal.
  Prediction corr = predict(v, 0.8 * vc.tracking.max_position_sigma_mm, 0.1);
  corr.cov(0, 1) = corr.cov(1, 0) = 0.9 * corr.cov(0, 0);
  EXPECT_FALSE(prediction_trusted(corr, vc.tracking));
  vc.tracking.enabled = false;
  WindowPlanner off(vc, cam, LandmarkGeometry{}, &map);
  off.plan(predict(v, 1.0, 0.1), &w);
  EXPECT_TRUE(w.empty());
  // A landmark far outside the footprint gives no window.
  planner.plan(predict(compose(kLandmarkWorld, Pose2{400.0, 0.0, 0.0}), 1.0, 0.1), &w);
  EXPECT_TRUE(w.empty());
}

// The tracked detection (track_detect.cpp) starts the pose stage from its own centre and angle
// estimate, which differs from the full search's by a fraction of a coarse pixel; the pose stage
// re-fits the border edges, so the fix moves only in the edge bands' last points.
struct FixDiff {
  double pos_mm = 0.0, heading_deg = 0.0;
};
FixDiff fix_diff(const LandmarkFix& a, const LandmarkFix& b) {
  EXPECT_EQ(a.status, b.status);
  EXPECT_EQ(a.landmark_id, b.landmark_id);
  EXPECT_STREQ(a.payload, b.payload);
  EXPECT_EQ(a.identity, b.identity);
  EXPECT_EQ(a.partly_outside, b.partly_outside);
  FixDiff d;
  d.pos_mm = std::hypot(a.vehicle_in_world.x_mm - b.vehicle_in_world.x_mm,
                        a.vehicle_in_world.y_mm - b.vehicle_in_world.y_mm);
  d.heading_deg = std::abs(
      rad_to_deg(wrap_angle_rad(a.vehicle_in_world.theta_rad - b.vehicle_in_world.theta_rad)));
  return d;
}

TEST(Tracking, TrackedFixMatchesFullSearchFix) {
  const LandmarkMap map = one_map();
  double max_pos = 0.0, max_head = 0.0, max_det_full = 0.0, max_det_tr = 0.0;
  // The tracked detection itself: the edge probes (edge_probe.cpp, tested below) would otherwise
  // take these frames.
  VisionConfig vc;
  vc.tracking.probe_edges = false;
  for (const CameraModel& cam : {CameraModel::default_640x480(), tilted_camera()}) {
    LandmarkLocalizer loc(vc, cam, LandmarkGeometry{}, &map);
    int n = 0;
    for (double dx : {-40.0, 0.0, 25.0}) {
      for (double deg : {3.0, 44.0, 151.0, 268.0}) {
        const Pose2 v = over_landmark(cam, dx, 0.6 * dx, deg_to_rad(deg));
        const cv::Mat img = render(map, v, cam);
        LandmarkFix full;
        const FixStatus sf = loc.process(img, &full);
        EXPECT_EQ(full.search, SearchMode::kFull);
        if (sf != FixStatus::kOk) continue;
        ++n;
        // Predictions a few sigma off, as the filter's would be, in several directions.
        for (const Pose2& off : {Pose2{4.0, -3.0, deg_to_rad(0.4)}, Pose2{-9.0, 5.0, -0.01},
                                 Pose2{0.0, 10.0, deg_to_rad(1.0)}}) {
          const Pose2 pv{v.x_mm + off.x_mm, v.y_mm + off.y_mm, v.theta_rad + off.theta_rad};
          LandmarkFix tr;
          loc.process(img, predict(pv, 3.0, 0.3), &tr);
          EXPECT_EQ(tr.search, SearchMode::kWindow) << dx << " " << deg;
          EXPECT_FALSE(tr.detection_predicted);
          // The windowed corner search would reproduce the full search's detection exactly: a
          // different one shows the tracked detection made it.
          EXPECT_TRUE(tr.detect_x_px != full.detect_x_px || tr.detect_y_px != full.detect_y_px)
              << dx << " " << deg;
          const FixDiff d = fix_diff(full, tr);
          max_pos = std::max(max_pos, d.pos_mm);
          max_head = std::max(max_head, d.heading_deg);
          // Both detections against the fitted centre: the tracked one is no coarser.
          Vec2 fit_px;
          ASSERT_TRUE(cam.vehicle_to_pixel(
              {full.landmark_in_vehicle.x_mm, full.landmark_in_vehicle.y_mm}, &fit_px));
          max_det_full = std::max(
              max_det_full, std::hypot(full.detect_x_px - fit_px.x, full.detect_y_px - fit_px.y));
          max_det_tr = std::max(max_det_tr,
                                std::hypot(tr.detect_x_px - fit_px.x, tr.detect_y_px - fit_px.y));
        }
      }
    }
    EXPECT_GE(n, 8);
  }
  std::printf(
      "tracked vs full: max position difference %.6f mm, heading %.6f deg; detection centre "
      "to fitted centre: full %.2f px, tracked %.2f px\n",
      max_pos, max_head, max_det_full, max_det_tr);
  EXPECT_LE(max_det_tr, max_det_full + kTrackedDetectSlackPx);
  EXPECT_LE(max_pos, kTrackedPosTolMm);
  EXPECT_LE(max_head, kTrackedHeadingTolDeg);
}

// The windowed corner search gives the full search's fix bit for bit (same coarse pixels, same
// binarization): what run() falls back to when the tracked detection declines. A prediction 45
// degrees off in heading is trusted (sigma 1 deg) but wrong: the tracked detection must not turn
// it into a fix; the windowed search, whose window still holds the landmark, finds the right one.
TEST(Tracking, WrongHeadingFallsBackToTheWindowedSearch) {
  const LandmarkMap map = one_map();
  const CameraModel cam = CameraModel::default_640x480();
  LandmarkLocalizer loc(VisionConfig{}, cam, LandmarkGeometry{}, &map);
  int n = 0;
  for (double deg : {10.0, 100.0, 217.0}) {
    const Pose2 v = over_landmark(cam, 5.0, -4.0, deg_to_rad(deg));
    const cv::Mat img = render(map, v, cam);
    LandmarkFix full, fb;
    if (loc.process(img, &full) != FixStatus::kOk) continue;
    ++n;
    const Pose2 wrong{v.x_mm, v.y_mm, v.theta_rad + deg_to_rad(45.0)};
    loc.process(img, predict(wrong, 3.0, 1.0), &fb);
    EXPECT_NE(fb.search, SearchMode::kFull);
    expect_same_fix(full, fb);
  }
  EXPECT_GE(n, 2);
}

TEST(Tracking, WrongPredictionFallsBackToTheFullFrame) {
  const LandmarkMap map = one_map();
  const CameraModel cam = CameraModel::default_640x480();
  LandmarkLocalizer loc(VisionConfig{}, cam, LandmarkGeometry{}, &map);
  // The landmark in the left half of the image; the prediction puts it 100 mm to the right, so
  // its window (with sigma 2 mm) lies in the right half.
  const Pose2 v = over_landmark(cam, -10.0, 48.0, 0.05);
  const cv::Mat img = render(map, v, cam);
  LandmarkFix full, fb;
  ASSERT_EQ(loc.process(img, &full), FixStatus::kOk);
  const Pose2 wrong = compose(v, Pose2{0.0, 100.0, 0.0});
  WindowPlanner planner(VisionConfig{}, cam, LandmarkGeometry{}, &map);
  std::vector<SearchWindow> w;
  planner.plan(predict(wrong, 2.0, 0.2), &w);
  ASSERT_EQ(w.size(), 1u);
  EXPECT_GT(w[0].x0, full.detect_x_px + 30.0 / cam.mm_per_px());
  ASSERT_EQ(loc.process(img, predict(wrong, 2.0, 0.2), &fb), FixStatus::kOk);
  EXPECT_EQ(fb.search, SearchMode::kWindowThenFull);
  expect_same_fix(full, fb);
  // The predicted landmark is 100 mm from the one found, so its code is not expected there; the
  // code is read from the map's code book, as in the full search.
  EXPECT_TRUE(fb.qr_verified);
  EXPECT_EQ(fb.qr_grid_decodes, 0);
  EXPECT_EQ(fb.qr_search_attempts, 0);
  // Trusted, but no mapped landmark predicted in view: nothing to window, the full frame.
  const Pose2 far = compose(v, Pose2{0.0, -1000.0, 0.0});
  ASSERT_EQ(loc.process(img, predict(far, 2.0, 0.2), &fb), FixStatus::kOk);
  EXPECT_EQ(fb.search, SearchMode::kFull);
  expect_same_fix(full, fb);
}

namespace {

// Paints the landmark's direction logo (with a 1.5 mm margin) in the paper's grey: dirt or wear
// that leaves the logo unreadable, so the guided reader must try the turns in the logo's NCC order.
void erase_logo(cv::Mat* img, const CameraModel& cam, const Pose2& landmark_in_vehicle) {
  const LandmarkGeometry g;
  auto px_of = [&](Vec2 uv) {
    Vec2 px;
    EXPECT_TRUE(cam.vehicle_to_pixel(transform(landmark_in_vehicle, page_to_landmark(uv)), &px));
    return px;
  };
  // Paper between the logo and the code.
  const Vec2 paper = px_of({0.0, -11.5 * g.k()});
  const std::uint8_t grey = img->at<std::uint8_t>(static_cast<int>(std::lround(paper.y)),
                                                  static_cast<int>(std::lround(paper.x)));
  std::vector<cv::Point> poly;
  for (const Vec2 uv : {Vec2{-6.5 * g.k(), -11.5 * g.k()}, Vec2{6.5 * g.k(), -11.5 * g.k()},
                        Vec2{6.5 * g.k(), -22.5 * g.k()}, Vec2{-6.5 * g.k(), -22.5 * g.k()}}) {
    const Vec2 p = px_of(uv);
    poly.emplace_back(static_cast<int>(std::lround(p.x)), static_cast<int>(std::lround(p.y)));
  }
  cv::fillConvexPoly(*img, poly, cv::Scalar(grey));
}

// Prints the logo a quarter turn away from its place (rotated by 90 degrees about the landmark's
// centre), in the border's black: a landmark whose logo contradicts its code.
void paint_logo_turned(cv::Mat* img, const CameraModel& cam, const Pose2& landmark_in_vehicle) {
  const LandmarkGeometry g;
  auto px_of = [&](Vec2 uv) {
    Vec2 px;
    EXPECT_TRUE(cam.vehicle_to_pixel(transform(landmark_in_vehicle, page_to_landmark(uv)), &px));
    return cv::Point(static_cast<int>(std::lround(px.x)), static_cast<int>(std::lround(px.y)));
  };
  const cv::Point border = px_of({0.0, -27.0 * g.k()});
  const std::uint8_t black = img->at<std::uint8_t>(border.y, border.x);
  std::vector<cv::Point> tri;
  for (const Vec2 uv : {g.logo_apex_uv_mm(), g.logo_base_left_uv_mm(), g.logo_base_right_uv_mm()}) {
    tri.push_back(px_of({-uv.y, uv.x}));
  }
  cv::fillConvexPoly(*img, tri, cv::Scalar(black));
}

}  // namespace

// Verified read (docs/design/tracking.md): the guided reader compares the sampled grid with the
// mapped codes and skips zxing, with or without a prediction; the predicted heading gives the turn
// to read first when the logo is unreadable, where the full search samples wrong turns first and
// zxing runs on each of their grids. Same fixes, fewer zxing runs.
TEST(Tracking, TrackedFramesReadTheExpectedCodeWithoutZxing) {
  const LandmarkMap map = one_map();
  const CameraModel cam = CameraModel::default_640x480();
  LandmarkLocalizer loc(VisionConfig{}, cam, LandmarkGeometry{}, &map);
  // Without the centre-only first read, the full search's reader walks an unclear logo's turns
  // through zxing (below); with it, the map's code book reads the right turn's centres first.
  VisionConfig five;
  five.qr_centre_first = false;
  LandmarkLocalizer loc5(five, cam, LandmarkGeometry{}, &map);
  int n = 0, worst_full_runs = 0;
  for (bool logo : {true, false}) {
    for (double deg : {3.0, 44.0, 151.0, 268.0}) {
      const Pose2 v = over_landmark(cam, 6.0, -4.0, deg_to_rad(deg));
      cv::Mat img = render(map, v, cam);
      if (!logo) {
        erase_logo(
            &img, cam,
            Pose2{cam.mount.offset_x_mm + 6.0, cam.mount.offset_y_mm - 4.0, deg_to_rad(deg)});
      }
      LandmarkFix full, tr;
      ASSERT_EQ(loc.process(img, &full), FixStatus::kOk) << deg << " logo " << logo;
      EXPECT_TRUE(full.qr_verified);  // from the map's code book
      EXPECT_EQ(full.qr_search_attempts, 0);
      EXPECT_EQ(full.qr_grid_decodes, 0);
      if (logo) {
        EXPECT_GT(full.logo_margin, VisionConfig{}.logo_margin);
      } else {
        EXPECT_LT(full.logo_score, VisionConfig{}.logo_threshold);
      }
      LandmarkFix full5;
      ASSERT_EQ(loc5.process(img, &full5), FixStatus::kOk);
      EXPECT_STREQ(full5.payload, full.payload);
      worst_full_runs = std::max(worst_full_runs, full5.qr_grid_decodes);
      ASSERT_EQ(loc.process(img, predict(compose(v, Pose2{3.0, -2.0, 0.004}), 3.0, 0.3), &tr),
                FixStatus::kOk);
      EXPECT_EQ(tr.search, SearchMode::kWindow);
      EXPECT_TRUE(tr.qr_verified) << deg << " logo " << logo;
      EXPECT_EQ(tr.qr_grid_decodes, 0) << deg << " logo " << logo;
      EXPECT_EQ(tr.qr_search_attempts, 0);
      EXPECT_EQ(tr.landmark_id, full.landmark_id);
      EXPECT_STREQ(tr.payload, full.payload);
      EXPECT_EQ(tr.identity, full.identity);
      ++n;
    }
  }
  EXPECT_EQ(n, 8);
  // Without the prediction and the centre-only first read, an unreadable logo sends the reader
  // through wrong turns first. Each of their grids went to zxing (up to 16 reads on one frame);
  // now every grid's verified read comes before the first zxing read, so none runs.
  std::printf("zxing grid decodes without the prediction, centre-only read off, worst frame: %d\n",
              worst_full_runs);
  EXPECT_EQ(worst_full_runs, 0);
}

// vision.qr_max_grid_decodes bounds the zxing reads of the guided grids on a frame. Without a map
// (no verified read) and with an unreadable logo, the reader has four turns' grids for zxing:
// unbounded it reads them until one decodes, bounded it stops and zxing's search of the crop
// reads the code instead; with no grid reads at all the search alone reads it. Same fixes.
TEST(Tracking, ZxingGridReadsStayWithinTheirBudget) {
  const LandmarkMap map = one_map();
  const CameraModel cam = CameraModel::default_640x480();
  auto localizer = [&](int budget) {
    VisionConfig c;
    c.qr_centre_first = false;
    c.qr_max_grid_decodes = budget;
    return LandmarkLocalizer(c, cam, LandmarkGeometry{}, nullptr);
  };
  LandmarkLocalizer unbounded = localizer(32), bounded = localizer(2), none = localizer(0);
  int worst_unbounded = 0, n = 0;
  for (double deg : {3.0, 44.0, 151.0, 268.0}) {
    const Pose2 v = over_landmark(cam, 6.0, -4.0, deg_to_rad(deg));
    cv::Mat img = render(map, v, cam);
    erase_logo(&img, cam,
               Pose2{cam.mount.offset_x_mm + 6.0, cam.mount.offset_y_mm - 4.0, deg_to_rad(deg)});
    LandmarkFix fu, fb, fn;
    ASSERT_EQ(unbounded.process(img, &fu), FixStatus::kOk) << deg;
    ASSERT_EQ(bounded.process(img, &fb), FixStatus::kOk) << deg;
    ASSERT_EQ(none.process(img, &fn), FixStatus::kOk) << deg;
    EXPECT_FALSE(fu.qr_verified);
    worst_unbounded = std::max(worst_unbounded, fu.qr_grid_decodes);
    EXPECT_LE(fb.qr_grid_decodes, 2) << deg;
    EXPECT_EQ(fn.qr_grid_decodes, 0) << deg;
    EXPECT_EQ(fn.qr_method, 2) << deg;  // zxing's search of the crop
    for (const LandmarkFix* f : {&fb, &fn}) {
      EXPECT_STREQ(f->payload, fu.payload) << deg;
      EXPECT_NEAR(f->landmark_in_vehicle.x_mm, fu.landmark_in_vehicle.x_mm, 1e-9) << deg;
      EXPECT_NEAR(f->landmark_in_vehicle.theta_rad, fu.landmark_in_vehicle.theta_rad, 1e-12);
    }
    ++n;
  }
  EXPECT_EQ(n, 4);
  std::printf("zxing grid reads of an unreadable logo without a map, unbounded, worst: %d\n",
              worst_unbounded);
  EXPECT_GT(worst_unbounded, 2);  // the bound did bind
}

// vision.qr_centre_first: the centre-only first read gives exactly what the five-sample read
// gives (status, payload, identity, pose), tracked and in full search, on clean, realistic and
// partly covered codes; it reads most frames, and the frames it does not read (a covered strip
// beyond the verified bound) still get the five-sample read.
TEST(Tracking, CentreOnlyFirstReadReadsWhatTheFiveSampleReadReads) {
  OnOff t([](VisionConfig* c) { c->qr_centre_first = false; });
  auto& [map, cam, five, loc, loc5] = t;
  sim::Scene scene;
  std::string err;
  ASSERT_TRUE(sim::make_scene(map, LandmarkGeometry{}, sim::PayloadMode::kFull, &scene, &err));
  int frames = 0, uncovered = 0, centre_uncovered = 0, fallback_read = 0;
  for (double cover : {0.0, 0.0, 0.06, 0.12, 0.2}) {
    // Clean, then realistic frames (blur, noise, light), then realistic with a covered strip.
    sim::RenderOptions o =
        cover > 0 || frames >= 8 ? sim::realistic_options() : sim::RenderOptions{};
    o.qr_cover_fraction = cover;
    for (double deg : {7.0, 97.0, 200.0, 301.0}) {
      const Pose2 v = over_landmark(cam, 4.0, -6.0, deg_to_rad(deg));
      o.degradation_seed = static_cast<std::uint64_t>(deg + 1000 * cover);
      std::mt19937_64 rng(11);
      const cv::Mat img = sim::render_frame(scene, cam, v, o, rng);
      for (bool tracked : {false, true}) {
        const Prediction pred =
            tracked ? predict(compose(v, Pose2{2.0, 1.0, 0.003}), 3.0, 0.3) : Prediction{};
        LandmarkFix a, b;
        const FixStatus sa = loc.process(img, pred, &a), sb = loc5.process(img, pred, &b);
        ASSERT_EQ(sa, sb) << cover << " " << deg << " " << tracked;
        EXPECT_STREQ(a.payload, b.payload);
        EXPECT_EQ(a.landmark_id, b.landmark_id);
        EXPECT_EQ(a.identity, b.identity);
        EXPECT_EQ(a.e_x_mm, b.e_x_mm);
        EXPECT_EQ(a.e_y_mm, b.e_y_mm);
        EXPECT_EQ(a.e_phi_deg, b.e_phi_deg);
        EXPECT_FALSE(b.qr_centre_only);
        if (a.qr_centre_only) {
          EXPECT_TRUE(a.qr_verified);
        }
        if (cover == 0) {
          ++uncovered;
          centre_uncovered += a.qr_centre_only;
        }
        if (!a.qr_centre_only && a.qr_method != 0) ++fallback_read;
        ++frames;
      }
    }
  }
  std::printf("centre-only first read: %d of %d uncovered frames; read after it failed: %d of %d\n",
              centre_uncovered, uncovered, fallback_read, frames - uncovered);
  EXPECT_EQ(frames, 40);
  EXPECT_EQ(centre_uncovered, uncovered);
  EXPECT_GE(fallback_read, 1);
}

TEST(Tracking, ExtrapolationMovesAlongTheArcAndGrowsTheCovariance) {
  MotionSnapshot s;
  EXPECT_FALSE(extrapolate(s, 0, 10.0, 0.01).valid);
  s.valid = true;
  s.t_ns = 1'000'000'000;
  s.vehicle_in_world = {100.0, 50.0, 0.0};
  s.cov = Eigen::Vector3d(4.0, 4.0, 1e-4).asDiagonal();
  s.v_mm_per_s = 1000.0;
  s.omega_rad_per_s = 0.5;
  const Prediction p = extrapolate(s, s.t_ns + 20'000'000, 100.0, 0.05);
  ASSERT_TRUE(p.valid);
  // 20 ms at 1 m/s along the chord at the mid heading (0.005 rad).
  EXPECT_NEAR(p.vehicle_in_world.x_mm, 100.0 + 20.0 * std::cos(0.005), 1e-9);
  EXPECT_NEAR(p.vehicle_in_world.y_mm, 50.0 + 20.0 * std::sin(0.005), 1e-9);
  EXPECT_NEAR(p.vehicle_in_world.theta_rad, 0.01, 1e-12);
  // Heading uncertainty moves into the cross-track position; the growth terms add on top.
  EXPECT_NEAR(p.cov(1, 1), 4.0 + 1e-4 * 20.0 * 20.0 * std::cos(0.005) * std::cos(0.005) + 4.0,
              1e-9);
  EXPECT_NEAR(p.cov(2, 2), 1e-4 + 0.001 * 0.001, 1e-12);
  EXPECT_GT(p.cov(0, 0), 4.0);
  // Same time: the snapshot itself.
  const Prediction same = extrapolate(s, s.t_ns, 100.0, 0.05);
  EXPECT_EQ(same.vehicle_in_world.x_mm, 100.0);
  EXPECT_EQ(same.cov, s.cov);
}

// Detection from the prediction (predicted_detect.cpp): a prediction whose corners are known to
// within half the edge band places the bands itself; no detection runs, and the fix agrees with
// the full search's as the tracked detection's does (the bands' ends follow the predicted centre
// instead of the detection's, which moves the last edge points).
constexpr double kPredictedPosTolMm = 0.01;
constexpr double kPredictedHeadingTolDeg = 0.01;

TEST(Tracking, PrecisePredictionPlacesTheBandsWithoutDetection) {
  const LandmarkMap map = one_map();
  double max_pos = 0.0, max_head = 0.0;
  for (const CameraModel& cam : {CameraModel::default_640x480(), tilted_camera()}) {
    VisionConfig off;
    off.tracking.detect_from_prediction = false;
    LandmarkLocalizer loc(VisionConfig{}, cam, LandmarkGeometry{}, &map);
    LandmarkLocalizer loc_off(off, cam, LandmarkGeometry{}, &map);
    int n = 0, n_predicted = 0;
    for (double dx : {-40.0, 0.0, 25.0}) {
      for (double deg : {3.0, 44.0, 151.0, 268.0}) {
        const Pose2 v = over_landmark(cam, dx, 0.6 * dx, deg_to_rad(deg));
        const cv::Mat img = render(map, v, cam);
        LandmarkFix full, pr, tr;
        if (loc.process(img, &full) != FixStatus::kOk) continue;
        ++n;
        const Pose2 pv{v.x_mm + 0.2, v.y_mm - 0.1, v.theta_rad + deg_to_rad(0.02)};
        ASSERT_EQ(loc.process(img, predict(pv, 0.1, 0.02), &pr), FixStatus::kOk)
            << dx << " " << deg;
        EXPECT_EQ(pr.search, SearchMode::kWindow);
        // A landmark cut by the image border keeps the detection (the predicted square is
        // checked, so one just inside may too).
        EXPECT_TRUE(!full.partly_outside || !pr.detection_predicted) << dx << " " << deg;
        if (!pr.detection_predicted) continue;
        ++n_predicted;
        EXPECT_EQ(pr.corner_score, 0.0);
        const FixDiff d = fix_diff(full, pr);
        max_pos = std::max(max_pos, d.pos_mm);
        max_head = std::max(max_head, d.heading_deg);
        // Switched off: the tracked detection, as before.
        ASSERT_EQ(loc_off.process(img, predict(pv, 0.1, 0.02), &tr), FixStatus::kOk);
        EXPECT_FALSE(tr.detection_predicted);
        EXPECT_GT(tr.corner_score, 0.0);
        // A looser prediction (sigma 3 mm: 4 sigma is far more than half the band) does not
        // place the bands itself: the edge probes do, or without them the tracked detection.
        ASSERT_EQ(loc.process(img, predict(pv, 3.0, 0.3), &tr), FixStatus::kOk);
        EXPECT_TRUE(tr.detection_probed);
        ASSERT_EQ(loc_off.process(img, predict(pv, 3.0, 0.3), &tr), FixStatus::kOk);
        EXPECT_FALSE(tr.detection_predicted);
      }
    }
    EXPECT_GE(n, 8);
    EXPECT_GE(n_predicted, 4);
  }
  std::printf("predicted bands vs full search: max position difference %.6f mm, heading %.6f deg\n",
              max_pos, max_head);
  EXPECT_LE(max_pos, kPredictedPosTolMm);
  EXPECT_LE(max_head, kPredictedHeadingTolDeg);
}

// A prediction that claims to be precise but is wrong: the bands miss the edges (3 mm off, more
// than the band) or the fit lands elsewhere than predicted (1.5 mm off, inside the band but
// beyond the gate). Either way the frame falls back to the tracked detection and its fix.
TEST(Tracking, WrongPrecisePredictionFallsBackToTheDetection) {
  OnOff t([](VisionConfig* c) { c->tracking.detect_from_prediction = false; });
  auto& [map, cam, off, loc, loc_off] = t;
  for (double miss_mm : {1.5, 3.0, 6.0}) {
    for (double deg : {12.0, 200.0}) {
      const Pose2 v = over_landmark(cam, 8.0, -5.0, deg_to_rad(deg));
      const cv::Mat img = render(map, v, cam);
      const Pose2 wrong = compose(v, Pose2{miss_mm, 0.0, 0.0});
      LandmarkFix fb, tr;
      ASSERT_EQ(loc.process(img, predict(wrong, 0.1, 0.02), &fb), FixStatus::kOk) << miss_mm;
      EXPECT_FALSE(fb.detection_predicted) << miss_mm << " " << deg;
      ASSERT_EQ(loc_off.process(img, predict(wrong, 0.1, 0.02), &tr), FixStatus::kOk);
      expect_same_fix(tr, fb);
    }
  }
}

// A precise prediction of a landmark that is not there (plain floor where the map says one is):
// no fix and not the predicted path. On plain floor both the full-image ring check and the pose
// decline, so this checks the outcome, not which of the two declined.
TEST(Tracking, PrecisePredictionOfAMissingLandmarkGivesNoFix) {
  const LandmarkMap map = one_map();
  const CameraModel cam = CameraModel::default_640x480();
  LandmarkLocalizer loc(VisionConfig{}, cam, LandmarkGeometry{}, &map);
  const Pose2 v = over_landmark(cam, 0.0, 0.0, 0.3);
  const cv::Mat blank = render(LandmarkMap{}, v, cam);
  // Precise (the prediction places the bands) and loose (the edge probes would).
  for (const double sigma_mm : {0.1, 3.0}) {
    LandmarkFix fix;
    EXPECT_EQ(loc.process(blank, predict(v, sigma_mm, 0.02), &fix), FixStatus::kNoLandmark);
    EXPECT_FALSE(fix.detection_predicted) << sigma_mm;
  }
}

// Edge probes (edge_probe.cpp): a trusted prediction too loose to place the bands itself (sigma 3
// mm: 4 sigma is 46 px) is made precise by 1-D searches for the border's outer edge across each
// predicted side. No detection runs, and the fix agrees with the full search's as closely as the
// tracked detection's does; the probes' centre is nearer the fitted one than either detection's.
TEST(Tracking, EdgeProbesMakeALoosePredictionPrecise) {
  const LandmarkMap map = one_map();
  double max_pos = 0.0, max_head = 0.0, max_probe_px = 0.0;
  for (const CameraModel& cam : {CameraModel::default_640x480(), tilted_camera()}) {
    LandmarkLocalizer loc(VisionConfig{}, cam, LandmarkGeometry{}, &map);
    int n = 0, n_inside = 0, n_probed = 0;
    for (double dx : {-40.0, 0.0, 25.0}) {
      for (double deg : {3.0, 44.0, 151.0, 268.0}) {
        const Pose2 v = over_landmark(cam, dx, 0.6 * dx, deg_to_rad(deg));
        const cv::Mat img = render(map, v, cam);
        LandmarkFix full;
        if (loc.process(img, &full) != FixStatus::kOk) continue;
        ++n;
        if (!full.partly_outside) n_inside += 3;
        for (const Pose2& off : {Pose2{4.0, -3.0, deg_to_rad(0.4)}, Pose2{-9.0, 5.0, -0.01},
                                 Pose2{0.0, 10.0, deg_to_rad(1.0)}}) {
          const Pose2 pv{v.x_mm + off.x_mm, v.y_mm + off.y_mm, v.theta_rad + off.theta_rad};
          LandmarkFix pr;
          ASSERT_EQ(loc.process(img, predict(pv, 3.0, 0.3), &pr), FixStatus::kOk)
              << dx << " " << deg;
          EXPECT_EQ(pr.search, SearchMode::kWindow);
          EXPECT_EQ(pr.detection_probed, pr.detection_predicted);
          // A landmark cut by the image border keeps the detection.
          EXPECT_TRUE(!full.partly_outside || !pr.detection_probed) << dx << " " << deg;
          if (!pr.detection_probed) continue;
          ++n_probed;
          EXPECT_EQ(pr.corner_score, 0.0);
          const FixDiff d = fix_diff(full, pr);
          max_pos = std::max(max_pos, d.pos_mm);
          max_head = std::max(max_head, d.heading_deg);
          Vec2 fit_px;
          ASSERT_TRUE(cam.vehicle_to_pixel(
              {full.landmark_in_vehicle.x_mm, full.landmark_in_vehicle.y_mm}, &fit_px));
          max_probe_px = std::max(max_probe_px,
                                  std::hypot(pr.detect_x_px - fit_px.x, pr.detect_y_px - fit_px.y));
        }
      }
    }
    EXPECT_GE(n, 8);
    // Every landmark wholly in view, near the image border too (a probe starts where it enters
    // the image).
    EXPECT_GE(n_inside, 3 * 4);
    EXPECT_EQ(n_probed, n_inside);
  }
  std::printf(
      "edge probes vs full search: max position difference %.6f mm, heading %.6f deg; probes' "
      "centre to fitted centre %.2f px\n",
      max_pos, max_head, max_probe_px);
  EXPECT_LE(max_pos, kPredictedPosTolMm);
  EXPECT_LE(max_head, kPredictedHeadingTolDeg);
  // The detections are up to 6.45 px off (TrackedFixMatchesFullSearchFix); the probes' lines
  // through the outer edge are within a pixel or two (perspective and lens distortion bend the
  // sides the lines are fitted to).
  EXPECT_LE(max_probe_px, 2.0);
}

namespace {

// Paints the middle of one border side (u in +-20 mm, the border and 10 mm of floor beyond it) in
// the floor's grey: a pallet foot or a shoe over the side, where every probe of that side falls.
void cover_side(cv::Mat* img, const CameraModel& cam, const Pose2& landmark_in_vehicle) {
  const LandmarkGeometry g;
  auto px_of = [&](Vec2 uv) {
    Vec2 px;
    EXPECT_TRUE(cam.vehicle_to_pixel(transform(landmark_in_vehicle, page_to_landmark(uv)), &px));
    return cv::Point(static_cast<int>(std::lround(px.x)), static_cast<int>(std::lround(px.y)));
  };
  const cv::Point floor = px_of({0.0, 45.0 * g.k()});
  const std::uint8_t grey = img->at<std::uint8_t>(floor.y, floor.x);
  std::vector<cv::Point> poly;
  for (const Vec2 uv : {Vec2{-20.0 * g.k(), 22.0 * g.k()}, Vec2{20.0 * g.k(), 22.0 * g.k()},
                        Vec2{20.0 * g.k(), 40.0 * g.k()}, Vec2{-20.0 * g.k(), 40.0 * g.k()}}) {
    poly.push_back(px_of(uv));
  }
  cv::fillConvexPoly(*img, poly, cv::Scalar(grey));
}

}  // namespace

namespace {

// The frame with the edge probes on (loc) is not probed and gives the same fix, to 1e-9, as with
// them off (loc_off): what the probes decline, the tracked detection handles as before. Returns
// the fix's status.
FixStatus expect_probes_fall_back(LandmarkLocalizer& loc, LandmarkLocalizer& loc_off,
                                  const cv::Mat& img, const Prediction& pred, double tag) {
  LandmarkFix fb, tr;
  const FixStatus st = loc.process(img, pred, &fb);
  loc_off.process(img, pred, &tr);
  EXPECT_FALSE(fb.detection_predicted) << tag;
  expect_same_fix(tr, fb);
  return st;
}

}  // namespace

// What the probes decline, the tracked detection (and after it the windows and the full frame)
// handles as before, bit for bit: a covered side (no border edge under that side's probes) and a
// loose prediction 25 mm off (beyond its 4 sigma: the lines, if any, are not where it said).
// Plain floor where the map puts a landmark: PrecisePredictionOfAMissingLandmarkGivesNoFix.
TEST(Tracking, EdgeProbesDeclineWhatIsNotTheBorder) {
  OnOff t([](VisionConfig* c) { c->tracking.probe_edges = false; });
  auto& [map, cam, off, loc, loc_off] = t;
  int n_covered = 0;
  for (double deg : {12.0, 200.0}) {
    const Pose2 v = over_landmark(cam, 8.0, -5.0, deg_to_rad(deg));
    cv::Mat img = render(map, v, cam);
    LandmarkFix full;
    ASSERT_EQ(loc.process(img, &full), FixStatus::kOk);
    // The probes take the clean frame.
    LandmarkFix clean;
    ASSERT_EQ(loc.process(img, predict(v, 3.0, 0.3), &clean), FixStatus::kOk);
    EXPECT_TRUE(clean.detection_probed) << deg;
    for (const Pose2& wrong :
         {compose(v, Pose2{25.0, 0.0, 0.0}), compose(v, Pose2{0.0, -25.0, 0.0})}) {
      expect_probes_fall_back(loc, loc_off, img, predict(wrong, 3.0, 0.3), deg);
    }
    cover_side(&img, cam, full.landmark_in_vehicle);
    if (expect_probes_fall_back(loc, loc_off, img, predict(v, 3.0, 0.3), deg) == FixStatus::kOk) {
      ++n_covered;
    }
  }
  // The covered frames still give fixes (three sides and the rest of the fourth): the fallback
  // was exercised, not a frame without a landmark.
  EXPECT_GE(n_covered, 1);
}

// A blurred landmark keeps the detection (edge_probe.cpp kMaxMeanRampPx): with defocus 2 px,
// 7 px of motion blur and noise at once the tracked detection's fixes were measured better than
// the probes'. The same view sharp is probed; blurred it is not, and gives the tracked fix.
TEST(Tracking, EdgeProbesLeaveABlurredLandmarkToTheDetection) {
  OnOff t([](VisionConfig* c) { c->tracking.probe_edges = false; });
  auto& [map, cam, off, loc, loc_off] = t;
  sim::Scene scene;
  std::string err;
  ASSERT_TRUE(sim::make_scene(map, LandmarkGeometry{}, sim::PayloadMode::kFull, &scene, &err));
  int n_blurred = 0;
  for (double deg : {20.0, 135.0, 250.0}) {
    const Pose2 v = over_landmark(cam, 5.0, 3.0, deg_to_rad(deg));
    sim::RenderOptions sharp;
    std::mt19937_64 rng(3);
    LandmarkFix fix;
    ASSERT_EQ(loc.process(sim::render_frame(scene, cam, v, sharp, rng), predict(v, 3.0, 0.3), &fix),
              FixStatus::kOk);
    EXPECT_TRUE(fix.detection_probed) << deg;
    sim::RenderOptions blurred;
    blurred.defocus_sigma_px = 2.0;
    blurred.exposure_s = 0.001;
    blurred.speed_mps = 7.0 * cam.mm_per_px();  // 7 px during the exposure
    blurred.read_noise_sigma = 4.0;
    const cv::Mat img = sim::render_frame(scene, cam, v, blurred, rng);
    if (expect_probes_fall_back(loc, loc_off, img, predict(v, 3.0, 0.3), deg) == FixStatus::kOk) {
      ++n_blurred;
    }
  }
  EXPECT_GE(n_blurred, 2);
}

// Logo at the code's turn (docs/design/tracking.md): a tracked frame whose code verifies at the
// predicted turn scores the logo at that turn only, and gives the four turns' fix. An erased logo,
// or one printed a quarter turn away, takes the four turns; the latter is refused as before.
TEST(Tracking, LogoIsScoredAtTheVerifiedCodesTurnOnly) {
  OnOff t([](VisionConfig* c) { c->tracking.logo_at_code_turn = false; });
  auto& [map, cam, four, loc, loc4] = t;
  enum { kIntact, kErased, kTurned };
  for (int logo : {kIntact, kErased, kTurned}) {
    for (double deg : {3.0, 44.0, 151.0, 268.0}) {
      const Pose2 v = over_landmark(cam, 6.0, -4.0, deg_to_rad(deg));
      cv::Mat img = render(map, v, cam);
      const Pose2 lm{cam.mount.offset_x_mm + 6.0, cam.mount.offset_y_mm - 4.0, deg_to_rad(deg)};
      if (logo != kIntact) erase_logo(&img, cam, lm);
      if (logo == kTurned) paint_logo_turned(&img, cam, lm);
      const Prediction p = predict(compose(v, Pose2{3.0, -2.0, 0.004}), 3.0, 0.3);
      LandmarkFix one, all;
      loc.process(img, p, &one);
      loc4.process(img, p, &all);
      SCOPED_TRACE(testing::Message() << "logo case " << logo << ", heading " << deg);
      expect_same_fix(one, all);
      EXPECT_EQ(one.logo_one_turn, logo == kIntact);
      EXPECT_FALSE(all.logo_one_turn);
      EXPECT_EQ(one.search, SearchMode::kWindow);
      if (logo == kIntact) {
        EXPECT_EQ(one.status, FixStatus::kOk);
        EXPECT_TRUE(one.qr_verified);
        // The same NCC at the same turn; only the margin over the other turns is not measured.
        EXPECT_EQ(one.logo_score, all.logo_score);
        EXPECT_EQ(one.logo_margin, 0.0);
        EXPECT_GT(all.logo_margin, four.logo_margin);
      } else {
        EXPECT_EQ(one.logo_score, all.logo_score);
        EXPECT_EQ(one.logo_margin, all.logo_margin);
      }
      if (logo == kErased) {
        EXPECT_EQ(one.status, FixStatus::kOk);
      }
      if (logo == kTurned) {
        // Refused: the direction is ambiguous, or the turned logo (which overlaps two module
        // columns of the code) left the code unread at every turn the reader tried.
        EXPECT_TRUE(one.status == FixStatus::kDirectionAmbiguous ||
                    one.status == FixStatus::kQrUnreadable)
            << to_string(one.status);
      }
    }
  }
}
