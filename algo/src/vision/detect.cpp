// Stages 1-2 of the pipeline (docs/design/vision.md), binarization and detection: coarse pyramid
// level, adaptive binarization, rotated corner templates (NCC), corner peaks merged into landmark
// hypotheses, angle and centre refinement, border ring check. Li et al. section 3.1 with the
// changes measured in docs/design/accuracy.md.
#include <algorithm>
#include <cmath>
#include <cstring>
#include <opencv2/imgproc.hpp>

#include "agv/vision/coarse_level.hpp"
#include "corner_detector.hpp"

namespace agv::vision {

namespace {

// Corner templates are rendered with this many sub-samples per coarse pixel and axis: enough
// that the area-weighted edge pixels are exact to 1/64 grey step of the template's range.
constexpr int kTemplateSupersample = 8;
// Template half size in border widths: the corner's dark square (1 border width) plus half a
// border width of white on each side, so the template sees both edges of both sides.
constexpr double kTemplateRadiusBorderWidths = 1.5;
// Fine templates for the local re-match, one per whole degree.
constexpr int kFineTemplateSteps = 360;
// cv::adaptiveThreshold needs an odd block of at least 3 pixels.
constexpr int kMinAdaptiveBlockPx = 3;
// Grey-level standard deviation a coarse patch must have to be scored: NCC ignores contrast, and
// faint floor texture normalised to unit variance can look like a corner. The printed border is
// 100+ grey levels darker than the paper; 12 keeps blurred, dim landmarks.
constexpr double kMinCornerPatchSigmaGrey = 12.0;
// Two corner peaks belong to the same landmark when their predicted centres are closer than
// kMergeDistanceBorderWidths (stage_common.hpp) and their square angles agree within this (the
// 30-degree templates are at most 15 degrees off each).
constexpr double kMergeAngleTolDeg = 25.0;
// Angle refinement from the gradients and centre re-match, alternated at most this many times:
// the second pass catches a whole-degree change of the angle; a third never changed the result.
constexpr int kRefinePasses = 2;
// Local re-match window: +-2 coarse pixels around the peak covers the shift between a 30-degree
// template and the true rotation; the score array has one more guard cell on each side.
constexpr int kRematchRadiusPx = 2;
constexpr int kRematchGrid = 2 * kRematchRadiusPx + 3;
constexpr int kRematchCentre = kRematchGrid / 2;
// A re-matched corner with a poor (or negative) score still votes a little, so a hypothesis with
// only weak corners keeps its centre estimate instead of none.
constexpr double kMinRematchWeight = 0.05;
// The local re-match skips windows with a grey-level variance up to this (grey levels^2): a flat
// window has no corner and its NCC would divide by ~0.
constexpr double kMinRematchWindowVar = 1.0;
// Gradients below this squared Prewitt magnitude (grey levels^2) carry no orientation.
constexpr double kMinOrientGradient2 = 1.0;
// The angle refinement looks at pixels up to this far (coarse px) beyond the predicted outer
// border, so the outer edge's gradients are inside even when the centre is a pixel off.
constexpr double kRefineReachMarginPx = 1.0;
// Ring check: at least this many samples per side, two per coarse pixel of side length.
constexpr int kMinRingSamplesPerSide = 4;
constexpr double kRingSamplesPerPx = 2.0;

// Dot products of one coarse patch (row pointer, stride) with every corner template at once.
// Templates are stored pixel-major with `Lanes` slots per pixel, so one pixel value multiplies
// Lanes / 4 vectors of four templates (GCC/Clang vector extensions: SSE on x86-64, NEON on
// aarch64; the auto-vectoriser interleaved this loop badly at 16 lanes). 12 lanes hold the
// default 12 rotations exactly (no multiply of padding: a fifth fewer instructions than 16 lanes
// per pixel on aarch64; the dot products of the real templates are the same), 16 and 32 the rest.
template <int Lanes>
int best_template(const float* patch, size_t stride, int tsz, const float* tp, int n_t,
                  float* best_dot) {
  typedef float V4 __attribute__((vector_size(16)));
  constexpr int kV = Lanes / 4;
  V4 acc[kV];
  for (int k = 0; k < kV; ++k) acc[k] = V4{0, 0, 0, 0};
  for (int j = 0; j < tsz; ++j) {
    const float* row = patch + static_cast<size_t>(j) * stride;
    for (int i = 0; i < tsz; ++i) {
      const float v = row[i];
      const V4 vv{v, v, v, v};
      const float* tq = tp + static_cast<size_t>(j * tsz + i) * Lanes;
      for (int k = 0; k < kV; ++k) {
        V4 t;
        std::memcpy(&t, tq + 4 * k, sizeof t);
        acc[k] += t * vv;
      }
    }
  }
  float out[Lanes];
  std::memcpy(out, acc, sizeof out);
  int best_i = 0;
  for (int t = 1; t < n_t; ++t) {
    if (out[t] > out[best_i]) best_i = t;
  }
  *best_dot = out[best_i];
  return best_i;
}

std::vector<float> zero_mean_unit(const cv::Mat& t) {
  cv::Scalar mean = cv::mean(t);
  std::vector<float> zm(static_cast<size_t>(t.total()));
  double norm = 0;
  for (size_t q = 0; q < zm.size(); ++q) {
    zm[q] = static_cast<float>(static_cast<double>(t.at<float>(static_cast<int>(q))) - mean[0]);
    norm += static_cast<double>(zm[q]) * static_cast<double>(zm[q]);
  }
  for (float& v : zm) v = static_cast<float>(static_cast<double>(v) / std::sqrt(norm));
  return zm;
}

// Parabolic subpixel offset of a maximum from its two neighbours, within half a pixel.
double parabola_offset(double lo, double centre, double hi) {
  const double d2 = lo - 2.0 * centre + hi;
  return d2 < 0 ? std::clamp(0.5 * (lo - hi) / d2, -0.5, 0.5) : 0.0;
}

}  // namespace

// Corner template: the top-left outer corner of the border (square towards +x, +y), rendered
// by supersampling and rotated by image angle a about its anchor (middle of the corner's dark
// square), into t (CV_32F, (2r+1)^2).
void CornerDetector::render_corner(double a, int r, cv::Mat* t) const {
  constexpr int kS = kTemplateSupersample;
  t->create(2 * r + 1, 2 * r + 1, CV_32FC1);
  const double ca = std::cos(a), sa = std::sin(a);
  for (int y = -r; y <= r; ++y) {
    for (int x = -r; x <= r; ++x) {
      double acc = 0;
      for (int sy = 0; sy < kS; ++sy) {
        for (int sx = 0; sx < kS; ++sx) {
          const Vec2 q{x + (sx + 0.5) / kS - 0.5, y + (sy + 0.5) / kS - 0.5};
          const Vec2 u{ca * q.x + sa * q.y, -sa * q.x + ca * q.y};  // rotate by -a
          const double px = u.x + setup.coarse_anchor, py = u.y + setup.coarse_anchor;
          const bool inside = px >= 0 && py >= 0;
          const bool dark = inside && (px < setup.coarse_w || py < setup.coarse_w);
          acc += dark ? 0.0 : 1.0;
        }
      }
      t->at<float>(y + r, x + r) = static_cast<float>(acc / (kS * kS));
    }
  }
}

CornerDetector::CornerDetector(const VisionSetup& s) : setup(s) { build_templates(); }

void CornerDetector::build_templates() {
  const int r = static_cast<int>(std::ceil(kTemplateRadiusBorderWidths * setup.coarse_w));
  const int n_rot = std::clamp(setup.cfg.corner_rotations, 1, kMaxTemplates);
  templates.clear();
  templates_zm.clear();
  template_angles.clear();
  for (int i = 0; i < n_rot; ++i) {
    const double a = 2.0 * kPi * i / n_rot;
    cv::Mat t;
    render_corner(a, r, &t);
    templates_zm.push_back(zero_mean_unit(t));
    templates.push_back(t);
    template_angles.push_back(a);
  }
  // Transposed, padded to a fixed number of lanes (zeros) so the NCC inner loop has a fixed
  // trip count and vectorises.
  const size_t n_pix = templates_zm[0].size(), n_t = templates_zm.size();
  template_lanes = n_t <= 12 ? 12 : n_t <= 16 ? 16 : kMaxTemplates;
  const size_t lanes = static_cast<size_t>(template_lanes);
  templates_t.assign(n_pix * lanes, 0.0f);
  for (size_t t = 0; t < n_t; ++t) {
    for (size_t q = 0; q < n_pix; ++q) templates_t[q * lanes + t] = templates_zm[t][q];
  }
  fine_templates.clear();
  for (int deg = 0; deg < kFineTemplateSteps; ++deg) {
    cv::Mat t;
    render_corner(deg_to_rad(deg), r, &t);
    fine_templates.push_back(zero_mean_unit(t));
  }
}

// NCC of a zero-mean unit template at coarse position (x, y) (top-left of the window); -1 when
// the window leaves the image or has no contrast. Window sums come from the integral images.
double CornerDetector::ncc_at(const std::vector<float>& tz, int tsz, int x, int y) const {
  if (x < 0 || y < 0 || x + tsz > coarse.cols || y + tsz > coarse.rows) return -1.0;
  double sum = 0.0, sq = 0.0;
  window_sum_sq(isum, isq, x, y, tsz, &sum, &sq);
  const double n = tsz * tsz;
  const double var = sq / n - (sum / n) * (sum / n);
  if (!(var > kMinRematchWindowVar)) return -1.0;
  float dot = 0.0f;
  const float* t = tz.data();
  for (int j = 0; j < tsz; ++j) {
    const float* row = coarse_f.ptr<float>(y + j) + x;
    for (int i = 0; i < tsz; ++i) dot += t[j * tsz + i] * row[i];
  }
  return static_cast<double>(dot) / std::sqrt(var * n);
}

bool CornerDetector::detect(const cv::Mat& img, Detection* best, bool* found_corner,
                            double* corner_score) {
  *found_corner = false;
  *corner_score = 0.0;
  // 1. Pyramid and binarization.
  if (!make_coarse(img)) return false;
  // 2a. Corner templates at every candidate position, local maxima.
  score_corner_templates();
  find_corner_peaks();
  if (peaks.empty()) return false;
  *found_corner = true;
  std::sort(peaks.begin(), peaks.end(),
            [](const CornerPeak& a, const CornerPeak& b) { return a.score > b.score; });
  if (static_cast<int>(peaks.size()) > setup.cfg.max_corner_peaks) {
    peaks.resize(static_cast<size_t>(setup.cfg.max_corner_peaks));
  }
  *corner_score = peaks[0].score;
  // 2b. Corners that predict the same landmark become one hypothesis.
  merge_peaks();
  // 2c. Refinement and ring check of each hypothesis.
  return select_hypothesis(best, corner_score);
}

bool CornerDetector::make_coarse(const cv::Mat& img) {
  const int f = setup.coarse_factor;
  const cv::Size cs(img.cols / f, img.rows / f);
  if (cs.width < templates[0].cols + 2 || cs.height < templates[0].rows + 2) return false;
  box_downsample(img, f, cs, &coarse, &row_sums);
  int block = static_cast<int>(std::lround(setup.cfg.adaptive_block_mm / (setup.mm_per_px * f)));
  block = std::max(kMinAdaptiveBlockPx, block | 1);
  adaptive_threshold_mean_inv(coarse, block, setup.cfg.adaptive_offset, &binary, &threshold_sums);
  return true;
}

// NCC of every rotated corner template at the candidate positions: the template's anchor (the
// middle of the corner's dark square) must be dark in the binary image and the patch must have
// contrast. Keeps the best score and rotation per position.
void CornerDetector::score_corner_templates() {
  integral_sum_sq(coarse, &isum, &isq);
  const int tsz = templates[0].cols, r = tsz / 2, n_pix = tsz * tsz;
  best_score.create(coarse.rows - tsz + 1, coarse.cols - tsz + 1, CV_32FC1);
  best_score.setTo(-1.0f);
  best_rot.create(best_score.size(), CV_8UC1);
  coarse.convertTo(coarse_f, CV_32F);
  const size_t fstride = coarse_f.step1();
  const int n_t = static_cast<int>(templates_zm.size());
  const double min_var = kMinCornerPatchSigmaGrey * kMinCornerPatchSigmaGrey;
  for (int y = 0; y < best_score.rows; ++y) {
    const std::uint8_t* brow = binary.ptr<std::uint8_t>(y + r);
    float* out_row = best_score.ptr<float>(y);
    for (int x = 0; x < best_score.cols; ++x) {
      if (!brow[x + r]) continue;
      double sum = 0.0, sq = 0.0;
      window_sum_sq(isum, isq, x, y, tsz, &sum, &sq);
      const double var = sq / n_pix - (sum / n_pix) * (sum / n_pix);
      if (var < min_var) continue;
      const float* patch = coarse_f.ptr<float>(y) + x;
      float best_dot = 0.0f;
      const float* tp = templates_t.data();
      const int best_i =
          template_lanes == 12 ? best_template<12>(patch, fstride, tsz, tp, n_t, &best_dot)
          : template_lanes == 16
              ? best_template<16>(patch, fstride, tsz, tp, n_t, &best_dot)
              : best_template<kMaxTemplates>(patch, fstride, tsz, tp, n_t, &best_dot);
      out_row[x] = static_cast<float>(static_cast<double>(best_dot) / std::sqrt(var * n_pix));
      best_rot.at<std::uint8_t>(y, x) = static_cast<std::uint8_t>(best_i);
    }
  }
}

// Local maxima of the score map above the corner threshold, with a parabolic subpixel position.
// Ties break towards the top-left so a flat plateau yields one peak.
void CornerDetector::find_corner_peaks() {
  peaks.clear();
  const float thr = static_cast<float>(setup.cfg.corner_threshold);
  const int tr = templates[0].cols / 2;
  for (int y = 1; y + 1 < best_score.rows; ++y) {
    const float* sm = best_score.ptr<float>(y - 1);
    const float* s0 = best_score.ptr<float>(y);
    const float* sp = best_score.ptr<float>(y + 1);
    for (int x = 1; x + 1 < best_score.cols; ++x) {
      const float v = s0[x];
      if (v < thr) continue;
      if (v < s0[x - 1] || v <= s0[x + 1] || v < sm[x - 1] || v < sm[x] || v < sm[x + 1] ||
          v <= sp[x - 1] || v <= sp[x] || v <= sp[x + 1]) {
        continue;
      }
      CornerPeak p;
      p.x = x + tr + parabola_offset(s0[x - 1], v, s0[x + 1]);
      p.y = y + tr + parabola_offset(sm[x], v, sp[x]);
      p.score = v;
      p.rot = best_rot.at<std::uint8_t>(y, x);
      peaks.push_back(p);
    }
  }
}

// Each corner predicts the landmark centre; corners that agree are merged (score-weighted centre,
// square angle from the 4x-angle vector).
void CornerDetector::merge_peaks() {
  hyps.clear();
  for (const CornerPeak& p : peaks) {
    const double a = template_angles[static_cast<size_t>(p.rot)];
    const Vec2 d =
        rot({setup.coarse_h - setup.coarse_anchor, setup.coarse_h - setup.coarse_anchor}, a);
    const Vec2 c{p.x + d.x, p.y + d.y};
    // Normal of the template's top side points to image angle a - 90 deg.
    const double up = a - kPi / 2.0;
    Hypothesis* hit = nullptr;
    for (Hypothesis& h : hyps) {
      const double da = std::abs(reduce_angle_90(up, h.up_angle) - h.up_angle);
      if (std::hypot(h.cx - c.x, h.cy - c.y) < kMergeDistanceBorderWidths * setup.coarse_w &&
          da < deg_to_rad(kMergeAngleTolDeg)) {
        hit = &h;
        break;
      }
    }
    if (!hit) {
      hyps.push_back({});
      hit = &hyps.back();
    }
    const double w = p.score;
    hit->cx = (hit->cx * hit->sum_w + c.x * w) / (hit->sum_w + w);
    hit->cy = (hit->cy * hit->sum_w + c.y * w) / (hit->sum_w + w);
    hit->sum_w += w;
    hit->c4 += w * std::cos(4.0 * up);
    hit->s4 += w * std::sin(4.0 * up);
    hit->up_angle = std::atan2(hit->s4, hit->c4) / 4.0;
    hit->score_sum += p.score;
    hit->score_max = std::max(hit->score_max, p.score);
    if (hit->n_peaks < static_cast<int>(hit->peak_idx.size())) {
      hit->peak_idx[static_cast<size_t>(hit->n_peaks++)] = static_cast<int>(&p - peaks.data());
    }
  }
  std::sort(hyps.begin(), hyps.end(),
            [](const Hypothesis& a, const Hypothesis& b) { return a.score_sum > b.score_sum; });
}

bool CornerDetector::select_hypothesis(Detection* best, double* corner_score) {
  int best_dark_count = 0;
  compute_orient4();
  for (Hypothesis& h : hyps) {
    refine_hypothesis(&h);
    double dark = 0, white = 0;
    int n_dark = 0;
    if (ring_check(h, &dark, &white, &n_dark) && n_dark > best_dark_count) {
      // The hypothesis with the most dark ring samples wins (a false corner predicting a
      // landmark mostly outside the image has few).
      best_dark_count = n_dark;
      best->h = h;
      best->dark_grey = dark;
      best->white_grey = white;
      *corner_score = h.score_max;
    }
  }
  return best_dark_count > 0;
}

// The templates are 30 degrees apart: refine the angle from the gradients, then the centre from
// the supporting corners with the refined angle.
void CornerDetector::refine_hypothesis(Hypothesis* h) const {
  int prev_deg = -1;
  for (int it = 0; it < kRefinePasses; ++it) {
    refine_coarse_angle(h);
    // The re-match below depends on the angle only through its whole degree (mod 90): when
    // that did not change, a second pass would repeat the first.
    const int deg90 = static_cast<int>(std::lround(rad_to_deg(h->up_angle))) % 90;
    const int key = deg90 < 0 ? deg90 + 90 : deg90;
    if (key == prev_deg) break;
    prev_deg = key;
    double sx = 0, sy = 0, sw = 0;
    for (int i = 0; i < h->n_peaks; ++i) {
      const CornerPeak& p = peaks[static_cast<size_t>(h->peak_idx[static_cast<size_t>(i)])];
      const double a_tmpl = template_angles[static_cast<size_t>(p.rot)];
      // The corner's true rotation: the template's, snapped to the refined square angle.
      const double a = reduce_angle_90(h->up_angle + kPi / 2.0, a_tmpl);
      double w = 0;
      const Vec2 q = rematch_corner(p, a, &w);
      const Vec2 d =
          rot({setup.coarse_h - setup.coarse_anchor, setup.coarse_h - setup.coarse_anchor}, a);
      sx += w * (q.x + d.x);
      sy += w * (q.y + d.y);
      sw += w;
    }
    if (sw > 0) {
      h->cx = sx / sw;
      h->cy = sy / sw;
    }
  }
}

// Re-matches a template at rotation a around the peak (the 30-degree templates shift the peak)
// with a parabolic subpixel maximum; returns the corner's coarse position and its vote weight.
Vec2 CornerDetector::rematch_corner(const CornerPeak& p, double a, double* weight) const {
  const int tsz = templates[0].cols, r = tsz / 2;
  const int deg = static_cast<int>(std::lround(rad_to_deg(a))) % kFineTemplateSteps;
  const std::vector<float>& tz =
      fine_templates[static_cast<size_t>(deg < 0 ? deg + kFineTemplateSteps : deg)];
  const int px0 = static_cast<int>(std::lround(p.x)), py0 = static_cast<int>(std::lround(p.y));
  constexpr int kC = kRematchCentre, kLast = kRematchGrid - 1;
  double sc[kRematchGrid][kRematchGrid];
  for (auto& row : sc) std::fill(std::begin(row), std::end(row), -1.0);
  int bx = kC, by = kC;
  for (int dy = -kRematchRadiusPx; dy <= kRematchRadiusPx; ++dy) {
    for (int dx = -kRematchRadiusPx; dx <= kRematchRadiusPx; ++dx) {
      sc[dy + kC][dx + kC] = ncc_at(tz, tsz, px0 + dx - r, py0 + dy - r);
      if (sc[dy + kC][dx + kC] > sc[by][bx]) {
        bx = dx + kC;
        by = dy + kC;
      }
    }
  }
  double qx = px0 + bx - kC, qy = py0 + by - kC;
  if (bx > 0 && bx < kLast) {
    const double d2 = sc[by][bx - 1] - 2 * sc[by][bx] + sc[by][bx + 1];
    if (d2 < 0) qx += std::clamp(0.5 * (sc[by][bx - 1] - sc[by][bx + 1]) / d2, -0.5, 0.5);
  }
  if (by > 0 && by < kLast) {
    const double d2 = sc[by - 1][bx] - 2 * sc[by][bx] + sc[by + 1][bx];
    if (d2 < 0) qy += std::clamp(0.5 * (sc[by - 1][bx] - sc[by + 1][bx]) / d2, -0.5, 0.5);
  }
  *weight = std::max(kMinRematchWeight, sc[by][bx]);
  return {qx, qy};
}

// The corner templates come in 30-degree steps; the dominant gradient orientation (modulo 90
// degrees, from the 4x angle weighted by |g|^2) inside the predicted square refines the angle.
// The per-pixel 4x-angle vectors are computed once per frame (orient4), not per hypothesis.
void CornerDetector::compute_orient4() {
  compute_orient4_in(1, 1, coarse.cols - 2, coarse.rows - 2);
}

// compute_orient4 over [x0, x1] x [y0, y1] only (clipped to the pixels with a full Prewitt
// neighbourhood); zero elsewhere. The tracked detection needs it only around its hypothesis.
void CornerDetector::compute_orient4_in(int x0, int y0, int x1, int y1) {
  orient4.create(coarse.size(), CV_32FC2);
  orient4.setTo(cv::Scalar::all(0));
  x0 = std::max(x0, 1);
  y0 = std::max(y0, 1);
  x1 = std::min(x1, coarse.cols - 2);
  y1 = std::min(y1, coarse.rows - 2);
  for (int y = y0; y <= y1; ++y) {
    cv::Vec2f* o = orient4.ptr<cv::Vec2f>(y);
    for (int x = x0; x <= x1; ++x) {
      int gxi, gyi;
      prewitt_at(coarse.ptr<std::uint8_t>(y) + x, static_cast<std::ptrdiff_t>(coarse.step[0]), &gxi,
                 &gyi);
      const double ex = gxi, ey = gyi, m2 = ex * ex + ey * ey;
      if (m2 < kMinOrientGradient2) continue;
      const double a = ex * ex - ey * ey, b = 2 * ex * ey;
      o[x] =
          cv::Vec2f(static_cast<float>((a * a - b * b) / m2), static_cast<float>(2 * a * b / m2));
    }
  }
}

void CornerDetector::refine_coarse_angle(Hypothesis* h) const {
  const double reach = setup.coarse_h + kRefineReachMarginPx;
  const int x0 = std::max(1, static_cast<int>(h->cx - reach));
  const int x1 = std::min(coarse.cols - 2, static_cast<int>(h->cx + reach) + 1);
  const int y0 = std::max(1, static_cast<int>(h->cy - reach));
  const int y1 = std::min(coarse.rows - 2, static_cast<int>(h->cy + reach) + 1);
  const Vec2 n0{std::cos(h->up_angle), std::sin(h->up_angle)};
  double c4 = 0, s4 = 0;
  for (int y = y0; y <= y1; ++y) {
    const cv::Vec2f* o = orient4.ptr<cv::Vec2f>(y);
    for (int x = x0; x <= x1; ++x) {
      const double dx = x - h->cx, dy = y - h->cy;
      if (std::abs(dx * n0.x + dy * n0.y) > reach || std::abs(-dx * n0.y + dy * n0.x) > reach) {
        continue;
      }
      c4 += static_cast<double>(o[x][0]);
      s4 += static_cast<double>(o[x][1]);
    }
  }
  if (c4 != 0 || s4 != 0) h->up_angle = reduce_angle_90(std::atan2(s4, c4) / 4.0, h->up_angle);
}

// Samples the predicted border ring (middle of the dark border) and a ring just outside it on the
// paper. Accepts when enough of the ring is inside the image, the configured fraction of it is
// dark, and at most half of the outside ring is dark (a dark area is not a landmark).
bool CornerDetector::ring_check(const Hypothesis& h, double* dark_level, double* white_level,
                                int* n_dark) {
  int ring_in = 0, ring_dark = 0, out_in = 0, out_dark = 0, total = 0;
  double dark_sum = 0, white_sum = 0;
  const double len = setup.coarse_h - setup.coarse_w;
  const int n = std::max(kMinRingSamplesPerSide, static_cast<int>(kRingSamplesPerPx * len));
  for (int k = 0; k < 4; ++k) {
    const double a = h.up_angle + k * kPi / 2.0;
    const Vec2 nrm{std::cos(a), std::sin(a)}, tan{-nrm.y, nrm.x};
    for (int i = 0; i <= n; ++i) {
      const double t = -len + 2.0 * len * i / n;
      ++total;
      const double rx = h.cx + nrm.x * (setup.coarse_h - setup.coarse_w / 2) + tan.x * t;
      const double ry = h.cy + nrm.y * (setup.coarse_h - setup.coarse_w / 2) + tan.y * t;
      const int ix = static_cast<int>(std::lround(rx)), iy = static_cast<int>(std::lround(ry));
      if (ix >= 0 && iy >= 0 && ix < binary.cols && iy < binary.rows) {
        ++ring_in;
        if (binary.at<std::uint8_t>(iy, ix)) {
          ++ring_dark;
          dark_sum += coarse.at<std::uint8_t>(iy, ix);
        }
      }
      const double out_r = setup.coarse_h + kOutsideRingBorderWidths * setup.coarse_w;
      const double ox = h.cx + nrm.x * out_r + tan.x * t;
      const double oy = h.cy + nrm.y * out_r + tan.y * t;
      const int jx = static_cast<int>(std::lround(ox)), jy = static_cast<int>(std::lround(oy));
      if (jx >= 0 && jy >= 0 && jx < binary.cols && jy < binary.rows) {
        ++out_in;
        if (binary.at<std::uint8_t>(jy, jx)) {
          ++out_dark;
        } else {
          white_sum += coarse.at<std::uint8_t>(jy, jx);
        }
      }
    }
  }
  if (!setup.ring_accepted(total, ring_in, ring_dark, out_in, out_dark)) return false;
  *dark_level = dark_sum / ring_dark;
  *n_dark = ring_dark;
  *white_level = out_in > out_dark ? white_sum / (out_in - out_dark) : kWhiteGrey;
  return true;
}

// The ring check's acceptance, shared by the coarse check above and the full-image one
// (predicted_detect.cpp): at least a quarter of the ring (one side's worth) inside the image,
// ring_dark_fraction of it dark, and at most half of the outside ring dark (a dark area is not a
// landmark).
bool VisionSetup::ring_accepted(int total, int ring_in, int ring_dark, int out_in,
                                int out_dark) const {
  if (ring_in < total / 4 || ring_dark == 0) return false;
  if (static_cast<double>(ring_dark) < cfg.ring_dark_fraction * ring_in) return false;
  return !(out_in > 0 && out_dark > out_in / 2);
}

}  // namespace agv::vision
