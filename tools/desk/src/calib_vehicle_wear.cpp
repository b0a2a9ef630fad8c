// Vehicle calibration on worn prints: robust corners from a frame's edge points, and
// the per-landmark residual table and warning. No Ceres here (model: calib_vehicle.hpp).
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <span>

#include "agv/vision/edges.hpp"
#include "agv/vision/landmark_localizer.hpp"
#include "calib_vehicle.hpp"

namespace agv::desk::vcal {

namespace {

// The pose stage's per-line fit (pose.cpp fit_lines), in pixels: its scale floor is 0.02 mm,
// 0.08 px at 0.26 mm/px (rounded down: a smaller floor only costs good points on sharp frames),
// its RANSAC band 0.5 px, four IRLS rounds; Tukey c and the RANSAC candidates are VisionConfig's.
constexpr double kMinSigmaPx = 0.05;
constexpr double kRansacTolPx = 0.5;
constexpr int kIrlsIterations = 4;
// Fewer points than this on an edge give no line (as before the robust fit).
constexpr size_t kMinEdgePoints = 5;
constexpr double kParallelDet = 1e-9;

bool fit_edge(const std::vector<Vec2>& xn, double fx_px, vision::Line2* out) {
  if (xn.size() < kMinEdgePoints) return false;
  // Pixel-sized units so the vision stage's pixel constants apply as they are.
  std::vector<Vec2> px(xn.size());
  for (size_t i = 0; i < xn.size(); ++i) px[i] = {xn[i].x * fx_px, xn[i].y * fx_px};
  std::vector<double> w(px.size());
  vision::LineFit f;
  const vision::VisionConfig vc;
  if (!vision::fit_line_robust(px, vc.tukey_c, kMinSigmaPx, kIrlsIterations, w, &f,
                               vc.ransac_iterations, kRansacTolPx)) {
    return false;
  }
  size_t kept = 0;
  for (double wi : w) kept += wi > 0.0 ? 1 : 0;
  if (kept < kMinEdgePoints) return false;
  *out = f.line;
  out->d /= fx_px;
  return true;
}

}  // namespace

bool corners_from_edges(const BorderEdges& e, double fx_px, CornerObservation* out) {
  vision::Line2 lines[2][4];
  bool have[2][4] = {};
  for (size_t k = 0; k < 2; ++k) {
    for (size_t s = 0; s < 4; ++s) have[k][s] = fit_edge(e.xn[k][s], fx_px, &lines[k][s]);
  }
  // Corner k of landmark_corners: (+,+), (-,+), (-,-), (+,-) -> x-side and y-side.
  const int xs[4] = {0, 2, 2, 0}, ys[4] = {1, 1, 3, 3};
  int n = 0;
  for (int k = 0; k < 2; ++k) {
    for (int c = 0; c < 4; ++c) {
      const size_t i = static_cast<size_t>(k * 4 + c);
      out->valid[i] = false;
      if (!have[k][xs[c]] || !have[k][ys[c]]) continue;
      const vision::Line2& a = lines[k][xs[c]];
      const vision::Line2& b = lines[k][ys[c]];
      const double det = a.nx * b.ny - a.ny * b.nx;
      if (std::abs(det) < kParallelDet) continue;
      out->xn[i] = {(a.d * b.ny - a.ny * b.d) / det, (a.nx * b.d - a.d * b.nx) / det};
      out->valid[i] = true;
      ++n;
    }
  }
  return n >= 3;
}

void flag_standing_out(const Options& opt, std::vector<LandmarkReport>* lms,
                       std::vector<std::string>* warnings) {
  for (LandmarkReport& l : *lms) {
    std::vector<double> others;
    for (const LandmarkReport& o : *lms) {
      if (o.landmark_id != l.landmark_id) others.push_back(o.rms_after_px);
    }
    double med = 0.0;
    if (!others.empty()) {
      std::sort(others.begin(), others.end());
      const size_t m = others.size() / 2;
      med = others.size() % 2 ? others[m] : 0.5 * (others[m - 1] + others[m]);
    }
    const bool relative = !others.empty() && l.rms_after_px > opt.residual_warn_ratio * med &&
                          l.rms_after_px > opt.residual_warn_floor_px;
    l.stands_out = relative || l.rms_after_px > opt.residual_warn_px;
    if (!l.stands_out) continue;
    char why[160], b[480];
    if (relative) {
      std::snprintf(why, sizeof why, "%.1fx the other landmarks' median %.3f px",
                    l.rms_after_px / std::max(med, 1e-9), med);
    } else {
      std::snprintf(why, sizeof why, "above %.2f px", opt.residual_warn_px);
    }
    std::snprintf(b, sizeof b,
                  "landmark %u: corner residual %.3f px RMS after calibration, %s: a worn, dirty "
                  "or misprinted landmark; its frames were given %.3f px of corner noise and "
                  "%.3f mm of print deviation, so it counts less; clean or reprint it and drive "
                  "again for the best result",
                  l.landmark_id, l.rms_after_px, why, l.sigma_px, l.print_offset_mm);
    warnings->push_back(b);
  }
}

std::string landmark_table(const Result& r) {
  std::string s =
      "per landmark (corner residual RMS with the printed geometry, px; the corner noise and "
      "print\n"
      "deviation the calibration gave its frames):\n"
      "landmark  passes  frames   before    after  sigma_px  print_dev_mm\n";
  for (const LandmarkReport& l : r.landmarks) {
    char b[200];
    std::snprintf(b, sizeof b, "%8u  %6d  %6d  %7.3f  %7.3f  %8.3f  %12.4f%s\n", l.landmark_id,
                  l.passes, l.frames, l.rms_before_px, l.rms_after_px, l.sigma_px,
                  l.print_offset_mm, l.stands_out ? "  <- stands out" : "");
    s += b;
  }
  return s;
}

}  // namespace agv::desk::vcal
