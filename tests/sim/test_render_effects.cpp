// Imaging effects and degradations do what docs/design/simulator.md says, and only that.
#include <gtest/gtest.h>

#include <cmath>
#include <opencv2/imgproc.hpp>

#include "agv/sim/render.hpp"

using namespace agv;
using namespace agv::sim;

namespace {

// Landmark 1 at the world origin, heading 0; with the vehicle at the origin too, page (u, v)
// maps to pixel centre + (u, v) / 0.26 (image up = landmark forward).
struct Fixture {
  Scene scene;
  CameraModel cam = CameraModel::default_640x480();
  Fixture() {
    LandmarkMap map;
    map.entries[1] = {1, {0.0, 0.0, 0.0}};
    std::string err;
    EXPECT_TRUE(make_scene(map, LandmarkGeometry{}, PayloadMode::kFull, &scene, &err)) << err;
    scene.floor.amplitude = 0.0;
  }
  cv::Mat render(const RenderOptions& o, std::uint64_t seed = 1) const {
    std::mt19937_64 rng(seed);
    return render_frame(scene, cam, {0.0, 0.0, 0.0}, o, rng);
  }
  // Mean grey over a 5x5 px box around page point (u, v) in mm.
  double at_page(const cv::Mat& img, double u, double v) const {
    const int x = static_cast<int>(std::lround(319.5 + u / 0.26));
    const int y = static_cast<int>(std::lround(239.5 + v / 0.26));
    return cv::mean(img(cv::Rect(x - 2, y - 2, 5, 5)))[0];
  }
};

double max_abs_gradient(const cv::Mat& img, bool along_x, cv::Rect roi) {
  cv::Mat f, g;
  img(roi).convertTo(f, CV_32F);
  cv::Sobel(f, g, CV_32F, along_x ? 1 : 0, along_x ? 0 : 1, 3);
  double mn, mx;
  cv::minMaxLoc(cv::abs(g), &mn, &mx);
  return mx;
}

}  // namespace

TEST(RenderEffects, CleanFrameHasDocumentedGreys) {
  const Fixture f;
  const cv::Mat img = f.render(RenderOptions{});
  EXPECT_NEAR(f.at_page(img, -27.0, 0.0), 30.0, 0.5);   // border (left)
  EXPECT_NEAR(f.at_page(img, 20.0, 0.0), 215.0, 0.5);   // white area right of the QR
  EXPECT_NEAR(f.at_page(img, -40.0, 0.0), 135.0, 0.5);  // flat floor
  EXPECT_NEAR(f.at_page(img, 0.0, -18.0), 30.0, 0.5);   // inside the logo triangle
}

TEST(RenderEffects, OccluderCoversRequestedFractionOfBorderInOrder) {
  const Fixture f;
  RenderOptions o;
  o.occluder_border_fraction = 0.25;  // exactly the left edge (perimeter starts front-left)
  cv::Mat img = f.render(o);
  EXPECT_NEAR(f.at_page(img, -27.0, 0.0), 90.0, 0.5);
  EXPECT_NEAR(f.at_page(img, 0.0, 27.0), 30.0, 0.5);  // bottom still ink
  EXPECT_NEAR(f.at_page(img, 27.0, 0.0), 30.0, 0.5);
  EXPECT_NEAR(f.at_page(img, 0.0, -27.0), 30.0, 0.5);
  EXPECT_NEAR(f.at_page(img, 0.0, 0.0), f.at_page(f.render(RenderOptions{}), 0.0, 0.0), 1e-9);
  o.occluder_border_fraction = 0.5;  // left and bottom
  img = f.render(o);
  EXPECT_NEAR(f.at_page(img, 0.0, 27.0), 90.0, 0.5);
  EXPECT_NEAR(f.at_page(img, 27.0, 0.0), 30.0, 0.5);
  // Overhangs the outer edge (the border's outline is hidden, not just its ink).
  EXPECT_NEAR(f.at_page(img, -31.0, 0.0), 90.0, 0.5);
}

TEST(RenderEffects, ScratchesAndDirtOnlyOnThePrintAndDeterministic) {
  const Fixture f;
  const cv::Mat clean = f.render(RenderOptions{});
  RenderOptions o;
  o.scratches_per_landmark = 4;
  o.dirt_spots_per_landmark = 6;
  const cv::Mat a = f.render(o), b = f.render(o, 99);
  EXPECT_EQ(cv::norm(a, b, cv::NORM_INF), 0.0);  // fixed per landmark, not per frame noise
  cv::Mat diff;
  cv::absdiff(a, clean, diff);
  const int half_px = static_cast<int>(30.0 / 0.26) + 2;
  const cv::Rect lm(320 - half_px, 240 - half_px, 2 * half_px, 2 * half_px);
  EXPECT_GT(cv::countNonZero(diff(lm)), 200);
  cv::Mat outside = diff.clone();
  outside(lm).setTo(0);
  EXPECT_EQ(cv::countNonZero(outside), 0);
  o.degradation_seed = 8;
  EXPECT_GT(cv::norm(f.render(o), a, cv::NORM_INF), 0.0);
}

TEST(RenderEffects, DefocusAndMotionBlur) {
  const Fixture f;
  const cv::Mat clean = f.render(RenderOptions{});
  // The left border's outer edge is vertical in the image, the top border's edge horizontal.
  const cv::Rect left_edge(319 - 125, 200, 20, 80), top_edge(280, 239 - 125, 80, 20);
  RenderOptions o;
  o.defocus_sigma_px = 1.5;
  const cv::Mat blurred = f.render(o);
  EXPECT_LT(max_abs_gradient(blurred, true, left_edge),
            0.6 * max_abs_gradient(clean, true, left_edge));
  // Forward motion moves the floor along image rows: horizontal edges smear, vertical ones not.
  o = {};
  o.exposure_s = 0.004;
  o.speed_mps = 1.0;  // 4 mm = 15 px
  const cv::Mat moving = f.render(o);
  EXPECT_LT(max_abs_gradient(moving, false, top_edge),
            0.3 * max_abs_gradient(clean, false, top_edge));
  EXPECT_NEAR(max_abs_gradient(moving, true, left_edge), max_abs_gradient(clean, true, left_edge),
              0.05 * max_abs_gradient(clean, true, left_edge));
  // Blur is centred on the frame time: the smeared edge keeps its mean position.
  auto edge_row = [&](const cv::Mat& img) {
    double s = 0.0;  // floor-covered length above the top border, column 320
    for (int y = 239 - 140; y < 239 - 105; ++y) s += (img.at<std::uint8_t>(y, 320) - 30.0) / 105.0;
    return s;
  };
  EXPECT_NEAR(edge_row(moving), edge_row(clean), 0.1);
}

TEST(RenderEffects, IlluminationAndNoise) {
  Fixture f;
  f.scene.landmarks.clear();
  RenderOptions o;
  o.illumination_ratio = 0.6;  // direction 0: bright at the left, 0.6 at the right
  const cv::Mat lit = f.render(o);
  EXPECT_NEAR(lit.at<std::uint8_t>(240, 0), 135, 1);
  EXPECT_NEAR(lit.at<std::uint8_t>(240, 639), 0.6 * 135, 1);
  o = {};
  o.read_noise_sigma = 2.0;
  o.shot_noise_gain = 0.1;
  const cv::Mat noisy = f.render(o, 5);
  cv::Scalar mean, sd;
  cv::meanStdDev(noisy, mean, sd);
  EXPECT_NEAR(mean[0], 135.0, 0.2);
  EXPECT_NEAR(sd[0], std::sqrt(4.0 + 0.1 * 135.0), 0.15);
  EXPECT_GT(cv::norm(noisy, f.render(o, 6), cv::NORM_INF), 0.0);
}
