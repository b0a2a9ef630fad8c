// Tracked detection (docs/design/tracking.md "Tracked detection"): when the
// prediction is trusted, the landmark's hypothesis comes from the predicted
// centre and border angle instead of the corner template search over every dark
// pixel. Only the four outer corners are searched, each with the one fine
// template at its predicted rotation and within window_sigmas of its predicted
// position; then the full path's angle and centre refinement and ring check
// decide. Anything doubtful returns false and locate() falls back to the
// windowed search, then the full frame.
#include <algorithm>
#include <cmath>
#include <opencv2/imgproc.hpp>

#include "agv/vision/coarse_level.hpp"
#include "corner_detector.hpp"

namespace agv::vision {

namespace {

// The corner grid is searched at every second coarse pixel: the NCC peak of a
// corner template is as wide as the border (2.5+ coarse px), so a grid point
// lies within one pixel of it and the re-match of refine_hypothesis (+-2 px,
// subpixel) then finds the maximum.
constexpr int kGridStepPx = 2;
// Two corners fix centre and angle; a single one (landmark cut by the image
// border, or covered) is left to the full search, which has the context of
// every other corner peak.
constexpr int kMinTrackedCorners = 2;
// The orientation field is computed this far (coarse px) beyond what the angle
// refinement reads around the first centre estimate: the re-match moves the
// centre by at most 2 px per pass.
constexpr int kOrientGuardPx = 4;

}  // namespace

// Detection on the bounding box of the windows, aligned to the coarse grid so
// its coarse pixels are the full frame's (the windows' margin keeps the
// binarization block inside): the same hypothesis as the full search, shifted
// back into frame coordinates.
bool CornerDetector::detect_in_windows(const cv::Mat& img, const std::vector<SearchWindow>& windows,
                                       Detection* best, bool* found_corner, double* corner_score,
                                       bool* whole_frame) {
  int x0 = img.cols, y0 = img.rows, x1 = 0, y1 = 0;
  for (const SearchWindow& w : windows) {
    x0 = std::min(x0, w.x0);
    y0 = std::min(y0, w.y0);
    x1 = std::max(x1, w.x1);
    y1 = std::max(y1, w.y1);
  }
  const int f = setup.coarse_factor;
  x0 = x0 / f * f;
  y0 = y0 / f * f;
  // The full search covers only whole coarse pixels (make_coarse): so does the
  // window.
  x1 = std::min((x1 + f - 1) / f * f, img.cols / f * f);
  y1 = std::min((y1 + f - 1) / f * f, img.rows / f * f);
  *whole_frame = false;
  if (x1 <= x0 || y1 <= y0) return false;
  *whole_frame = x0 == 0 && y0 == 0 && x1 == img.cols / f * f && y1 == img.rows / f * f;
  const cv::Mat roi = img(cv::Rect(x0, y0, x1 - x0, y1 - y0));
  if (!detect(roi, best, found_corner, corner_score)) return false;
  best->h.cx += x0 / f;
  best->h.cy += y0 / f;
  return true;
}

bool CornerDetector::detect_tracked(const cv::Mat& img, const std::vector<SearchWindow>& windows,
                                    Detection* best, double* corner_score) {
  int best_dark = 0;
  for (const SearchWindow& w : windows) {
    Detection d;
    double score = 0.0;
    int n_dark = 0;
    // Several landmarks in view: the one with the most dark ring samples, as
    // the full search.
    if (detect_tracked_in(img, w, &d, &score, &n_dark) && n_dark > best_dark) {
      best_dark = n_dark;
      *best = d;
      *corner_score = score;
    }
  }
  return best_dark > 0;
}

// 1. Each outer corner: the fine template at its predicted rotation on a grid
// around its predicted position (pcx, pcy, coarse px of the window), within
// radius, gated like the full search (template anchor dark in the binary
// image). Fills peaks.
void CornerDetector::tracked_corner_peaks(const SearchWindow& w, double pcx, double pcy,
                                          int radius) {
  const int tsz = templates[0].cols, r = tsz / 2;
  const int n_rot = static_cast<int>(template_angles.size());
  peaks.clear();
  for (int k = 0; k < 4; ++k) {
    const double a = w.up_angle_rad + kPi / 2.0 + k * kPi / 2.0;
    const Vec2 d =
        rot({setup.coarse_h - setup.coarse_anchor, setup.coarse_h - setup.coarse_anchor}, a);
    const int deg = static_cast<int>(std::lround(rad_to_deg(a))) % 360;
    const std::vector<float>& tz = fine_templates[static_cast<size_t>(deg < 0 ? deg + 360 : deg)];
    const int qx = static_cast<int>(std::lround(pcx - d.x));
    const int qy = static_cast<int>(std::lround(pcy - d.y));
    CornerPeak p;
    p.score = -1.0;
    for (int y = qy - radius; y <= qy + radius; y += kGridStepPx) {
      if (y < r || y + r >= coarse.rows) continue;
      const std::uint8_t* brow = binary.ptr<std::uint8_t>(y);
      for (int x = qx - radius; x <= qx + radius; x += kGridStepPx) {
        if (x < r || x + r >= coarse.cols || !brow[x]) continue;
        const double s = ncc_at(tz, tsz, x - r, y - r);
        if (s > p.score) {
          p.score = s;
          p.x = x;
          p.y = y;
        }
      }
    }
    if (p.score < setup.cfg.corner_threshold) continue;
    // The nearest 30-degree template: refine_hypothesis snaps its angle to the
    // refined square angle, which gives back this corner's rotation (the
    // templates are < 45 degrees apart).
    const double turns = a / (2.0 * kPi) * n_rot;
    p.rot = static_cast<int>(std::lround(turns)) % n_rot;
    if (p.rot < 0) p.rot += n_rot;
    peaks.push_back(p);
  }
}

// 2. The corners' centre votes: the largest agreeing group becomes the
// hypothesis; false when it has fewer than kMinTrackedCorners.
bool CornerDetector::tracked_hypothesis(const SearchWindow& w, Hypothesis* out) {
  const size_t n = peaks.size();
  std::array<Vec2, 4> votes{};
  for (size_t i = 0; i < n; ++i) {
    const double a = template_angles[static_cast<size_t>(peaks[i].rot)];
    const double a_k = reduce_angle_90(w.up_angle_rad + kPi / 2.0, a);
    const Vec2 d =
        rot({setup.coarse_h - setup.coarse_anchor, setup.coarse_h - setup.coarse_anchor}, a_k);
    votes[i] = {peaks[i].x + d.x, peaks[i].y + d.y};
  }
  const double agree = kMergeDistanceBorderWidths * setup.coarse_w;
  int best_i = -1, best_count = 0;
  for (size_t i = 0; i < n; ++i) {
    int count = 0;
    for (size_t j = 0; j < n; ++j) {
      if (std::hypot(votes[i].x - votes[j].x, votes[i].y - votes[j].y) < agree) ++count;
    }
    if (count > best_count) {
      best_count = count;
      best_i = static_cast<int>(i);
    }
  }
  if (best_count < kMinTrackedCorners) return false;
  Hypothesis& h = *out;
  h.up_angle = w.up_angle_rad;
  for (size_t j = 0; j < n; ++j) {
    const Vec2& v = votes[j];
    if (std::hypot(votes[best_i].x - v.x, votes[best_i].y - v.y) >= agree) continue;
    const double s = peaks[j].score;
    h.cx = (h.cx * h.sum_w + v.x * s) / (h.sum_w + s);
    h.cy = (h.cy * h.sum_w + v.y * s) / (h.sum_w + s);
    h.sum_w += s;
    h.score_sum += s;
    h.score_max = std::max(h.score_max, s);
    h.peak_idx[static_cast<size_t>(h.n_peaks++)] = static_cast<int>(j);
  }
  return true;
}

bool CornerDetector::detect_tracked_in(const cv::Mat& img, const SearchWindow& w, Detection* best,
                                       double* corner_score, int* n_dark) {
  if (!std::isfinite(w.centre_px.x) || !std::isfinite(w.centre_px.y) ||
      !std::isfinite(w.up_angle_rad) || !std::isfinite(w.corner_sigma_px)) {
    return false;
  }
  // The window, aligned to the coarse grid as detect_in_windows does: its
  // coarse pixels are the full frame's, and its margin keeps the adaptive
  // threshold's block inside.
  const int f = setup.coarse_factor;
  const int x0 = w.x0 / f * f, y0 = w.y0 / f * f;
  const int x1 = std::min((w.x1 + f - 1) / f * f, img.cols / f * f);
  const int y1 = std::min((w.y1 + f - 1) / f * f, img.rows / f * f);
  if (x1 <= x0 || y1 <= y0) return false;
  if (!make_coarse(img(cv::Rect(x0, y0, x1 - x0, y1 - y0)))) return false;
  integral_sum_sq(coarse, &isum, &isq);
  coarse.convertTo(coarse_f, CV_32F);

  const double ox = x0 / f, oy = y0 / f;
  const double pcx = (w.centre_px.x + 0.5) / f - 0.5 - ox;
  const double pcy = (w.centre_px.y + 0.5) / f - 0.5 - oy;
  const double reach_px = setup.cfg.tracking.window_sigmas * w.corner_sigma_px / f;
  const int radius = static_cast<int>(std::ceil(reach_px)) + 1;
  tracked_corner_peaks(w, pcx, pcy, radius);
  Hypothesis h;
  if (!tracked_hypothesis(w, &h)) return false;
  const double agree = kMergeDistanceBorderWidths * setup.coarse_w;

  // 3. The full path's refinement (angle from the gradients, centre from the
  // re-matched corners) and ring check. The orientation field is needed only
  // where the refinement reads.
  const int reach = static_cast<int>(setup.coarse_h + 1.0) + 1 + kOrientGuardPx;
  compute_orient4_in(static_cast<int>(h.cx) - reach, static_cast<int>(h.cy) - reach,
                     static_cast<int>(h.cx) + reach, static_cast<int>(h.cy) + reach);
  refine_hypothesis(&h);
  const double angle_tol =
      setup.cfg.tracking.window_sigmas * w.up_angle_sigma_rad + deg_to_rad(kTrackedAngleSlackDeg);
  if (std::abs(reduce_angle_90(h.up_angle, w.up_angle_rad) - w.up_angle_rad) > angle_tol) {
    return false;
  }
  if (std::hypot(h.cx - pcx, h.cy - pcy) > reach_px + agree) return false;
  double dark = 0, white = 0;
  if (!ring_check(h, &dark, &white, n_dark)) return false;
  h.cx += ox;
  h.cy += oy;
  best->h = h;
  best->dark_grey = dark;
  best->white_grey = white;
  *corner_score = h.score_max;
  return true;
}

}  // namespace agv::vision
