// Intrinsics calibration on simulated board views (agv_sim calib_board through the project's
// camera model with distortion): recovered vs true, blurred-view rejection, too few views,
// coverage warnings, and the configuration snippet round trip through the key table.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <opencv2/imgproc.hpp>
#include <string>
#include <vector>

#include "agv/config/config.hpp"
#include "calib_intrinsics.hpp"

#if AGV_HAVE_ARUCO
#include <opencv2/aruco/charuco.hpp>
#endif

namespace agv::desk::calib {
namespace {

struct SimRun {
  Result result;
  std::vector<SimView> sim;
};

SimRun simulate_and_calibrate(const BoardSpec& spec, const SimBoardSet& set,
                              const Options& options = {}) {
  SimRun run;
  std::string error;
  EXPECT_TRUE(simulate_board_views(spec, set, &run.sim, &error)) << error;
  std::vector<View> views;
  for (const auto& s : run.sim) views.push_back(detect_view(s.image, s.name, spec, options));
  run.result = calibrate(std::move(views), spec, options);
  return run;
}

// Prints the recovered-vs-true table (simulated views) and checks the targets:
// fx, fy within 0.1 %, principal point within 0.5 px, RMS within max_rms.
void expect_targets(const char* label, const Result& r, const CameraIntrinsics& t, double max_rms) {
  ASSERT_TRUE(r.ok) << r.error;
  const auto& e = r.intrinsics;
  std::printf("%s (simulated views): %d usable of %zu, %d corners, RMS %.4f px\n", label, r.usable,
              r.views.size(), r.corners, r.rms_px);
  std::printf("  param   recovered        true       error\n");
  std::printf("  fx   %11.4f %11.4f %+10.4f %%\n", e.fx, t.fx, 100 * (e.fx - t.fx) / t.fx);
  std::printf("  fy   %11.4f %11.4f %+10.4f %%\n", e.fy, t.fy, 100 * (e.fy - t.fy) / t.fy);
  std::printf("  cx   %11.4f %11.4f %+10.4f px\n", e.cx, t.cx, e.cx - t.cx);
  std::printf("  cy   %11.4f %11.4f %+10.4f px\n", e.cy, t.cy, e.cy - t.cy);
  std::printf("  k1   %11.6f %11.6f %+10.6f\n", e.k1, t.k1, e.k1 - t.k1);
  std::printf("  k2   %11.6f %11.6f %+10.6f\n", e.k2, t.k2, e.k2 - t.k2);
  std::printf("  p1   %11.6f %11.6f %+10.6f\n", e.p1, t.p1, e.p1 - t.p1);
  std::printf("  p2   %11.6f %11.6f %+10.6f\n", e.p2, t.p2, e.p2 - t.p2);
  std::printf("  k3   %11.6f %11.6f %+10.6f\n", e.k3, t.k3, e.k3 - t.k3);
  EXPECT_LE(std::abs(e.fx - t.fx) / t.fx, 0.001);
  EXPECT_LE(std::abs(e.fy - t.fy) / t.fy, 0.001);
  EXPECT_LE(std::abs(e.cx - t.cx), 0.5);
  EXPECT_LE(std::abs(e.cy - t.cy), 0.5);
  EXPECT_LE(r.rms_px, max_rms);
  EXPECT_EQ(e.width_px, t.width_px);
  EXPECT_EQ(e.height_px, t.height_px);
}

TEST(CalibIntrinsics, CharucoThirtyCleanViewsMeetTheTargets) {
  if (!have_charuco()) GTEST_SKIP() << "built without OpenCV aruco";
  SimBoardSet set = default_sim_board_set();
  set.blur_sigma_px = 0.0;
  set.noise_sigma = 0.0;
  set.blurred = 0;
  const SimRun run = simulate_and_calibrate(BoardSpec{}, set);
  expect_targets("ChArUco 11x8, 30 clean views", run.result, set.camera, 0.1);
  EXPECT_EQ(run.result.usable, 30);
  EXPECT_TRUE(run.result.coverage.warnings.empty());
}

TEST(CalibIntrinsics, CharucoMildBlurAndNoiseRejectsTheBlurredViewsByName) {
  if (!have_charuco()) GTEST_SKIP() << "built without OpenCV aruco";
  SimBoardSet set = default_sim_board_set();  // blur 0.5 px, noise 1.0, 3 blurred (3 px)
  set.seed = 2;
  const SimRun run = simulate_and_calibrate(BoardSpec{}, set);
  expect_targets("ChArUco 11x8, 30 views with blur 0.5 px + noise 1.0", run.result, set.camera,
                 0.1);
  ASSERT_EQ(run.result.views.size(), run.sim.size());
  int blurred = 0;
  for (size_t i = 0; i < run.sim.size(); ++i) {
    const View& v = run.result.views[i];
    EXPECT_EQ(v.name, run.sim[i].name);
    if (run.sim[i].blurred) {
      ++blurred;
      EXPECT_FALSE(v.used) << v.name;
      EXPECT_EQ(v.reject_reason.rfind("blurred: edge blur ", 0), 0u)
          << v.name << ": " << v.reject_reason;
    } else {
      EXPECT_TRUE(v.used) << v.name << ": " << v.reject_reason;
    }
  }
  EXPECT_EQ(blurred, 3);
  const std::string report = report_text(run.result);
  for (const auto& s : run.sim) {
    if (s.blurred) {
      EXPECT_NE(report.find(s.name + " "), std::string::npos);
    }
  }
  EXPECT_NE(report.find("rejected: blurred"), std::string::npos) << report;
}

// A board that is not flat (the calibration takes it flat) leaves its mark in the residual and
// in the lens: what a real print on foam board does that the flat simulated one does not.
TEST(CalibIntrinsics, ABowedBoardRaisesTheResidual) {
  if (!have_charuco()) GTEST_SKIP() << "built without OpenCV aruco";
  SimBoardSet set = default_sim_board_set();
  set.blurred = 0;
  set.views = 15;
  set.seed = 3;
  const SimRun flat = simulate_and_calibrate(BoardSpec{}, set);
  set.bow_mm = 0.3;  // of a 110 x 80 mm board
  const SimRun bowed = simulate_and_calibrate(BoardSpec{}, set);
  ASSERT_TRUE(flat.result.ok) << flat.result.error;
  ASSERT_TRUE(bowed.result.ok) << bowed.result.error;
  double moved = 0.0;
  for (std::size_t i = 0; i < flat.sim.size(); ++i) {
    moved = std::max(moved, cv::norm(flat.sim[i].image, bowed.sim[i].image, cv::NORM_INF));
  }
  const auto& f = flat.result.intrinsics;
  const auto& b = bowed.result.intrinsics;
  std::printf("flat: RMS %.4f px, fx %.3f k1 %.5f; bowed 0.3 mm: RMS %.4f px, fx %.3f k1 %.5f\n",
              flat.result.rms_px, f.fx, f.k1, bowed.result.rms_px, b.fx, b.k1);
  EXPECT_GT(moved, 50.0);  // edges moved: the bow is rendered
  EXPECT_GT(bowed.result.rms_px, 2.0 * flat.result.rms_px);
}

// The evaluations' board (calibrate_simulated_board, 660 x 480 mm): flat, the focal lengths come
// back; bowed 1 mm at its centre, both come back long by about 0.3 % while the calibration's own
// sigma stays an order of magnitude smaller (what docs/guide/ranging.md warns of).
TEST(CalibIntrinsics, TheEvaluationBoardsBowMakesTheFocalLengthsLong) {
  if (!have_charuco()) GTEST_SKIP() << "built without OpenCV aruco";
  const CameraIntrinsics t = default_sim_board_set().camera;
  const Result flat = calibrate_simulated_board(t, 12, 0.0, 5);
  const Result bowed = calibrate_simulated_board(t, 12, 1.0, 5);
  ASSERT_TRUE(flat.ok) << flat.error;
  ASSERT_TRUE(bowed.ok) << bowed.error;
  const double flat_rel = flat.intrinsics.fx / t.fx - 1.0;
  const double bowed_rel[2] = {bowed.intrinsics.fx / t.fx - 1.0, bowed.intrinsics.fy / t.fy - 1.0};
  std::printf(
      "evaluation board: flat fx %+.4f %%; bowed 1 mm fx %+.4f %% fy %+.4f %% (own sigma "
      "%.4f %%)\n",
      100.0 * flat_rel, 100.0 * bowed_rel[0], 100.0 * bowed_rel[1],
      100.0 * bowed.stddev[0] / bowed.intrinsics.fx);
  EXPECT_LT(std::abs(flat_rel), 0.0005);
  for (const double rel : bowed_rel) {
    EXPECT_GT(rel, 0.0015);
    EXPECT_LT(rel, 0.005);
    EXPECT_GT(rel, 5.0 * bowed.stddev[0] / bowed.intrinsics.fx);
  }
}
TEST(CalibIntrinsics, ChessboardThirtyCleanViewsMeetTheTargets) {
  BoardSpec spec;
  spec.type = BoardType::kChessboard;
  spec.squares_x = 9;
  spec.squares_y = 7;
  spec.square_mm = 10.0;
  SimBoardSet set = default_sim_board_set();
  set.blur_sigma_px = 0.0;
  set.noise_sigma = 0.0;
  set.blurred = 0;
  set.seed = 3;
  const SimRun run = simulate_and_calibrate(spec, set);
  expect_targets("chessboard 9x7, 30 clean views", run.result, set.camera, 0.1);
  EXPECT_EQ(run.result.usable, 30);
}

TEST(CalibIntrinsics, TooFewUsableViewsIsAnErrorNamingTheMinimumAndTheCount) {
  BoardSpec spec;
  spec.type = have_charuco() ? BoardType::kCharuco : BoardType::kChessboard;
  SimBoardSet set = default_sim_board_set();
  set.views = 6;
  set.blurred = 2;
  const SimRun run = simulate_and_calibrate(spec, set);
  const Result& r = run.result;
  EXPECT_FALSE(r.ok);
  EXPECT_EQ(r.usable, 6);
  EXPECT_NE(r.error.find("only 6 usable view(s) of 8, at least 10 needed (--min-views)"),
            std::string::npos)
      << r.error;
  // The rejected views are listed with their reason.
  for (const auto& s : run.sim) {
    if (s.blurred) {
      EXPECT_NE(r.error.find(s.name + ": blurred"), std::string::npos) << r.error;
    }
  }
  // With the minimum lowered the same views calibrate.
  Options lower;
  lower.min_views = 6;
  std::vector<View> again = r.views;
  EXPECT_TRUE(calibrate(std::move(again), spec, lower).ok);
}

TEST(CalibIntrinsics, EdgeBlurEstimateFollowsTheBlur) {
  const sim::CalibBoard board = sim::make_chessboard(9, 7, 10.0, 10.0);
  const SimBoardSet set = default_sim_board_set();
  sim::BoardPoseOptions po;
  po.near_mm = 200.0;
  po.far_mm = 220.0;
  const auto poses = sim::calib_view_poses(board, set.camera, 1, 5, po);
  ASSERT_EQ(poses.size(), 1u);
  std::vector<double> est;
  for (double sigma : {0.0, 1.5, 3.0}) {
    sim::BoardImageOptions o;
    o.blur_sigma_px = sigma;
    o.noise_sigma = 1.0;
    const cv::Mat img = sim::render_board_view(board, set.camera, poses[0], o);
    est.push_back(edge_blur_px(img, {}));
    std::printf("blur sigma %.1f px -> edge blur estimate %.2f px\n", sigma, est.back());
  }
  EXPECT_LT(est[0], 1.2);
  EXPECT_GT(est[1], est[0] + 0.4);
  EXPECT_GT(est[2], 2.5);
  EXPECT_LT(est[2], 4.0);
}

TEST(CalibIntrinsics, ADetectedButBlurredViewIsRejectedByName) {
  BoardSpec spec;
  spec.type = BoardType::kChessboard;  // findChessboardCorners still finds a 3 px blurred board
  SimBoardSet set = default_sim_board_set();
  set.views = 2;
  set.blurred = 1;
  std::vector<SimView> sim;
  std::string error;
  ASSERT_TRUE(simulate_board_views(spec, set, &sim, &error)) << error;
  ASSERT_EQ(sim.size(), 3u);
  for (const auto& s : sim) {
    const View v = detect_view(s.image, s.name, spec, Options{});
    EXPECT_TRUE(v.detected) << v.name << ": " << v.reject_reason;
    EXPECT_EQ(v.image_points.size(), 70u);
    if (s.blurred) {
      EXPECT_EQ(v.reject_reason.rfind("blurred: edge blur ", 0), 0u) << v.reject_reason;
      EXPECT_GT(v.blur_px, 2.5);
    } else {
      EXPECT_TRUE(v.reject_reason.empty()) << v.name << ": " << v.reject_reason;
      EXPECT_LT(v.blur_px, 1.2);
    }
  }
}

// An X-junction at a sub-pixel position, drawn at 8x and area-averaged; optionally a dark blob
// (a marker corner) inside the refinement window.
cv::Mat x_junction(cv::Point2d c, bool blob) {
  const int s = 8, w = 100, h = 80;
  cv::Mat big(h * s, w * s, CV_8U);
  for (int y = 0; y < h * s; ++y) {
    for (int x = 0; x < w * s; ++x) {
      const double px = (x + 0.5) / s - 0.5, py = (y + 0.5) / s - 0.5;
      const bool dark = ((px < c.x) != (py < c.y));
      const bool in_blob =
          blob && px > c.x + 2.0 && px < c.x + 6.0 && py > c.y + 2.0 && py < c.y + 6.0;
      big.at<uchar>(y, x) = (dark || in_blob) ? 30 : 215;
    }
  }
  cv::Mat img;
  cv::resize(big, img, cv::Size(w, h), 0, 0, cv::INTER_AREA);
  return img;
}

TEST(CalibIntrinsics, SaddleRefinementIsSubPixelAndFlagsDisturbedCorners) {
  const cv::Point2d truth(50.375, 40.625);  // on the 1/8 px drawing grid
  std::vector<cv::Point2f> p{cv::Point2f(50.8f, 40.2f)};
  std::vector<double> asym;
  ASSERT_TRUE(refine_saddle(x_junction(truth, false), &p, 3, 1.0, &asym));
  EXPECT_NEAR(p[0].x, truth.x, 0.01);
  EXPECT_NEAR(p[0].y, truth.y, 0.01);
  EXPECT_LT(asym[0], 0.01);
  std::vector<cv::Point2f> q{cv::Point2f(50.8f, 40.2f)};
  refine_saddle(x_junction(truth, true), &q, 3, 1.0, &asym);
  EXPECT_GT(asym[0], 0.05);  // dropped by detect_view
}

#if AGV_HAVE_ARUCO
// The simulator's (and --print-board's) board is the one OpenCV draws: same squares, same
// marker bits, same orientation (only anti-aliasing pixels on cell edges differ).
TEST(CalibIntrinsics, SimulatedBoardMatchesOpenCvsDrawing) {
  const BoardSpec spec;
  sim::CalibBoard b;
  std::string error;
  ASSERT_TRUE(make_sim_board(spec, 0.0, &b, &error)) << error;
  EXPECT_EQ(b.markers.size(), 44u);
  auto board = cv::aruco::CharucoBoard::create(
      spec.squares_x, spec.squares_y, static_cast<float>(spec.square_mm),
      static_cast<float>(spec.marker_mm),
      cv::aruco::getPredefinedDictionary(cv::aruco::DICT_4X4_50));
  const int ppm = 12;  // pixels per mm: 7.5 mm markers have 15 px cells
  cv::Mat img;
  board->draw(cv::Size(spec.squares_x * 10 * ppm, spec.squares_y * 10 * ppm), img, 0, 1);
  long bad = 0, n = 0;
  for (int y = 0; y < img.rows; ++y) {
    for (int x = 0; x < img.cols; ++x) {
      const bool dark = img.at<uchar>(y, x) < 128;
      const bool sim_dark = b.at({(x + 0.5) / ppm, (y + 0.5) / ppm}) == sim::PageInk::kBlack;
      bad += dark != sim_dark ? 1 : 0;
      ++n;
    }
  }
  std::printf("simulated vs OpenCV-drawn board: %.4f %% of pixels differ\n", 100.0 * bad / n);
  EXPECT_LT(static_cast<double>(bad) / n, 0.002);
  const std::string svg = board_svg(spec, b);
  EXPECT_NE(svg.find("width=\"110mm\""), std::string::npos) << svg.substr(0, 200);  // no margin
  EXPECT_EQ(svg.find("scale(1 -1)"), std::string::npos);  // Debian's 4.6 board frame has y down
}
#endif

View synthetic_view(const std::string& name, cv::Size size, double x0, double x1, double y0,
                    double y1) {
  View v;
  v.name = name;
  v.size = size;
  v.detected = true;
  v.used = true;
  for (int j = 0; j < 5; ++j) {
    for (int i = 0; i < 5; ++i) {
      v.image_points.emplace_back(static_cast<float>(x0 + (x1 - x0) * i / 4.0),
                                  static_cast<float>(y0 + (y1 - y0) * j / 4.0));
    }
  }
  return v;
}

TEST(CalibIntrinsics, CoverageNamesEmptyQuadrantsAndBorderBands) {
  const cv::Size size(640, 480);
  // Corners only in the left half, away from the top and bottom bands.
  const std::vector<View> views{synthetic_view("a.png", size, 10, 300, 60, 200),
                                synthetic_view("b.png", size, 20, 310, 250, 400)};
  const Coverage c = measure_coverage(views, size);
  auto has = [&](const std::string& s) {
    for (const auto& w : c.warnings) {
      if (w.find(s) != std::string::npos) return true;
    }
    return false;
  };
  EXPECT_TRUE(has("top-right quadrant"));
  EXPECT_TRUE(has("bottom-right quadrant"));
  EXPECT_FALSE(has("top-left quadrant"));
  EXPECT_FALSE(has("bottom-left quadrant"));
  EXPECT_TRUE(has("right border band"));
  EXPECT_TRUE(has("top border band"));
  EXPECT_TRUE(has("bottom border band"));
  EXPECT_FALSE(has("left border band"));
  EXPECT_EQ(c.warnings.size(), 5u);
  EXPECT_NEAR(c.covered, 24.0 / 48.0, 1e-9);  // columns 0..3 of 8 in all 6 rows
  Result r;
  r.views = views;
  r.usable = 2;
  r.coverage = c;
  r.intrinsics.width_px = 640;
  r.intrinsics.height_px = 480;
  const std::string svg = coverage_svg(r);
  size_t circles = 0;
  for (size_t p = svg.find("<circle"); p != std::string::npos; p = svg.find("<circle", p + 1)) {
    ++circles;
  }
  EXPECT_EQ(circles, 50u);
  EXPECT_NE(svg.find("top-right quadrant"), std::string::npos);
}

TEST(CalibIntrinsics, SnippetParsesWithTheKeyTableAndRoundTrips) {
  Result r;
  r.ok = true;
  r.usable = 30;
  r.corners = 1646;
  r.rms_px = 0.0141;
  auto& k = r.intrinsics;
  k = {.width_px = 1280,
       .height_px = 800,
       .fx = 1542.123456789,
       .fy = 1539.987654321,
       .cx = 641.25,
       .cy = 398.75,
       .k1 = -0.123456789,
       .k2 = 0.0876543211,
       .p1 = 0.000612345,
       .p2 = -0.000398765,
       .k3 = 0.0212345678};
  const std::string text = config_snippet(r, "views/");
  config::Config cfg;
  std::vector<std::string> errors;
  ASSERT_TRUE(config::parse_config(text, ".", &cfg, &errors)) << text << errors.front();
  const auto& p = cfg.camera_model.intrinsics;
  EXPECT_EQ(p.width_px, 1280);
  EXPECT_EQ(p.height_px, 800);
  EXPECT_EQ(cfg.camera.camera.width_px, 1280);
  for (auto [got, want] : {std::pair{p.fx, k.fx},
                           {p.fy, k.fy},
                           {p.cx, k.cx},
                           {p.cy, k.cy},
                           {p.k1, k.k1},
                           {p.k2, k.k2},
                           {p.p1, k.p1},
                           {p.p2, k.p2},
                           {p.k3, k.k3}}) {
    EXPECT_NEAR(got, want, 1e-11 * std::max(1.0, std::abs(want)));
  }
  // A refused result has no snippet to give: the command writes nothing (test_calib_cli).
  // The simulator's truth file is a configuration file as well.
  SimBoardSet set = default_sim_board_set();
  config::Config truth;
  ASSERT_TRUE(config::parse_config(truth_yaml(set, {}), ".", &truth, &errors));
  EXPECT_DOUBLE_EQ(truth.camera_model.intrinsics.fx, set.camera.fx);
  EXPECT_DOUBLE_EQ(truth.camera_model.intrinsics.p2, set.camera.p2);
}

TEST(CalibIntrinsics, BadBoardSpecsAreNamed) {
  std::string error;
  BoardSpec s;
  s.squares_x = 2;
  EXPECT_FALSE(validate_board(s, &error));
  EXPECT_NE(error.find("each side needs 3..100 squares"), std::string::npos) << error;
  if (have_charuco()) {
    s = BoardSpec{};
    s.marker_mm = 12.0;
    EXPECT_FALSE(validate_board(s, &error));
    EXPECT_NE(error.find("below the square size"), std::string::npos) << error;
    s = BoardSpec{};
    s.dictionary = "DICT_9X9_1";
    EXPECT_FALSE(validate_board(s, &error));
    EXPECT_NE(error.find("unknown dictionary 'DICT_9X9_1'"), std::string::npos) << error;
    s = BoardSpec{};
    s.squares_x = 20;
    s.squares_y = 20;  // 200 markers > 50 in DICT_4X4_50
    EXPECT_FALSE(validate_board(s, &error));
    EXPECT_NE(error.find("has 50 markers, the board needs 200"), std::string::npos) << error;
  }
}

}  // namespace
}  // namespace agv::desk::calib
