// Edge probes (docs/design/tracking.md "Edge probes"): a trusted prediction that is too loose to
// place the pose stage's edge bands itself (predicted_detect.cpp) is made precise by a few 1-D
// searches across each predicted side, instead of the tracked detection's coarse level and corner
// templates over the window. Each probe walks inward along a side's normal from beyond the
// prediction's reach and takes the outermost step from light to dark that is followed, one border
// width further in, by the step back to light: the outer edge of the border, not a dark mark on
// the floor, a module of the code or the logo (the later probes of a side look near the edges
// found, for the step alone). A robust line through each side's edge points,
// the four corners where the lines meet, and a plausibility check against the prediction and the
// landmark's size give the centre and border angle that place the bands. Anything doubtful
// declines, and the frame takes the tracked detection.
#include <algorithm>
#include <cmath>

#include "predicted_detector.hpp"

namespace agv::vision {

namespace {

// Probes per side, spread over the side's length less the prediction's reach: enough for a
// robust line with a quarter of them on a smudge or an occluder, few enough to cost a few
// microseconds (the first probes of a side read about 2 reach + 1.7 border widths pixels each,
// the narrowed ones about 30).
constexpr int kProbesPerSide = 8;
// A side needs this many probes on its line (after the robust fit): 5 of 8.
constexpr int kMinProbesOnLine = 5;
// The probes keep this many border widths away from the predicted corners beyond the reach, so
// none of them runs past the corner into the neighbouring side or the paper margin.
constexpr double kCornerClearBorderWidths = 0.5;
// Below this share of the half side left for the probes (a very loose prediction), no probe.
constexpr double kMinProbeSpanRel = 0.25;
// The search runs this many border widths beyond the reach on each side of the predicted edge:
// the perspective of a tilted camera moves the sides against the mean-scale prediction.
constexpr double kSlackBorderWidths = 0.5;
// The border's outer edge: a light-to-dark step (central difference of at least kMinStepGrey, a
// local maximum: on a blurred edge, the ramp's start), the light level before it, the dark level
// in the middle of the border (0.4 to 0.6 border widths further in, clear of any blur the pose
// stage takes) at least the detection's contrast floor below it, and the edge where the grey
// crosses halfway between the two (a blurred edge's middle, as the pose stage's gradient
// maximum). On the whole pattern, 0.7 to 1.3 border widths further in the strongest dark-to-light
// step there, as strong, with the run between darker everywhere than halfway. A mark on the
// floor, a module of the code or the logo rarely has a border's width and both contrasts; the
// outermost such pair on the probe is taken.
constexpr int kMinStepGrey = 8;
constexpr double kInnerEdgeMinRel = 0.7, kInnerEdgeMaxRel = 1.3;
constexpr double kDarkFromRel = 0.4, kDarkToRel = 0.6;
// The light level is read this many pixels before the step, over this many more (5 samples
// against the floor's texture); the run's darkness from this far after the crossing.
constexpr int kLevelOffsetPx = 3;
constexpr int kLightRunPx = 4;
// A narrowed probe's window starts this much earlier: a blurred edge's ramp starts up to half
// the blur (7 px at the evaluated limit) before its middle.
constexpr double kRampHalfPx = 4.0;
// Mean distance from a step's start to its edge (half a blurred edge's width) above which the
// probes decline: on frames that blurred (defocus 2 px, motion 7 px and noise at once: 2.4-3.7 px
// here, against 0.03-0.6 px on the realistic rendering and 0.8-1.8 px with 7 px of motion blur
// alone) the tracked detection's fixes were measured 10 % better at p95 than the probes'
// (eval_tracking --condition stress, 500 frames), for reasons not found; with motion blur alone
// the two were within 3 %.
constexpr double kMaxMeanRampPx = 2.0;
// Robust line through a side's edge points: Tukey c (the usual 95 % efficiency constant), the
// scale floor (px, about the nearest-pixel sampling's scatter) and the RANSAC start (tolerance
// px), so that an occluder's or a smudge's points on up to 3 of 8 probes do not pull the line; a
// point further than kInlierPx from the line is off it.
constexpr double kProbeTukeyC = 4.685;
constexpr double kProbeMinSigmaPx = 0.5;
constexpr int kProbeIrlsIterations = 2;
constexpr int kProbeRansacIterations = 8;
constexpr double kProbeRansacTolPx = 1.5;
constexpr double kInlierPx = 2.0;
// The distance between opposite sides may differ from the landmark's size at the camera's mean
// scale by this share: the tilted-camera perspective changes it by a few percent.
constexpr double kSizeTolRel = 0.12;
// Two probes' edges agree when they differ along the normal by at most the predicted heading's
// reach over their distance plus this (px); the next probe then searches this far either way of
// the line through them (nearest-pixel sampling scatters by half a pixel, extrapolated up to 7
// probe spacings).
constexpr double kNarrowConsistentPx = 2.0;
constexpr double kNarrowPx = 4.0;

// Neighbouring sides closer to parallel than this determinant (sine of their angle) meet nowhere
// useful.
constexpr double kParallelSine = 1e-3;

// The point where two lines n . p = d meet; false when they are (nearly) parallel.
bool intersect(const Line2& a, const Line2& b, Vec2* p) {
  const double det = a.nx * b.ny - a.ny * b.nx;
  if (std::abs(det) < kParallelSine) return false;
  p->x = (a.d * b.ny - a.ny * b.d) / det;
  p->y = (a.nx * b.d - a.d * b.nx) / det;
  return true;
}

}  // namespace

// One probe: the outer border edge along p(s) = start + step * s (s = 0 beyond the predicted edge,
// increasing inward), s in [0, n), the outer edge searched for in [s_lo, s_hi]. whole: the whole
// pattern (the inner edge and the dark run between); otherwise the step and the dark over the
// light run's length just inside it. Returns false when the probe ends outside the image or
// finds no edge there.
bool PredictedDetector::probe_edge(const cv::Mat& img, Vec2 start, Vec2 step, int n,
                                   double border_px, int s_lo, int s_hi, bool whole,
                                   ProbeEdge* edge) {
  const int dark_lo = static_cast<int>(std::lround(kDarkFromRel * border_px));
  const int dark_hi = static_cast<int>(std::lround(kDarkToRel * border_px));
  const double inner_lo = kInnerEdgeMinRel * border_px, inner_hi = kInnerEdgeMaxRel * border_px;
  // Samples a candidate at s reads beyond it (the crossing lies before s + dark_lo).
  const int beyond =
      whole ? dark_lo + static_cast<int>(std::ceil(inner_hi)) + kLevelOffsetPx + 2 : dark_hi + 1;
  n = std::min(n, s_hi + beyond + 1);
  if (s_hi < s_lo || n < 2) return false;
  // The probe starts where it enters the image (a landmark near the image border); it must end
  // inside. The bounds keep a margin for the fixed-point steps' rounding (below 0.01 px over a
  // probe), so no read falls outside the image.
  constexpr double kFixedPointSlackPx = 0.01;
  const double lo = -kHalfPixel + kFixedPointSlackPx;
  const double hi_x = img.cols - kHalfPixel - kFixedPointSlackPx;
  const double hi_y = img.rows - kHalfPixel - kFixedPointSlackPx;
  auto inside = [&](double s) {
    const double x = start.x + step.x * s, y = start.y + step.y * s;
    return x >= lo && y >= lo && x < hi_x && y < hi_y;
  };
  if (!inside(n - 1)) return false;
  int s0 = std::max(0, s_lo - kLevelOffsetPx - kLightRunPx);
  while (s0 < n && !inside(s0)) ++s0;
  probe_grey.resize(static_cast<size_t>(n));
  // Nearest pixels in 16.16 fixed point: the probe is a few hundred reads, mostly one per row.
  constexpr double kOne = 65536.0;
  const std::uint8_t* base = img.ptr<std::uint8_t>(0);
  const std::ptrdiff_t stride = static_cast<std::ptrdiff_t>(img.step[0]);
  std::int64_t fx = std::llround((start.x + step.x * s0 + kHalfPixel) * kOne);
  std::int64_t fy = std::llround((start.y + step.y * s0 + kHalfPixel) * kOne);
  const std::int64_t dx = std::llround(step.x * kOne), dy = std::llround(step.y * kOne);
  std::uint8_t* g = probe_grey.data();
  for (int s = s0; s < n; ++s, fx += dx, fy += dy) g[s] = base[(fy >> 16) * stride + (fx >> 16)];
  auto grey = [&](int s) { return static_cast<int>(probe_grey[static_cast<size_t>(s)]); };
  // Central differences, positive from light (outside) to dark (inside).
  auto diff = [&](int s) { return grey(s - 1) - grey(s + 1); };
  for (int s = std::max(s_lo, s0 + kLevelOffsetPx + kLightRunPx); s <= s_hi && s + beyond < n;
       ++s) {
    const int d = diff(s);
    if (d < kMinStepGrey || d < diff(s - 1) || d < diff(s + 1)) continue;
    // Not dark just inside: not the border (most candidates on a textured floor end here).
    if (grey(s - kLevelOffsetPx) - grey(s + kLevelOffsetPx) < kMinContrastGrey) continue;
    int light_sum = 0, dark_sum = 0;
    for (int i = s - kLevelOffsetPx - kLightRunPx; i <= s - kLevelOffsetPx; ++i) {
      light_sum += grey(i);
    }
    for (int i = s + dark_lo; i <= s + dark_hi; ++i) dark_sum += grey(i);
    const double light = static_cast<double>(light_sum) / (kLightRunPx + 1);
    const double dark = static_cast<double>(dark_sum) / (dark_hi - dark_lo + 1);
    if (light - dark < kMinContrastGrey) continue;
    const double mid = 0.5 * (light + dark);
    int i = s - kLevelOffsetPx + 1;
    while (i < s + dark_lo && grey(i) > mid) ++i;
    if (i >= s + dark_lo || grey(i - 1) <= mid) continue;
    const double crossing = i - 1 + (grey(i - 1) - mid) / (grey(i - 1) - grey(i));
    // The run: darker than halfway from just after the crossing to the inner edge (whole) or to
    // the end of the dark level's window.
    int run_end = s + dark_hi;
    if (whole) {
      int j = static_cast<int>(std::ceil(crossing + inner_lo));
      for (int k = j + 1; k <= static_cast<int>(crossing + inner_hi); ++k) {
        if (diff(k) < diff(j)) j = k;
      }
      const int after = grey(j + kLevelOffsetPx);
      if (after - dark < kMinContrastGrey) continue;
      run_end = j - kLevelOffsetPx;
    }
    int dark_max = 0;
    for (int k = static_cast<int>(crossing) + kLevelOffsetPx; k <= run_end; ++k) {
      dark_max = std::max(dark_max, grey(k));
    }
    if (dark_max > mid) continue;
    edge->s = crossing;
    edge->ramp_px = crossing - s;
    edge->light_grey = light;
    edge->dark_grey = dark;
    return true;
  }
  return false;
}

// The probes' geometry for window w; false when the prediction cannot be probed (too loose, or
// the landmark certainly cut by the image border).
bool PredictedDetector::plan_probes(const cv::Mat& img, const SearchWindow& w,
                                    ProbePlan* plan) const {
  if (!std::isfinite(w.centre_px.x) || !std::isfinite(w.centre_px.y) ||
      !std::isfinite(w.up_angle_rad) || !std::isfinite(w.corner_sigma_px) ||
      !std::isfinite(w.up_angle_sigma_rad)) {
    return false;
  }
  const double border_px = setup.geom.border_width_mm() / setup.mm_per_px;
  const double half_px = setup.geom.outer_half_mm() / setup.mm_per_px;
  const double reach = setup.cfg.tracking.window_sigmas * w.corner_sigma_px;
  const double t_max = half_px - reach - kCornerClearBorderWidths * border_px;
  if (t_max < kMinProbeSpanRel * half_px) return false;
  const double angle_reach = setup.cfg.tracking.window_sigmas * w.up_angle_sigma_rad;
  if (angle_reach >= kPi / 8) return false;
  // A landmark certainly cut by the image border (a predicted outer corner outside by more than
  // the reach) is not probed: it keeps the detection, which weighs its corners.
  for (int k = 0; k < 4; ++k) {
    const Vec2 d = rot({half_px, half_px}, w.up_angle_rad + k * kPi / 2.0);
    const double x = w.centre_px.x + d.x, y = w.centre_px.y + d.y;
    if (x < -kHalfPixel - reach || y < -kHalfPixel - reach || x > img.cols - kHalfPixel + reach ||
        y > img.rows - kHalfPixel + reach) {
      return false;
    }
  }
  // The side may lie this far either way of its predicted place along the probe.
  const double range = reach + t_max * std::tan(angle_reach) + kSlackBorderWidths * border_px;
  plan->n =
      static_cast<int>(std::ceil(2.0 * range + (kDarkFromRel + kInnerEdgeMaxRel) * border_px)) +
      2 * kLevelOffsetPx + 3;
  plan->border_px = border_px;
  plan->half_px = half_px;
  plan->reach = reach;
  plan->t_max = t_max;
  plan->angle_reach = angle_reach;
  plan->range = range;
  return true;
}

// Side k's probes: the border's outer edge on each that finds one (probe_pts, probe_hits).
void PredictedDetector::probe_side(const cv::Mat& img, const SearchWindow& w, const ProbePlan& plan,
                                   int k) {
  const double border_px = plan.border_px, half_px = plan.half_px, t_max = plan.t_max;
  const double angle_reach = plan.angle_reach, range = plan.range;
  const int n = plan.n;
  const double a = w.up_angle_rad + k * kPi / 2.0;
  const Vec2 nrm{std::cos(a), std::sin(a)}, tan{-nrm.y, nrm.x};
  probe_pts.clear();
  probe_hits.clear();
  for (int i = 0; i < kProbesPerSide; ++i) {
    const double t = -t_max + 2.0 * t_max * i / (kProbesPerSide - 1);
    const double r0 = half_px + range + 1.0 + kLevelOffsetPx;
    const Vec2 start{w.centre_px.x + nrm.x * r0 + tan.x * t,
                     w.centre_px.y + nrm.y * r0 + tan.y * t};
    // After the first edge found on a side, the next probe looks near it (within the predicted
    // heading's reach); after two that agree, near the line through the first and the last
    // found. There only the outer step and the dark just inside it are checked: the pattern
    // was found whole on the first, and the probe then reads a fifth of the pixels,
    // mostly ones the pose stage's band reads next. Where it finds nothing there (a smudge
    // took the first), the whole range and pattern.
    ProbeEdge e;
    bool found = false;
    double s_pred = 0, half = -1;
    if (probe_hits.size() == 1) {
      s_pred = probe_hits.front().s;
      half = std::abs(t - probe_hits.front().t) * std::tan(angle_reach) + kNarrowPx;
    } else if (probe_hits.size() >= 2) {
      const ProbeEdge &first = probe_hits.front(), &last = probe_hits.back();
      if (std::abs(last.s - first.s) <=
          std::abs(last.t - first.t) * std::tan(angle_reach) + kNarrowConsistentPx) {
        s_pred = first.s + (last.s - first.s) * (t - first.t) / (last.t - first.t);
        half = kNarrowPx;
      }
    }
    if (half >= 0) {
      found = probe_edge(img, start, {-nrm.x, -nrm.y}, n, border_px,
                         static_cast<int>(std::floor(s_pred - half - kRampHalfPx)),
                         static_cast<int>(std::ceil(s_pred + half)), false, &e);
    }
    // A tag's border has no reliable inner edge (black data cells touch it), but its white
    // margin puts paper before the outer edge: the step and the dark just inside suffice.
    if (!found) {
      found = probe_edge(img, start, {-nrm.x, -nrm.y}, n, border_px, 0, n, !setup.outer_only, &e);
    }
    if (found) {
      probe_pts.push_back({start.x - nrm.x * e.s, start.y - nrm.y * e.s});
      e.t = t;
      probe_hits.push_back(e);
    }
  }
}

// The robust line through the side's probe edges (probe_side), and the grey levels and ramps of
// the probes on it added to the sums; false (sums unchanged) when too few probes lie on it.
bool PredictedDetector::fit_side(Line2* line, int* on_line_out, ProbeSums* sums) {
  if (static_cast<int>(probe_pts.size()) < kMinProbesOnLine) return false;
  double& light_sum = sums->light;
  double& ramp_sum = sums->ramp;
  double& dark_sum = sums->dark;
  probe_w.resize(probe_pts.size());
  LineFit fit;
  if (!fit_line_robust(probe_pts, kProbeTukeyC, kProbeMinSigmaPx, kProbeIrlsIterations, probe_w,
                       &fit, kProbeRansacIterations, kProbeRansacTolPx)) {
    return false;
  }
  int on_line = 0;
  for (size_t i = 0; i < probe_pts.size(); ++i) {
    const Vec2& p = probe_pts[i];
    if (std::abs(fit.line.nx * p.x + fit.line.ny * p.y - fit.line.d) > kInlierPx) continue;
    ++on_line;
    light_sum += probe_hits[i].light_grey;
    ramp_sum += probe_hits[i].ramp_px;
    dark_sum += probe_hits[i].dark_grey;
  }
  if (on_line < kMinProbesOnLine) {
    // Points already summed belong to a side that is dropped: take them back out.
    for (size_t i = 0; i < probe_pts.size(); ++i) {
      const Vec2& p = probe_pts[i];
      if (std::abs(fit.line.nx * p.x + fit.line.ny * p.y - fit.line.d) > kInlierPx) continue;
      light_sum -= probe_hits[i].light_grey;
      ramp_sum -= probe_hits[i].ramp_px;
      dark_sum -= probe_hits[i].dark_grey;
    }
    return false;
  }
  *on_line_out = on_line;
  *line = fit.line;
  return true;
}

// The square's centre and border-normal angle from its sides' lines (three or four of them);
// false when they do not make a square of the landmark's size.
bool PredictedDetector::square_from_lines(const SearchWindow& w, const ProbePlan& plan,
                                          const std::array<Line2, 4>& lines,
                                          const std::array<bool, 4>& have, int n_sides,
                                          double* up_out, Vec2* c_out) const {
  const double half_px = plan.half_px;
  double sum_c = 0, sum_s = 0;
  for (int k = 0; k < 4; ++k) {
    if (!have[static_cast<size_t>(k)]) continue;
    const Line2& l = lines[static_cast<size_t>(k)];
    const double a4 = 4.0 * std::atan2(l.ny, l.nx);
    sum_c += std::cos(a4);
    sum_s += std::sin(a4);
  }
  const double up = reduce_angle_90(std::atan2(sum_s, sum_c) / 4.0, w.up_angle_rad);
  Vec2 c{0.0, 0.0};
  if (n_sides == 4) {
    // Corners, centre and the mean border-normal angle (sides reduced to side 0's).
    for (int k = 0; k < 4; ++k) {
      Vec2 p;
      if (!intersect(lines[static_cast<size_t>(k)], lines[static_cast<size_t>((k + 1) % 4)], &p)) {
        return false;
      }
      c.x += p.x / 4;
      c.y += p.y / 4;
    }
  } else {
    // Three sides: along the axis with both, their middle; along the other, the one side moved
    // in by the half size at the camera's mean scale (a tilted camera's perspective leaves the
    // pose stage's band to take up the few percent).
    c = w.centre_px;
    for (int axis = 0; axis < 2; ++axis) {
      const double a = up + axis * kPi / 2.0;
      const Vec2 u{std::cos(a), std::sin(a)};
      // Edge position along u (from c) of side k, outward positive for side k = axis.
      auto edge_along = [&](int k, double* e) {
        const Line2& l = lines[static_cast<size_t>(k)];
        const double nu = l.nx * u.x + l.ny * u.y;
        if (std::abs(nu) < kParallelSine) return false;
        *e = (l.d - (l.nx * c.x + l.ny * c.y)) / nu;
        return true;
      };
      const int k0 = axis, k1 = axis + 2;
      double e0 = 0, e1 = 0, shift = 0;
      if (have[static_cast<size_t>(k0)] && have[static_cast<size_t>(k1)]) {
        if (!edge_along(k0, &e0) || !edge_along(k1, &e1)) return false;
        if (std::abs((e0 - e1) - 2.0 * half_px) > kSizeTolRel * 2.0 * half_px) return false;
        shift = 0.5 * (e0 + e1);
      } else if (have[static_cast<size_t>(k0)]) {
        if (!edge_along(k0, &e0)) return false;
        shift = e0 - half_px;
      } else {
        if (!edge_along(k1, &e1)) return false;
        shift = e1 + half_px;
      }
      c.x += shift * u.x;
      c.y += shift * u.y;
    }
  }
  // Opposite sides the landmark's size apart, measured through the centre.
  for (int k = 0; k < 2 && n_sides == 4; ++k) {
    const Line2& a = lines[static_cast<size_t>(k)];
    const Line2& b = lines[static_cast<size_t>(k + 2)];
    const double dist =
        std::abs(a.nx * c.x + a.ny * c.y - a.d) + std::abs(b.nx * c.x + b.ny * c.y - b.d);
    if (std::abs(dist - 2.0 * half_px) > kSizeTolRel * 2.0 * half_px) return false;
  }
  *up_out = up;
  *c_out = c;
  return true;
}

bool PredictedDetector::probe_prediction(const cv::Mat& img, const SearchWindow& w,
                                         ProbedSquare* out) {
  ProbePlan plan;
  if (!plan_probes(img, w, &plan)) return false;
  std::array<Line2, 4> lines;
  std::array<bool, 4> have{true, true, true, true};
  ProbeSums sums;
  int n_on_line = 0;
  for (int k = 0; k < 4; ++k) {
    probe_side(img, w, plan, k);
    int on_line = 0;
    if (!fit_side(&lines[static_cast<size_t>(k)], &on_line, &sums)) {
      // The tag family may lose one side (an occluder over the border: the side the detector's
      // quad broke on); the square is then placed from the other three and the known size.
      have[static_cast<size_t>(k)] = false;
      if (setup.outer_only) continue;
      return false;
    }
    n_on_line += on_line;
  }
  const int n_sides = static_cast<int>(std::count(have.begin(), have.end(), true));
  if (n_sides < 3 || n_on_line == 0) return false;
  double up = 0;
  Vec2 c;
  if (!square_from_lines(w, plan, lines, have, n_sides, &up, &c)) return false;
  // Where the tracked detection would accept it: within the reach (plus the corner votes'
  // agreement distance) and the angle tolerance of the prediction.
  const double angle_tol = plan.angle_reach + deg_to_rad(kTrackedAngleSlackDeg);
  if (std::abs(up - w.up_angle_rad) > angle_tol) return false;
  if (std::hypot(c.x - w.centre_px.x, c.y - w.centre_px.y) >
      plan.reach + kMergeDistanceBorderWidths * plan.border_px) {
    return false;
  }
  // A blurred landmark keeps the detection (measured, docs/design/tracking.md "Edge probes").
  if (sums.ramp / n_on_line > kMaxMeanRampPx) return false;
  out->centre_px = c;
  out->up_rad = up;
  out->dark_grey = sums.dark / n_on_line;
  out->white_grey = sums.light / n_on_line;
  out->on_line_share = static_cast<double>(n_on_line) / (4 * kProbesPerSide);
  return true;
}

}  // namespace agv::vision
