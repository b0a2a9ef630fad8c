// The tray's oriented box on the tray plane (tray_fit.hpp).
#include "agv/overhead/tray_fit.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <utility>
#include <vector>

#include "tray_fit_input.hpp"
#include "tray_fit_internal.hpp"

namespace agv::overhead {

namespace tray_fit_detail {

// Sides in the vehicle's frame, counter-clockwise from the front: outward normal at heading +
// k quarter turns; the front and rear are the length's ends.
constexpr int kSides = 4;
constexpr double kMadToSigma = 1.4826;
constexpr double kTukeyC = 4.685;
// Orientation histogram of the edges (modulo a quarter turn) and its peaks.
constexpr double kAngleBinRad = 0.5 * kPi / 180.0;
constexpr int kMaxOrientations = 3;
constexpr int kMinPeakPoints = 5;
// Centre hypotheses per axis and orientation; each is refined briefly and scored by how much of
// the tray's outline it explains.
constexpr std::size_t kPeaksPerAxis = 3;
constexpr int kPeakSeparationBins = 4;
constexpr int kSharpenSteps = 6;
constexpr double kSharpenStepRad = 0.4 * kPi / 180.0;
constexpr int kScoringIterations = 2;
// A rim line seen where the tray's side face should end counts this much of a side.
constexpr double kRimWeight = 0.5;
// Headings are searched this much beyond the prediction's sigma_window sigma (the histogram's
// bins and the sharpening steps).
constexpr double kHeadingSlackRad = 2.0 * kPi / 180.0;

struct Box {
  Vec2 c;  // relative to the predicted centre, mm
  double theta = 0.0;
};

Vec2 side_normal(int k, double theta) {
  const double a = theta + 0.5 * kPi * k;
  return {std::cos(a), std::sin(a)};
}
double half_across(int k, const site::FleetAgv& agv) {
  return 0.5 * (k % 2 == 0 ? agv.tray_length_mm : agv.tray_width_mm);
}
double half_along(int k, const site::FleetAgv& agv) {
  return 0.5 * (k % 2 == 0 ? agv.tray_width_mm : agv.tray_length_mm);
}
// Distance between two axes (angles modulo pi), in [0, pi/2].
double axis_distance(double a, double b) { return std::abs(std::remainder(a - b, kPi)); }

// The box's axes at heading theta, for the per-point tests: an edge's axis is within tol of the
// length axis when the cosine of twice the angle between them is at least cos(2 tol), of the
// width axis when it is at most -cos(2 tol).
struct Axes {
  Vec2 n0;     // outward normal of the front
  Vec2 twice;  // (cos, sin) of 2 theta
  double cos2tol = 1.0;
  Axes(double theta, double tol_rad)
      : n0{std::cos(theta), std::sin(theta)},
        twice{std::cos(2.0 * theta), std::sin(2.0 * theta)},
        cos2tol(std::cos(2.0 * tol_rad)) {}
  // 0 (front/rear), 1 (left/right) or -1.
  int group(const PlaneEdge& e) const {
    const double c = e.axis2.x * twice.x + e.axis2.y * twice.y;
    return c >= cos2tol ? 0 : (c <= -cos2tol ? 1 : -1);
  }
  Vec2 normal(int k) const {
    switch (k & 3) {
      case 0:
        return n0;
      case 1:
        return {-n0.y, n0.x};
      case 2:
        return {-n0.x, -n0.y};
      default:
        return {n0.y, -n0.x};
    }
  }
};

// Candidate orientations of the rectangle (modulo pi): the strongest directions of the edges
// modulo a quarter turn, each as either axis, within `allowed` of the prediction.
std::vector<double> orientations(const std::vector<PlaneEdge>& edges, double theta_pred,
                                 double allowed) {
  const int n = static_cast<int>(std::lround(0.5 * kPi / kAngleBinRad));
  std::vector<double> hist(static_cast<std::size_t>(n), 0.0), smooth(hist.size(), 0.0);
  for (const PlaneEdge& e : edges) {
    const double a = std::fmod(e.axis_rad, 0.5 * kPi);
    hist[static_cast<std::size_t>(std::min(n - 1, static_cast<int>(a / kAngleBinRad)))] += 1.0;
  }
  static constexpr double kKernel[5] = {1, 2, 3, 2, 1};
  for (int i = 0; i < n; ++i) {
    for (int k = -2; k <= 2; ++k) {
      smooth[static_cast<std::size_t>(i)] +=
          kKernel[k + 2] * hist[static_cast<std::size_t>((i + k + n) % n)] / 9.0;
    }
  }
  std::vector<std::pair<double, double>> peaks;  // (height, angle)
  for (int i = 0; i < n; ++i) {
    const double v = smooth[static_cast<std::size_t>(i)];
    if (v < kMinPeakPoints / 3.0 || v < smooth[static_cast<std::size_t>((i + 1) % n)] ||
        v <= smooth[static_cast<std::size_t>((i + n - 1) % n)]) {
      continue;
    }
    const double a = (i + 0.5) * kAngleBinRad;
    for (const double theta : {a, a + 0.5 * kPi}) {
      if (axis_distance(theta, theta_pred) <= allowed) peaks.push_back({v, theta});
    }
  }
  std::sort(peaks.begin(), peaks.end(), [](const auto& x, const auto& y) { return x > y; });
  std::vector<double> out;
  for (std::size_t i = 0; i < peaks.size() && out.size() < 2 * kMaxOrientations; ++i) {
    out.push_back(peaks[i].second);
  }
  return out;
}

// The centre along each axis at orientation theta: every edge point of that axis votes for the
// centre half the tray's size behind it and in front of it; where both sides agree the vote
// peaks. The highest peaks of each axis (offsets along the axis from the prediction).
double vote_centre(const std::vector<PlaneEdge>& edges, const site::FleetAgv& agv, double theta,
                   double reach_mm, double bin_mm, double tol_rad, std::vector<double> peaks[2]) {
  const int n = 2 * static_cast<int>(std::ceil(reach_mm / bin_mm)) + 1;
  const double lo = -0.5 * n * bin_mm;
  std::vector<double> h[2] = {std::vector<double>(static_cast<std::size_t>(n), 0.0),
                              std::vector<double>(static_cast<std::size_t>(n), 0.0)};
  const Axes ax(theta, tol_rad);
  const Vec2 nrm[2] = {ax.normal(0), ax.normal(1)};
  for (const PlaneEdge& e : edges) {
    const int axis = ax.group(e);
    if (axis < 0) continue;
    const double u = e.q.x * nrm[axis].x + e.q.y * nrm[axis].y, half = half_across(axis, agv);
    for (const double v : {u - half, u + half}) {
      const int b = static_cast<int>(std::floor((v - lo) / bin_mm));
      if (b >= 0 && b < n) h[axis][static_cast<std::size_t>(b)] += 1.0;
    }
  }
  std::vector<double> sm(static_cast<std::size_t>(n));
  double height = 0.0;
  for (int axis = 0; axis < 2; ++axis) {
    const auto at = [&](int b) {
      return b >= 0 && b < n ? h[axis][static_cast<std::size_t>(b)] : 0.0;
    };
    for (int b = 0; b < n; ++b)
      sm[static_cast<std::size_t>(b)] = at(b - 1) + 2.0 * at(b) + at(b + 1);
    std::vector<std::pair<double, int>> top;
    for (int b = 0; b < n; ++b) {
      const double v = sm[static_cast<std::size_t>(b)];
      if (v > 0.0 && (b == 0 || v > sm[static_cast<std::size_t>(b - 1)]) &&
          (b + 1 == n || v >= sm[static_cast<std::size_t>(b + 1)])) {
        top.push_back({v, b});
      }
    }
    std::sort(top.begin(), top.end(), [](const auto& x, const auto& y) { return x > y; });
    if (!top.empty()) height += top[0].first;
    peaks[axis].clear();
    // Distinct peaks: a side's votes spread over a few bins, whose ripples are no hypotheses.
    std::vector<int> taken;
    for (std::size_t i = 0; i < top.size() && taken.size() < kPeaksPerAxis; ++i) {
      bool near = false;
      for (const int b : taken) near = near || std::abs(b - top[i].second) < kPeakSeparationBins;
      if (near) continue;
      taken.push_back(top[i].second);
      peaks[axis].push_back(lo + (top[i].second + 0.5) * bin_mm);
    }
  }
  return height;
}

// The histogram's direction is a degree or so off (the gradient kernel's bias on diagonal
// edges), which smears the votes along a side: the orientation whose votes peak highest within
// a few degrees of it.
double sharpen(const std::vector<PlaneEdge>& edges, const site::FleetAgv& agv, double theta,
               double reach_mm, double bin_mm, double tol_rad, std::vector<double> peaks[2]) {
  double best = -1.0, best_theta = theta;
  std::vector<double> trial[2];
  for (int k = -kSharpenSteps; k <= kSharpenSteps; ++k) {
    const double t = theta + k * kSharpenStepRad;
    const double h = vote_centre(edges, agv, t, reach_mm, bin_mm, tol_rad, trial);
    if (h > best) best = h, best_theta = t, peaks[0] = trial[0], peaks[1] = trial[1];
  }
  return best_theta;
}

// An edge point's side of the box and its signed distance beyond it; false when it belongs to
// none (direction or distance).
bool side_of(const PlaneEdge& e, const Box& b, const Axes& ax, const site::FleetAgv& agv,
             double band_mm, int* side, double* r) {
  const int axis = ax.group(e);
  if (axis < 0) return false;
  const Vec2 nrm = ax.normal(axis);
  const Vec2 d{e.q.x - b.c.x, e.q.y - b.c.y};
  const double u = d.x * nrm.x + d.y * nrm.y, v = -d.x * nrm.y + d.y * nrm.x;
  const int k = u >= 0.0 ? axis : axis + 2;
  *side = k;
  *r = std::abs(u) - half_across(k, agv);
  return std::abs(*r) <= band_mm && std::abs(v) <= half_along(k, agv) + band_mm;
}

struct Fitted {
  Box box;
  std::vector<int> side;     // per edge, -1 when none
  std::vector<double> w, r;  // Tukey weight and residual per edge
  double h[9] = {};          // sum of w J J^T
  double s2 = 0.0;           // weighted residual variance, mm^2
};

bool invert3(const double* a, double* inv) {
  const double c00 = a[4] * a[8] - a[5] * a[7], c01 = a[5] * a[6] - a[3] * a[8],
               c02 = a[3] * a[7] - a[4] * a[6];
  const double det = a[0] * c00 + a[1] * c01 + a[2] * c02;
  if (!(std::abs(det) > 1e-300) || !std::isfinite(det)) return false;
  inv[0] = c00 / det;
  inv[1] = (a[2] * a[7] - a[1] * a[8]) / det;
  inv[2] = (a[1] * a[5] - a[2] * a[4]) / det;
  inv[3] = c01 / det;
  inv[4] = (a[0] * a[8] - a[2] * a[6]) / det;
  inv[5] = (a[2] * a[3] - a[0] * a[5]) / det;
  inv[6] = c02 / det;
  inv[7] = (a[1] * a[6] - a[0] * a[7]) / det;
  inv[8] = (a[0] * a[4] - a[1] * a[3]) / det;
  return true;
}

// The Jacobian of an edge's residual on side k with respect to (cx, cy, theta).
void jacobian(const PlaneEdge& e, const Box& b, const Axes& ax, int k, double* j) {
  const Vec2 n = ax.normal(k);
  j[0] = -n.x;
  j[1] = -n.y;
  j[2] = -n.y * (e.q.x - b.c.x) + n.x * (e.q.y - b.c.y);
}

// Robust Gauss-Newton of the box's centre and heading (known size): Tukey weights from the
// residuals' median scale, the points re-assigned to sides at every step.
bool refine(const std::vector<PlaneEdge>& edges, const site::FleetAgv& agv, double band_mm,
            double min_sigma_mm, double tol_rad, int iterations, Fitted* f) {
  const std::size_t n = edges.size();
  f->side.assign(n, -1);
  f->w.assign(n, 0.0);
  f->r.assign(n, 0.0);
  std::vector<double> abs_r;
  for (int it = 0; it <= iterations; ++it) {
    abs_r.clear();
    const Axes ax(f->box.theta, tol_rad);
    for (std::size_t i = 0; i < n; ++i) {
      if (!side_of(edges[i], f->box, ax, agv, band_mm, &f->side[i], &f->r[i])) {
        f->side[i] = -1;
        continue;
      }
      abs_r.push_back(std::abs(f->r[i]));
    }
    if (abs_r.size() < 6) return false;
    std::nth_element(abs_r.begin(), abs_r.begin() + static_cast<std::ptrdiff_t>(abs_r.size() / 2),
                     abs_r.end());
    const double sigma = std::max(min_sigma_mm, kMadToSigma * abs_r[abs_r.size() / 2]);
    double h[9] = {}, g[3] = {}, swr2 = 0.0, sw = 0.0;
    for (std::size_t i = 0; i < n; ++i) {
      f->w[i] = 0.0;
      if (f->side[i] < 0) continue;
      const double u = f->r[i] / (kTukeyC * sigma);
      if (!(std::abs(u) < 1.0)) continue;
      const double w = (1.0 - u * u) * (1.0 - u * u);
      f->w[i] = w;
      double j[3];
      jacobian(edges[i], f->box, ax, f->side[i], j);
      for (int a = 0; a < 3; ++a) {
        g[a] += w * j[a] * f->r[i];
        for (int b = 0; b < 3; ++b) h[3 * a + b] += w * j[a] * j[b];
      }
      swr2 += w * f->r[i] * f->r[i];
      sw += w;
    }
    double inv[9];
    if (!(sw > 3.0) || !invert3(h, inv)) return false;
    std::copy(h, h + 9, f->h);
    f->s2 = swr2 / (sw - 3.0);
    if (it == iterations) break;  // weights and information of the final box
    f->box.c.x -= inv[0] * g[0] + inv[1] * g[1] + inv[2] * g[2];
    f->box.c.y -= inv[3] * g[0] + inv[4] * g[1] + inv[5] * g[2];
    f->box.theta -= inv[6] * g[0] + inv[7] * g[1] + inv[8] * g[2];
  }
  return true;
}

// Fraction of side k's length covered by its kept points within on_line_mm of its line (one bin
// per two pixels on the plane: a diagonal edge's thinned points are up to sqrt 2 pixels apart),
// and
// the mean of their residuals.
void side_stats(const std::vector<PlaneEdge>& edges, const Fitted& f, const site::FleetAgv& agv,
                double mm_per_px, double on_line_mm, TrayFix* out, double mean_r[kSides]) {
  for (int k = 0; k < kSides; ++k) {
    const double half = half_along(k, agv);
    const int bins = std::max(1, static_cast<int>(std::lround(half / mm_per_px)));
    std::vector<char> hit(static_cast<std::size_t>(bins), 0);
    const Vec2 n = side_normal(k, f.box.theta);
    double sw = 0.0, swr = 0.0;
    int count = 0;
    for (std::size_t i = 0; i < edges.size(); ++i) {
      if (f.side[i] != k || !(f.w[i] > 0.0)) continue;
      ++count;
      sw += f.w[i];
      swr += f.w[i] * f.r[i];
      const Vec2 d{edges[i].q.x - f.box.c.x, edges[i].q.y - f.box.c.y};
      const double along = -d.x * n.y + d.y * n.x;
      const int b = static_cast<int>(std::floor((along + half) / (2.0 * half) * bins));
      if (b >= 0 && b < bins && std::abs(f.r[i]) <= on_line_mm)
        hit[static_cast<std::size_t>(b)] = 1;
    }
    double covered = 0.0;
    for (const char h : hit) covered += h;
    out->coverage[static_cast<std::size_t>(k)] = covered / bins;
    out->points[static_cast<std::size_t>(k)] = count;
    mean_r[k] = sw > 0.0 ? swr / sw : 0.0;
  }
}

// Where the tray's side faces are seen: the camera's foot on the plane relative to the predicted
// centre, the camera's height above the plane and the face's depth below the top edge.
struct RimView {
  Vec2 foot;
  double height_mm = 0.0;
  double depth_mm = 0.0;
};

// A side facing the camera shows its face beside the top edge, ending in a second line further
// out (a point below the plane is seen nearer the camera's foot). A box put on that second line
// explains the same side, but leaves the first one inside it unexplained; the right box explains
// both. Sum over the sides facing the camera of the coverage of their face's far line.
double rim_coverage(const std::vector<PlaneEdge>& edges, const Box& box, const site::FleetAgv& agv,
                    const RimView& rim, double on_line_mm, double mm_per_px, double tol_rad) {
  if (!(rim.depth_mm > 0.0)) return 0.0;
  const Axes ax(box.theta, tol_rad);
  double sum = 0.0;
  std::vector<char> hit;
  for (int k = 0; k < kSides; ++k) {
    const Vec2 n = ax.normal(k);
    const double h = half_across(k, agv), half = half_along(k, agv);
    const Vec2 mid{box.c.x + h * n.x, box.c.y + h * n.y};
    const double out = (n.x * (rim.foot.x - mid.x) + n.y * (rim.foot.y - mid.y)) * rim.depth_mm /
                       (rim.height_mm + rim.depth_mm);
    if (!(out > 2.0 * on_line_mm)) continue;  // not facing the camera, or the lines merge
    const int bins = std::max(1, static_cast<int>(std::lround(half / mm_per_px)));
    hit.assign(static_cast<std::size_t>(bins), 0);
    for (const PlaneEdge& e : edges) {
      if (ax.group(e) != k % 2) continue;
      const Vec2 d{e.q.x - box.c.x, e.q.y - box.c.y};
      const double r = d.x * n.x + d.y * n.y - h - out;
      if (!(std::abs(r) <= on_line_mm)) continue;
      const double along = -d.x * n.y + d.y * n.x;
      const int b = static_cast<int>(std::floor((along + half) / (2.0 * half) * bins));
      if (b >= 0 && b < bins) hit[static_cast<std::size_t>(b)] = 1;
    }
    double covered = 0.0;
    for (const char c : hit) covered += c;
    sum += covered / bins;
  }
  return sum;
}

// Covariance of (cx, cy, theta): the residuals' scatter, each counted once per `correlation`
// neighbours, plus an error of every side's line (an offset and a turn: the edge model, the
// plate's face, a parcel's edge along part of it) carried through the fit.
// *bias: bias_share of the sides' offset and turn share of *cov, which the next frames share
// (TrayFitParams::side_offset_bias_share), so that the tracker does not average it down.
void box_covariance(const std::vector<PlaneEdge>& edges, const Fitted& f, const site::FleetAgv& agv,
                    double correlation, double side_sigma_mm, double bias_share,
                    std::array<double, 9>* cov, std::array<double, 9>* bias) {
  double inv[9];
  invert3(f.h, inv);  // succeeded in refine
  bias->fill(0.0);
  for (int i = 0; i < 9; ++i) (*cov)[static_cast<std::size_t>(i)] = f.s2 * correlation * inv[i];
  const Axes ax(f.box.theta, 0.25 * kPi);
  for (int k = 0; k < kSides; ++k) {
    // Two modes per side: the line shifted, and turned about the side's middle (its ends moved
    // by the same sigma in opposite directions).
    double s[2][3] = {{0.0, 0.0, 0.0}, {0.0, 0.0, 0.0}};
    const Vec2 n = ax.normal(k);
    const double half = half_along(k, agv);
    for (std::size_t i = 0; i < edges.size(); ++i) {
      if (f.side[i] != k || !(f.w[i] > 0.0)) continue;
      double j[3];
      jacobian(edges[i], f.box, ax, k, j);
      const Vec2 d{edges[i].q.x - f.box.c.x, edges[i].q.y - f.box.c.y};
      const double along = (-d.x * n.y + d.y * n.x) / half;
      for (int a = 0; a < 3; ++a) {
        s[0][a] += f.w[i] * j[a];
        s[1][a] += f.w[i] * j[a] * along;
      }
    }
    for (int mode = 0; mode < 2; ++mode) {
      double g[3];
      for (int a = 0; a < 3; ++a) {
        g[a] = inv[3 * a] * s[mode][0] + inv[3 * a + 1] * s[mode][1] + inv[3 * a + 2] * s[mode][2];
      }
      for (int a = 0; a < 3; ++a) {
        for (int b = 0; b < 3; ++b) {
          const double c = side_sigma_mm * side_sigma_mm * g[a] * g[b];
          (*cov)[static_cast<std::size_t>(3 * a + b)] += c;
          (*bias)[static_cast<std::size_t>(3 * a + b)] += bias_share * c;
        }
      }
    }
  }
}

// Lengths on the tray's plane for the fit's tolerances, from the window's scale.
struct FitScales {
  double bin_mm, band_mm, min_sigma_mm, max_size_err, on_line_mm;
};

// Headings and centres are searched, and kept, within the prediction's reach only: a parcel's
// lifted outline elsewhere can explain as much of the picture as the tray.
bool within_reach(const Box& b, double theta_pred, double reach_mm, double allowed) {
  const Vec2 nx = side_normal(0, theta_pred), ny = side_normal(1, theta_pred);
  return std::abs(b.c.x * nx.x + b.c.y * nx.y) <= reach_mm &&
         std::abs(b.c.x * ny.x + b.c.y * ny.y) <= reach_mm &&
         axis_distance(b.theta, theta_pred) <= allowed;
}

// Every hypothesis refined a little and scored by the outline it explains: a parcel's edge
// can out-vote a tray side it hides, but not the whole outline. Returns the best score (not
// positive when nothing fits) and its fit in *f.
double best_hypothesis(const std::vector<PlaneEdge>& edges, const site::FleetAgv& agv,
                       double theta_pred, const TrayWindow& win, const RimView& rim, double allowed,
                       const FitScales& sc, const TrayFitParams& p, Fitted* f) {
  Fitted trial;
  double best = -1.0;
  std::vector<double> peaks[2];
  TrayFix r;
  double mean_r[kSides];
  std::vector<double> done;
  for (const double coarse : orientations(edges, theta_pred, allowed)) {
    const double theta =
        sharpen(edges, agv, coarse, win.reach_mm, sc.bin_mm, p.class_tol_rad, peaks);
    // Neighbouring histogram peaks often sharpen to the same orientation: its hypotheses once.
    bool again = false;
    for (const double t : done) again = again || axis_distance(t, theta) < 0.5 * kSharpenStepRad;
    if (again) continue;
    done.push_back(theta);
    const Vec2 nx = side_normal(0, theta), ny = side_normal(1, theta);
    for (const double a : peaks[0]) {
      for (const double b : peaks[1]) {
        trial.box = {{a * nx.x + b * ny.x, a * nx.y + b * ny.y}, theta};
        if (!refine(edges, agv, sc.band_mm, sc.min_sigma_mm, p.class_tol_rad, kScoringIterations,
                    &trial)) {
          continue;
        }
        if (!within_reach(trial.box, theta_pred, win.reach_mm, allowed)) continue;
        side_stats(edges, trial, agv, win.mm_per_px, sc.on_line_mm, &r, mean_r);
        const auto seen_k = [&](int k) {
          return r.coverage[static_cast<std::size_t>(k)] >= p.min_side_coverage;
        };
        double score = 0.0;
        for (int k = 0; k < kSides; ++k) {
          score += seen_k(k) ? r.coverage[static_cast<std::size_t>(k)] : 0.0;
        }
        for (int axis = 0; axis < 2; ++axis) {
          const bool both = seen_k(axis) && seen_k(axis + 2);
          if (both && std::abs(mean_r[axis] + mean_r[axis + 2]) > sc.max_size_err) score -= 1.0;
        }
        score += kRimWeight * rim_coverage(edges, trial.box, agv, rim, sc.on_line_mm, win.mm_per_px,
                                           p.class_tol_rad);
        if (score > best) best = score, *f = trial;
      }
    }
  }
  return best;
}

// The refined fit's sides, size and heading checked, and the fix made of it.
bool accept_fit(const std::vector<PlaneEdge>& edges, const Fitted& f, const site::FleetAgv& agv,
                const Pose2& predicted, const TrayWindow& win, const FitScales& sc, double period,
                const TrayFitParams& p, TrayFix* out, std::string* why) {
  TrayFix r{};
  double mean_r[kSides];
  side_stats(edges, f, agv, win.mm_per_px, sc.on_line_mm, &r, mean_r);
  bool seen[kSides];
  for (int k = 0; k < kSides; ++k) {
    seen[k] = r.coverage[static_cast<std::size_t>(k)] >= p.min_side_coverage;
    r.sides_seen += seen[k] ? 1 : 0;
  }
  if (!(seen[0] || seen[2]) || !(seen[1] || seen[3]) || r.sides_seen < p.min_sides_seen) {
    out->refusal = TrayRefusal::kSidesHidden;
    return fail(why, fmt("too few tray sides seen (front/rear %.0f%%, left/right %.0f%% covered)",
                         100.0 * std::max(r.coverage[0], r.coverage[2]),
                         100.0 * std::max(r.coverage[1], r.coverage[3])));
  }
  for (int axis = 0; axis < 2; ++axis) {
    if (!seen[axis] || !seen[axis + 2]) continue;
    r.size_error_mm[axis] = mean_r[axis] + mean_r[axis + 2];
    if (std::abs(r.size_error_mm[axis]) > sc.max_size_err) {
      out->refusal = TrayRefusal::kSizeMismatch;
      return fail(why, fmt(axis == 0 ? "tray length off by %.1f mm (limit %.1f)"
                                     : "tray width off by %.1f mm (limit %.1f)",
                           r.size_error_mm[axis], sc.max_size_err));
    }
  }
  // The half-turn (quarter-turn for a square) nearest the prediction.
  const double theta =
      f.box.theta + period * std::round((predicted.theta_rad - f.box.theta) / period);
  r.heading_from_prediction_rad = std::abs(wrap_angle_rad(theta - predicted.theta_rad));
  if (r.heading_from_prediction_rad > period / 3.0) {
    out->refusal = TrayRefusal::kAmbiguous;
    return fail(why, fmt("tray heading %.0f deg from the prediction: ambiguous",
                         rad_to_deg(r.heading_from_prediction_rad)));
  }
  box_covariance(edges, f, agv, p.edge_correlation, p.side_offset_sigma_px * win.mm_per_px,
                 p.side_offset_bias_share, &r.fix.cov, &r.fix.cov_camera);
  r.fix.pose = {predicted.x_mm + f.box.c.x, predicted.y_mm + f.box.c.y, wrap_angle_rad(theta)};
  r.residual_mm = std::sqrt(f.s2);
  r.fix.residual_mm = r.residual_mm;
  r.fix.size_error_rel = 0.0;
  for (int axis = 0; axis < 2; ++axis) {
    const double len = axis == 0 ? agv.tray_length_mm : agv.tray_width_mm;
    if (std::abs(r.size_error_mm[axis] / len) > std::abs(r.fix.size_error_rel)) {
      r.fix.size_error_rel = r.size_error_mm[axis] / len;
    }
  }
  *out = r;
  return true;
}

}  // namespace tray_fit_detail

bool fit_tray(const cv::Mat& gray, const site::CeilingCamera& cam, const site::FleetAgv& agv,
              const Pose2& predicted, const std::array<double, 9>& predicted_cov,
              const TrayFitParams& p, TrayFix* out, std::string* why) {
  using namespace tray_fit_detail;
  if (!out) return fail(why, "no output");
  out->refusal = TrayRefusal::kBadInput;
  if (!check_input(gray, cam, agv, predicted, predicted_cov, p, why)) return false;
  const double pxx = predicted_cov[0], pyy = predicted_cov[4];
  const double pxy = 0.5 * (predicted_cov[1] + predicted_cov[3]);
  const double sigma_pos =
      std::sqrt(0.5 * (pxx + pyy) + std::sqrt(0.25 * (pxx - pyy) * (pxx - pyy) + pxy * pxy));
  const double sigma_theta = std::sqrt(predicted_cov[8]);
  out->refusal = TrayRefusal::kUncertain;
  if (sigma_pos > p.max_position_sigma_mm) {
    return fail(why, fmt("prediction's position sigma %.0f mm is beyond %.0f mm", sigma_pos,
                         p.max_position_sigma_mm));
  }
  // A square tray repeats every quarter turn, an oblong one every half turn.
  const bool square = std::abs(agv.tray_length_mm - agv.tray_width_mm) < 2.0 * p.max_size_error_mm;
  const double period = square ? 0.5 * kPi : kPi;
  if (p.sigma_window * sigma_theta > period / 3.0) {
    return fail(why, fmt("prediction's heading 3-sigma %.0f deg cannot resolve the tray's %.0f deg "
                         "symmetry",
                         rad_to_deg(p.sigma_window * sigma_theta), rad_to_deg(period)));
  }
  TrayWindow win;
  out->refusal = TrayRefusal::kOutOfView;
  if (!tray_window(cam, agv, predicted, sigma_pos, sigma_theta, p, &win, why)) return false;
  thread_local std::vector<PlaneEdge> edges;
  plane_edges(gray, cam, agv, predicted, win, p, &edges);

  const double allowed = std::min(p.sigma_window * sigma_theta + kHeadingSlackRad, 0.5 * kPi);
  const double bin_mm = std::max(1.0, 0.5 * win.mm_per_px);
  const FitScales sc{bin_mm, std::max(2.0 * win.mm_per_px, 4.0 * bin_mm), 0.05 * win.mm_per_px,
                     std::max(p.max_size_error_mm, p.max_size_error_px * win.mm_per_px),
                     p.on_line_px * win.mm_per_px};
  const RimView rim{{cam.t_site_cam_mm[0] - predicted.x_mm, cam.t_site_cam_mm[1] - predicted.y_mm},
                    cam.t_site_cam_mm[2] - agv.tray_height_mm,
                    p.rim_depth_mm};
  Fitted f;
  out->refusal = TrayRefusal::kNoOutline;
  const double best =
      best_hypothesis(edges, agv, predicted.theta_rad, win, rim, allowed, sc, p, &f);
  if (!(best > 0.0)) return fail(why, "no tray edges in the window");
  if (!refine(edges, agv, sc.band_mm, sc.min_sigma_mm, p.class_tol_rad, p.iterations, &f)) {
    return fail(why, "too few tray edge points to fit");
  }
  if (!within_reach(f.box, predicted.theta_rad, win.reach_mm, allowed)) {
    return fail(why, "the tray's outline lies beyond the prediction's reach");
  }
  return accept_fit(edges, f, agv, predicted, win, sc, period, p, out, why);
}

}  // namespace agv::overhead
