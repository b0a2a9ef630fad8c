// Stage tests on small synthetic images with known answers: Prewitt (eq. 1-4), gradient-direction
// classes, least-squares lines (eq. 5-6), robust fitting, angle averaging (eq. 7, Yang et al. eq.
// 10-11).
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <opencv2/core.hpp>
#include <random>
#include <vector>

#include "agv/vision/bilinear.hpp"
#include "agv/vision/edges.hpp"

using namespace agv;
using namespace agv::vision;

namespace {

// A dark square (value 30) on white (220), half-side h_px, centred at (cx, cy), rotated by
// angle_rad (image angle), area-sampled 8x8.
cv::Mat draw_square(int w, int h, double cx, double cy, double half_px, double angle_rad) {
  cv::Mat img(h, w, CV_8UC1);
  const double c = std::cos(angle_rad), s = std::sin(angle_rad);
  for (int y = 0; y < h; ++y) {
    for (int x = 0; x < w; ++x) {
      int dark = 0;
      for (int sy = 0; sy < 8; ++sy) {
        for (int sx = 0; sx < 8; ++sx) {
          const double dx = x - 0.5 + (sx + 0.5) / 8 - cx, dy = y - 0.5 + (sy + 0.5) / 8 - cy;
          const double u = c * dx + s * dy, v = -s * dx + c * dy;
          if (std::abs(u) <= half_px && std::abs(v) <= half_px) ++dark;
        }
      }
      img.at<std::uint8_t>(y, x) = static_cast<std::uint8_t>(std::lround(220 - 190 * dark / 64.0));
    }
  }
  return img;
}

}  // namespace

TEST(VisionPrewitt, MatchesEquations2And3) {
  cv::Mat img(5, 5, CV_8UC1);
  for (int y = 0; y < 5; ++y) {
    for (int x = 0; x < 5; ++x)
      img.at<std::uint8_t>(y, x) = static_cast<std::uint8_t>(10 * x + 3 * y * y);
  }
  cv::Mat gx, gy;
  prewitt(img, cv::Rect(0, 0, 5, 5), &gx, &gy);
  // Interior pixel (2, 2): gx = sum over rows of f(x+1) - f(x-1) = 3 * 20; gy = sum of columns
  // f(y+1) - f(y-1) = 3 * (3*9 - 3*1).
  EXPECT_EQ(gx.at<std::int16_t>(2, 2), 60);
  EXPECT_EQ(gy.at<std::int16_t>(2, 2), 72);
  // Image border gets 0.
  EXPECT_EQ(gx.at<std::int16_t>(0, 0), 0);
  EXPECT_EQ(gy.at<std::int16_t>(4, 4), 0);
  // An ROI gives the same values at the same image pixel.
  cv::Mat gx2, gy2;
  prewitt(img, cv::Rect(1, 1, 3, 3), &gx2, &gy2);
  EXPECT_EQ(gx2.at<std::int16_t>(1, 1), 60);
  EXPECT_EQ(gy2.at<std::int16_t>(1, 1), 72);
}

// The pose stage's strips (vectorised along rows) give prewitt_at's integers at every pixel and
// screen exactly the pixels at or above the squared threshold: random images (full 0..255
// range, so the largest gradients and squares occur), strips along rows and along columns, every
// length from 1 to 70 (one to five vector chunks, every length of the last), with and without the
// 16-byte chunked reads, thresholds at a pixel's own squared magnitude and one above it.
TEST(VisionPrewitt, StripGradientsEqualPrewittAtAndScreenAtTheThreshold) {
  std::mt19937 rng(17);
  cv::Mat img(90, 97, CV_8UC1);
  StripGradients s;
  int checked = 0, strong_seen = 0;
  for (int image = 0; image < 3; ++image) {
    for (int y = 0; y < img.rows; ++y) {
      for (int x = 0; x < img.cols; ++x) {
        // Image 0 uniform noise; 1 only 0 and 255 (largest gradients); 2 a smooth ramp.
        const int v = image == 0   ? static_cast<int>(rng() % 256)
                      : image == 1 ? (rng() % 2 ? 255 : 0)
                                   : (2 * x + y) % 256;
        img.at<std::uint8_t>(y, x) = static_cast<std::uint8_t>(v);
      }
    }
    const std::ptrdiff_t step = static_cast<std::ptrdiff_t>(img.step[0]);
    for (int along_rows = 0; along_rows < 2; ++along_rows) {
      for (int read_past_end = 0; read_past_end < 2; ++read_past_end) {
        for (int n = 1; n <= 70; ++n) {
          // Strip start (the pixel before the first gradient) at (x0, y0).
          const int x0 = along_rows ? 1 + n % 7 : 1 + n % 90;
          const int y0 = along_rows ? 1 + n % 85 : 1 + n % 5;
          const std::ptrdiff_t dj = along_rows ? 1 : step, di = along_rows ? step : 1;
          const std::uint8_t* p = img.ptr<std::uint8_t>(y0) + x0;
          int gx_ref = 0, gy_ref = 0;
          prewitt_at(p + (n / 2 + 1) * dj, step, &gx_ref, &gy_ref);
          const int mid2 = gx_ref * gx_ref + gy_ref * gy_ref;
          for (int thr2 : {mid2, mid2 + 1, 0, -5, 1170450, 1170451, 5000000}) {
            strip_gradients(p, dj, di, n, thr2, read_past_end != 0, &s);
            ASSERT_GE(s.g_j.size(), static_cast<size_t>(n));
            ASSERT_GE(s.strong.size(), static_cast<size_t>(n));
            for (int q = 0; q < n; ++q) {
              int gx = 0, gy = 0;
              prewitt_at(p + (q + 1) * dj, step, &gx, &gy);
              const int gj = along_rows ? gx : gy, gi = along_rows ? gy : gx;
              ASSERT_EQ(s.g_j[static_cast<size_t>(q)], gj)
                  << image << " " << along_rows << " " << n;
              ASSERT_EQ(s.g_i[static_cast<size_t>(q)], gi)
                  << image << " " << along_rows << " " << n;
              const bool strong = gx * gx + gy * gy >= thr2;
              ASSERT_EQ(s.strong[static_cast<size_t>(q)] != 0, strong) << q << " thr2 " << thr2;
              strong_seen += strong;
              ++checked;
            }
          }
        }
      }
    }
  }
  EXPECT_EQ(checked, 3 * 2 * 2 * 7 * (70 * 71 / 2));
  EXPECT_GT(strong_seen, checked / 4);
}

TEST(VisionClassify, FourDirectionsAndTolerance) {
  const double up = -kPi / 2;  // page up = image up
  const double tol = deg_to_rad(20);
  EXPECT_EQ(classify_gradient(0, -100, up, tol), EdgeClass::kUp);
  EXPECT_EQ(classify_gradient(100, 0, up, tol), EdgeClass::kRight);
  EXPECT_EQ(classify_gradient(0, 100, up, tol), EdgeClass::kDown);
  EXPECT_EQ(classify_gradient(-100, 0, up, tol), EdgeClass::kLeft);
  EXPECT_EQ(classify_gradient(100, -100, up, tol), EdgeClass::kNone);  // 45 deg: no class
  EXPECT_EQ(classify_gradient(0, 0, up, tol), EdgeClass::kNone);
  // Rotated landmark: up axis at -90 + 30 deg.
  const double up2 = up + deg_to_rad(30);
  EXPECT_EQ(classify_gradient(std::cos(up2), std::sin(up2), up2, tol), EdgeClass::kUp);
  EXPECT_EQ(classify_gradient(std::cos(up2 + kPi), std::sin(up2 + kPi), up2, tol),
            EdgeClass::kDown);
}

// Every edge pixel of each side of a rotated dark square is classified to that side (the square
// is dark, so the gradient points outward; side k's outward normal is up + k * 90 deg).
TEST(VisionClassify, EverySidePointGoesToItsSide) {
  for (double deg : {0.0, 17.0, 38.0, -25.0}) {
    const double a = deg_to_rad(deg);
    const double cx = 60.3, cy = 59.6, half = 35.0;
    const cv::Mat img = draw_square(121, 121, cx, cy, half, a);
    cv::Mat gx, gy;
    prewitt(img, cv::Rect(0, 0, img.cols, img.rows), &gx, &gy);
    const double up = a - kPi / 2;
    int checked = 0;
    for (int k = 0; k < 4; ++k) {
      const double na = up + k * kPi / 2;
      const Vec2 n{std::cos(na), std::sin(na)}, t{-n.y, n.x};
      // Pixels nearest to the side, away from the corners.
      for (double s = -half + 6; s <= half - 6; s += 1.0) {
        const double px = cx + n.x * half + t.x * s, py = cy + n.y * half + t.y * s;
        const int ix = static_cast<int>(std::lround(px)), iy = static_cast<int>(std::lround(py));
        const double g_x = gx.at<std::int16_t>(iy, ix), g_y = gy.at<std::int16_t>(iy, ix);
        ASSERT_GT(std::hypot(g_x, g_y), 100.0);
        EXPECT_EQ(static_cast<int>(classify_gradient(g_x, g_y, up, deg_to_rad(20))), k)
            << "deg " << deg << " side " << k << " s " << s;
        ++checked;
      }
    }
    EXPECT_GT(checked, 200);
  }
}

TEST(VisionLineFit, TlsAndOlsRecoverKnownAngle) {
  std::mt19937_64 rng(3);
  std::normal_distribution<double> noise(0.0, 0.1);
  for (double deg : {0.0, 3.7, 12.0, -30.0, 44.0, 89.0}) {
    const double a = deg_to_rad(deg);
    std::vector<Vec2> pts;
    for (int i = -100; i <= 100; ++i) {
      const double t = i;
      const double off = noise(rng);
      pts.push_back(
          {5 + t * std::cos(a) - off * std::sin(a), -2 + t * std::sin(a) + off * std::cos(a)});
    }
    LineFit f;
    ASSERT_TRUE(fit_line_tls(pts, {}, &f));
    const double got = reduce_angle_90(f.line.angle_rad(), a);
    EXPECT_NEAR(rad_to_deg(got), deg, 0.01) << deg;
    EXPECT_NEAR(f.rms, 0.1, 0.02);
    EXPECT_GT(f.var_angle, 0.0);
    if (std::abs(deg) < 60) {
      double k, b;
      ASSERT_TRUE(fit_line_ols(pts, &k, &b));
      EXPECT_NEAR(rad_to_deg(std::atan(k)), deg, 0.01);  // eq. 6
    }
  }
}

TEST(VisionLineFit, RobustFitIgnoresOutliers) {
  std::vector<Vec2> pts;
  for (int i = 0; i < 200; ++i)
    pts.push_back({static_cast<double>(i), 0.5 * std::sin(i * 0.37) * 0.05});
  // 20 % gross outliers on one side (a scratch or an occluder edge).
  for (int i = 0; i < 50; ++i) pts.push_back({80.0 + i, 20.0});
  std::vector<double> w(pts.size());
  LineFit plain, robust;
  ASSERT_TRUE(fit_line_tls(pts, {}, &plain));
  ASSERT_TRUE(fit_line_robust(pts, 4.685, 0.01, 5, w, &robust));
  EXPECT_GT(std::abs(rad_to_deg(plain.line.angle_rad())), 0.3);
  EXPECT_LT(std::abs(rad_to_deg(reduce_angle_90(robust.line.angle_rad(), 0.0))), 0.01);
  EXPECT_NEAR(robust.line.d / robust.line.ny, 0.0, 0.01);
  for (size_t i = 200; i < pts.size(); ++i) EXPECT_EQ(w[i], 0.0);
}

// The robust fit's extent is the spread of the points it kept (the pose stage drops a line shorter
// than half the inner side by it), for every iteration count: only the final fit computes it.
TEST(VisionLineFit, RobustExtentIsTheSpreadOfTheKeptPoints) {
  std::vector<Vec2> pts;
  for (int i = 0; i < 120; ++i) pts.push_back({0.5 * i, 0.02 * std::sin(i * 0.9)});
  for (int i = 0; i < 30; ++i) pts.push_back({100.0 + i, 8.0});  // outliers beyond the line's end
  std::vector<double> w(pts.size());
  for (int iterations : {0, 1, 4}) {
    for (int ransac : {0, 24}) {
      LineFit f, check;
      ASSERT_TRUE(fit_line_robust(pts, 4.685, 0.01, iterations, w, &f, ransac, 0.5));
      ASSERT_TRUE(fit_line_tls(pts, w, &check));
      EXPECT_EQ(f.extent, check.extent) << iterations << " " << ransac;
      if (ransac > 0) {
        EXPECT_NEAR(f.extent, 59.5, 0.1) << iterations << " " << ransac;
      }
    }
  }
}

// The robust fit skips the median selection when more than half of the residuals are at the scale
// floor. Against the plain IRLS (sorted median every iteration), bit for bit: lines whose noise
// puts the median below, at and above the floor, with few points (so that exactly half at the
// floor, the boundary, occurs) and with many.
TEST(VisionLineFit, RobustScaleFloorShortcutEqualsTheSortedMedian) {
  const double tukey_c = 4.685, min_sigma = 0.02;
  const auto reference = [&](const std::vector<Vec2>& pts, int iterations, std::vector<double>* w,
                             LineFit* out) {
    w->assign(pts.size(), 1.0);
    LineFit f;
    if (!fit_line_tls(pts, *w, &f)) return false;
    for (int it = 0; it < iterations; ++it) {
      std::vector<double> r(pts.size()), kept;
      for (size_t i = 0; i < pts.size(); ++i) {
        r[i] = std::abs(f.line.nx * pts[i].x + f.line.ny * pts[i].y - f.line.d);
        if ((*w)[i] > 0) kept.push_back(r[i]);
      }
      if (kept.empty()) return false;
      std::sort(kept.begin(), kept.end());
      const double sigma = std::max(min_sigma, 1.4826 * kept[kept.size() / 2]);
      for (size_t i = 0; i < pts.size(); ++i) {
        const double u = r[i] / (tukey_c * sigma);
        (*w)[i] = u < 1.0 ? (1.0 - u * u) * (1.0 - u * u) : 0.0;
      }
      if (!fit_line_tls(pts, *w, &f)) return false;
    }
    *out = f;
    return true;
  };
  std::mt19937_64 rng(5);
  std::uniform_real_distribution<double> uni(-1.0, 1.0);
  int floored = 0, selected = 0;
  for (int trial = 0; trial < 3000; ++trial) {
    const size_t n = trial % 3 == 0 ? 60 : 3 + trial % 9;
    // Noise amplitudes around the floor's median residual (0.02 / 1.4826 = 0.0135).
    const double amp = 0.005 + 0.04 * (trial % 17) / 16.0;
    const double a = uni(rng), b = 10.0 * uni(rng);
    std::vector<Vec2> pts;
    for (size_t i = 0; i < n; ++i) {
      const double x = static_cast<double>(i) + 0.3 * uni(rng);
      pts.push_back({x, a * x + b + amp * uni(rng)});
    }
    for (int iterations : {1, 4}) {
      std::vector<double> w(n), w_ref;
      LineFit f, ref;
      const bool ok = fit_line_robust(pts, tukey_c, min_sigma, iterations, w, &f);
      ASSERT_EQ(ok, reference(pts, iterations, &w_ref, &ref)) << trial;
      if (!ok) continue;
      ASSERT_EQ(w, w_ref) << trial << " " << iterations;
      EXPECT_EQ(f.line.nx, ref.line.nx) << trial;
      EXPECT_EQ(f.line.ny, ref.line.ny) << trial;
      EXPECT_EQ(f.line.d, ref.line.d) << trial;
      EXPECT_EQ(f.rms, ref.rms) << trial;
      EXPECT_EQ(f.extent, ref.extent) << trial;
      // Both branches ran: count the fits whose final scale was the floor.
      std::vector<double> r;
      for (const Vec2& p : pts)
        r.push_back(std::abs(ref.line.nx * p.x + ref.line.ny * p.y - ref.line.d));
      std::sort(r.begin(), r.end());
      (1.4826 * r[r.size() / 2] <= min_sigma ? floored : selected) += 1;
    }
  }
  EXPECT_GT(floored, 500);
  EXPECT_GT(selected, 500);
}

TEST(VisionLineFit, DegenerateInputFails) {
  LineFit f;
  std::vector<Vec2> one{{1, 1}};
  EXPECT_FALSE(fit_line_tls(one, {}, &f));
  std::vector<Vec2> same{{1, 1}, {1, 1}, {1, 1}};
  EXPECT_FALSE(fit_line_tls(same, {}, &f));
  double k, b;
  std::vector<Vec2> vertical{{2, 0}, {2, 1}, {2, 5}};
  EXPECT_FALSE(fit_line_ols(vertical, &k, &b));
}

TEST(VisionHeading, Equation7AndPaper000Weights) {
  const std::vector<double> a{0.010, 0.012, 0.008, 0.011};
  EXPECT_NEAR(mean_angle(a), 0.01025, 1e-12);
  // eq. 11: a perfect fit has weight 1; residuals increase the weight above 1.
  EXPECT_DOUBLE_EQ(weight_000(100.0, 0.0), 1.0);
  EXPECT_NEAR(weight_000(100.0, 20.0), 1.25, 1e-12);
  const std::vector<double> k{1.0, 1.0, 1.0, 3.0};
  EXPECT_NEAR(weighted_angle_000(a, k), (0.010 + 0.012 + 0.008 + 3 * 0.011) / 6.0, 1e-12);
  EXPECT_NEAR(reduce_angle_90(deg_to_rad(92.0), 0.0), deg_to_rad(2.0), 1e-12);
  EXPECT_NEAR(reduce_angle_90(deg_to_rad(-178.0), 0.0), deg_to_rad(2.0), 1e-12);
}

// An occluder edge parallel to the border, 5 px outside it, over 45 % of a side: plain IRLS
// starts between the two and keeps a biased line; the RANSAC start locks onto the majority.
TEST(VisionLineFit, RansacStartRejectsParallelOccluderEdge) {
  std::vector<Vec2> pts;
  for (int i = 0; i < 110; ++i) pts.push_back({static_cast<double>(i), 0.03 * std::sin(i * 1.3)});
  for (int i = 110; i < 200; ++i)
    pts.push_back({static_cast<double>(i), 5.0 + 0.03 * std::sin(i * 0.7)});
  std::vector<double> w(pts.size());
  LineFit plain, ransac;
  ASSERT_TRUE(fit_line_robust(pts, 4.685, 0.01, 5, w, &plain));
  ASSERT_TRUE(fit_line_robust(pts, 4.685, 0.01, 5, w, &ransac, 24, 0.5));
  const double off_plain = std::abs(plain.line.d / plain.line.ny - 0.0);
  EXPECT_GT(off_plain + std::abs(rad_to_deg(reduce_angle_90(plain.line.angle_rad(), 0.0))), 0.1);
  EXPECT_NEAR(ransac.line.d / ransac.line.ny, 0.0, 0.01);
  EXPECT_LT(std::abs(rad_to_deg(reduce_angle_90(ransac.line.angle_rad(), 0.0))), 0.01);
  for (size_t i = 110; i < pts.size(); ++i) EXPECT_EQ(w[i], 0.0);
}

// The sampler of the logo and QR loops gives sample()'s value to the last bit, inside, on the
// last row and column, and outside (refused), also on images too small for its fast path and on
// a region of a larger image (row step larger than the width).
TEST(Bilinear, GreySamplerEqualsSampleBitForBit) {
  std::mt19937_64 rng(3);
  cv::Mat big(60, 80, CV_8UC1);
  cv::randu(big, 0, 256);
  const cv::Mat images[] = {big, big(cv::Rect(7, 5, 33, 21)),
                            cv::Mat(1, 9, CV_8UC1, cv::Scalar(77)),
                            cv::Mat(9, 1, CV_8UC1, cv::Scalar(33)), big(cv::Rect(0, 0, 2, 2))};
  int inside = 0;
  for (const cv::Mat& img : images) {
    const agv::vision::GreySampler grey(img);
    std::uniform_real_distribution<double> ux(-1.0, img.cols), uy(-1.0, img.rows);
    std::vector<std::pair<double, double>> pts = {{0, 0},
                                                  {img.cols - 1.0, img.rows - 1.0},
                                                  {img.cols - 1.0, 0},
                                                  {0, img.rows - 1.0},
                                                  {img.cols - 0.9999, 0},
                                                  {-1e-9, 0},
                                                  {std::nan(""), 0}};
    for (int k = 0; k < 2000; ++k) pts.emplace_back(ux(rng), uy(rng));
    for (const auto& [x, y] : pts) {
      double a = -1, b = -1;
      const bool ok_a = agv::vision::sample(img, x, y, &a);
      const bool ok_b = grey(x, y, &b);
      ASSERT_EQ(ok_a, ok_b) << x << ", " << y;
      if (ok_a) {
        ASSERT_EQ(a, b) << x << ", " << y;
        ++inside;
      }
    }
  }
  EXPECT_GT(inside, 3000);  // most points of the three 2-D images
}
