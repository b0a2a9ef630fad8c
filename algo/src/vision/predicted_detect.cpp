// Detection from a precise prediction (docs/design/tracking.md "Detection from the prediction").
// The pose stage only needs the landmark's centre and border angle to place its edge bands, which
// are
// +-band_rel border widths wide (+-2.4 mm at the defaults); the tracked detection's own estimate
// is up to 6.45 px (1.7 mm) off and the edge fit recovers from it. When the prediction already
// puts every outer corner well inside the band, the coarse level, the corner search and the
// refinement are skipped: the prediction places the bands. What the detection also gave is kept:
// the ring check (a dark border on light paper, not a dark patch of floor), sampled on the full
// image around the predicted square, and its grey levels, whose difference scales the edge
// threshold. locate() then requires the fitted centre to lie where the prediction said, and falls
// back to the tracked detection when anything here or there declines.
#include <algorithm>
#include <cmath>

#include "predicted_detector.hpp"

namespace agv::vision {

namespace {

// The prediction replaces the detection when window_sigmas times its corner sigma is at most this
// share of the edge band's half width: the edges then lie inside the bands with room for the edge
// blur and the non-maximum suppression's neighbours. 0.5 at the defaults: 4 sigma within 4.6 px,
// a corner sigma up to 0.3 mm at 0.26 mm/px. Larger takes looser predictions and moves more edge
// points to the bands' ends.
constexpr double kPredictedBandShare = 0.5;
// Ring samples per pixel of side length (full image): about 90 a side at 0.26 mm/px (the coarse
// check takes about 23), 4 a side at least, as the coarse ring check.
constexpr double kRingSamplesPerPx = 0.5;
constexpr int kMinRingSamplesPerSide = 4;

}  // namespace

bool PredictedDetector::prediction_places_bands(const SearchWindow& w) const {
  const double band_px = setup.cfg.band_rel * setup.geom.border_width_mm() / setup.mm_per_px;
  return std::isfinite(w.centre_px.x) && std::isfinite(w.centre_px.y) &&
         std::isfinite(w.up_angle_rad) && std::isfinite(w.corner_sigma_px) &&
         setup.cfg.tracking.window_sigmas * w.corner_sigma_px <= kPredictedBandShare * band_px;
}

bool PredictedDetector::detect_predicted(const cv::Mat& img,
                                         const std::vector<SearchWindow>& windows, Detection* best,
                                         Vec2* predicted_px, bool* probed) {
  // Several landmarks in view: the one with the largest share of dark ring samples, or of probes
  // on the border's lines.
  double best_share = 0.0;
  for (const SearchWindow& w : windows) {
    ProbedSquare sq;
    bool from_probes = false;
    if (prediction_places_bands(w)) {
      // A landmark cut by the image border keeps the detection, which weighs its corners.
      if (setup.partly_outside(img, w.centre_px, w.up_angle_rad)) continue;
      int n_dark = 0, n_samples = 0;
      sq.centre_px = w.centre_px;
      sq.up_rad = w.up_angle_rad;
      if (!ring_check_full(img, w.centre_px, w.up_angle_rad, &sq.dark_grey, &sq.white_grey, &n_dark,
                           &n_samples)) {
        continue;
      }
      sq.on_line_share = static_cast<double>(n_dark) / n_samples;
    } else {
      // Too loose to place the bands itself: the edge probes may make it precise. They check
      // more than the ring check (a dark run of the border's width between light on either
      // side, on four lines of the landmark's size) and give its grey levels.
      if (!setup.cfg.tracking.probe_edges || !probe_prediction(img, w, &sq) ||
          setup.partly_outside(img, sq.centre_px, sq.up_rad)) {
        continue;
      }
      from_probes = true;
    }
    if (sq.on_line_share <= best_share) continue;
    best_share = sq.on_line_share;
    best->h = Hypothesis{};
    const Vec2 cc = setup.full_to_coarse(sq.centre_px);
    best->h.cx = cc.x;
    best->h.cy = cc.y;
    best->h.up_angle = sq.up_rad;
    best->dark_grey = sq.dark_grey;
    best->white_grey = sq.white_grey;
    *predicted_px = sq.centre_px;
    *probed = from_probes;
  }
  return best_share > 0.0;
}

// ring_check on the full image: the middle of the border and a ring outside it, split at the
// midpoint of their mean grey levels (the coarse check's adaptive binary image is not computed
// here), with the same acceptance (ring_accepted).
bool PredictedDetector::ring_check_full(const cv::Mat& img, Vec2 c, double up, double* dark_level,
                                        double* white_level, int* n_dark, int* n_samples) {
  const double w_px = setup.geom.border_width_mm() / setup.mm_per_px;
  const double h_px = setup.geom.outer_half_mm() / setup.mm_per_px;
  const double len = h_px - w_px;
  const int n = std::max(kMinRingSamplesPerSide, static_cast<int>(kRingSamplesPerPx * 2 * len));
  ring_grey.clear();
  outside_grey.clear();
  int total = 0;
  auto grey_at = [&](double x, double y, std::vector<int>* dst) {
    const int ix = static_cast<int>(std::lround(x)), iy = static_cast<int>(std::lround(y));
    if (ix >= 0 && iy >= 0 && ix < img.cols && iy < img.rows) {
      dst->push_back(img.at<std::uint8_t>(iy, ix));
    }
  };
  for (int k = 0; k < 4; ++k) {
    const double a = up + k * kPi / 2.0;
    const Vec2 nrm{std::cos(a), std::sin(a)}, tan{-nrm.y, nrm.x};
    const double r_mid = h_px - w_px / 2, r_out = h_px + kOutsideRingBorderWidths * w_px;
    for (int i = 0; i <= n; ++i) {
      const double t = -len + 2.0 * len * i / n;
      ++total;
      grey_at(c.x + nrm.x * r_mid + tan.x * t, c.y + nrm.y * r_mid + tan.y * t, &ring_grey);
      grey_at(c.x + nrm.x * r_out + tan.x * t, c.y + nrm.y * r_out + tan.y * t, &outside_grey);
    }
  }
  const int ring_in = static_cast<int>(ring_grey.size());
  const int out_in = static_cast<int>(outside_grey.size());
  if (ring_in == 0) return false;
  double ring_sum = 0, out_sum = 0;
  for (int v : ring_grey) ring_sum += v;
  for (int v : outside_grey) out_sum += v;
  const double mid = out_in > 0 ? 0.5 * (ring_sum / ring_in + out_sum / out_in) : kWhiteGrey / 2;
  int ring_dark = 0, out_dark = 0;
  double dark_sum = 0, white_sum = 0;
  for (int v : ring_grey) {
    if (v < mid) {
      ++ring_dark;
      dark_sum += v;
    }
  }
  for (int v : outside_grey) {
    if (v < mid) {
      ++out_dark;
    } else {
      white_sum += v;
    }
  }
  if (!setup.ring_accepted(total, ring_in, ring_dark, out_in, out_dark)) return false;
  *dark_level = dark_sum / ring_dark;
  *white_level = out_in > out_dark ? white_sum / (out_in - out_dark) : kWhiteGrey;
  *n_dark = ring_dark;
  *n_samples = total;
  return true;
}

// The fitted centre (keep_overlay_geometry's centre_px) where the prediction put it: within the
// share of the band the prediction was admitted with. A fit further away found other edges than
// the predicted landmark's, or the prediction was wrong after all.
bool PredictedDetector::fit_agrees_with_prediction(Vec2 predicted_px) const {
  const double band_px = setup.cfg.band_rel * setup.geom.border_width_mm() / setup.mm_per_px;
  return std::hypot(square_fit.pixels().centre_px.x - predicted_px.x,
                    square_fit.pixels().centre_px.y - predicted_px.y) <=
         kPredictedBandShare * band_px;
}

}  // namespace agv::vision
