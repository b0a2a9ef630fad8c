// Stage 4 of the pipeline (docs/design/vision.md), logo, and the direction decision that closes
// stage 5: which of the four 90-degree turns of the fitted square is the landmark's forward axis.
// The logo (a filled triangle beside the QR code) is correlated at each turn; the result is
// cross-checked with the QR code's own orientation after the decode stage.
#include <algorithm>
#include <cmath>

#include "direction_stage.hpp"

namespace agv::vision {

namespace {

// Logo sampling window on the page, in units of LandmarkGeometry::k() (1 mm on a 60 mm landmark):
// the triangle spans u -5..5, v -21..-13; the window adds 3 units of white on the sides and 2
// above and below (inside the quiet zone, clear of the QR code and the border), so the template
// has both classes.
constexpr double kLogoWindowU0 = -8.0, kLogoWindowWidthU = 16.0;
constexpr double kLogoWindowV0 = -23.0, kLogoWindowHeightV = 12.0;
// 20 x 16 samples: 0.8 units apart, about 3 pixels at 0.26 mm/px, so every sample sees a
// different pixel neighbourhood and the NCC is over 320 samples.
constexpr int kLogoSamplesU = 20, kLogoSamplesV = 16;

bool in_triangle(Vec2 apex, Vec2 bl, Vec2 br, Vec2 p) {
  auto cross = [](Vec2 a, Vec2 b, Vec2 c) {
    return (b.x - a.x) * (c.y - a.y) - (b.y - a.y) * (c.x - a.x);
  };
  const double d1 = cross(apex, bl, p), d2 = cross(bl, br, p), d3 = cross(br, apex, p);
  const bool neg = d1 < 0 || d2 < 0 || d3<0, pos = d1> 0 || d2 > 0 || d3 > 0;
  return !(neg && pos);
}

}  // namespace

DirectionStage::DirectionStage(const VisionSetup& s) : setup(s) { build_logo(); }

// Logo template: samples on the page around the triangle, 1 = white, 0 = inside the triangle.
void DirectionStage::build_logo() {
  const double k = setup.geom.k();
  const Vec2 apex = setup.geom.logo_apex_uv_mm(), bl = setup.geom.logo_base_left_uv_mm(),
             br = setup.geom.logo_base_right_uv_mm();
  logo_page_pts.clear();
  logo_template.clear();
  for (int j = 0; j < kLogoSamplesV; ++j) {
    for (int i = 0; i < kLogoSamplesU; ++i) {
      const Vec2 p{(kLogoWindowU0 + kLogoWindowWidthU * (i + 0.5) / kLogoSamplesU) * k,
                   (kLogoWindowV0 + kLogoWindowHeightV * (j + 0.5) / kLogoSamplesV) * k};
      logo_page_pts.push_back(p);
      logo_template.push_back(in_triangle(apex, bl, br, p) ? 0.0 : 1.0);
    }
  }
}

// Logo NCC at turn q of the fitted square (turn q's forward axis is side q's normal); -1 where
// the logo leaves the image.
double DirectionStage::logo_ncc(const cv::Mat& img, Vec2 c_mm, double beta, int q) {
  const GreySampler grey(img);
  const PlaneProjector page = setup.page_projector(c_mm, beta - q * kPi / 2.0);
  logo_samples.clear();
  for (const Vec2& uv : logo_page_pts) {
    Vec2 px;
    double val = 0;
    if (!page.to_pixel(uv, &px) || !grey(px.x, px.y, &val)) return -1.0;
    logo_samples.push_back(val);
  }
  return ncc(logo_samples, logo_template);
}

// Logo NCC at the four turns.
LogoScores DirectionStage::logo_scores(const cv::Mat& img, Vec2 c_mm, double beta) {
  LogoScores r;
  for (int q = 0; q < 4; ++q) r.ncc[static_cast<size_t>(q)] = logo_ncc(img, c_mm, beta, q);
  for (int q = 1; q < 4; ++q) {
    if (r.ncc[static_cast<size_t>(q)] > r.ncc[static_cast<size_t>(r.best_q)]) r.best_q = q;
  }
  double second = -1.0;
  for (int q = 0; q < 4; ++q) {
    if (q != r.best_q) second = std::max(second, r.ncc[static_cast<size_t>(q)]);
  }
  r.best = r.ncc[static_cast<size_t>(r.best_q)];
  r.margin = r.best - second;
  r.clear = r.best >= setup.cfg.logo_threshold && r.margin >= setup.cfg.logo_margin;
  return r;
}

// The final turn, or -1 (kDirectionAmbiguous): a clear logo must agree with the QR orientation
// when the code gave one; an unreadable logo (below threshold, not merely without margin) defers
// to the QR orientation when the configuration allows it.
int DirectionStage::decide_direction(const LogoScores& logo, int qr_q) const {
  if (logo.clear) return qr_q >= 0 && qr_q != logo.best_q ? -1 : logo.best_q;
  if (setup.cfg.direction_from_qr_when_logo_weak && qr_q >= 0 &&
      logo.best < setup.cfg.logo_threshold) {
    return qr_q;
  }
  return -1;
}

}  // namespace agv::vision
