// Sub-pixel outer edges, lines, corners and cells of a tag's black square
// (tag_detect_internal.hpp).
#include <algorithm>
#include <cmath>
#include <opencv2/imgproc.hpp>
#include <vector>

#include "tag_detect_internal.hpp"

namespace agv::overhead::detect_detail {

namespace {

// Edge points stay this share of a side away from its corners, where the neighbouring side's
// edge and the blur of the corner bend the profile.
constexpr double kSideMargin = 0.12;
// Profile steps along a normal (px) and the half width of the area-method window around the
// strongest step (px): the window must reach the flat black border and white margin on each side,
// inside a cell (5 px on a 40 px tag).
constexpr double kProfileStep = 0.25;
constexpr double kSearchStep = 0.5;  // the coarse profile that finds the step
constexpr double kAreaHalfPx = 2.0;
constexpr double kLevelPx = 0.5;  // the levels are the means over this much at each end
// A side needs this share of its sampled points on its line.
constexpr double kMinInlierShare = 0.5;
constexpr int kMinPoints = 6;
// Outlier rejection: points beyond max(kOutlierSigmas * rms, kOutlierFloorPx) are dropped.
constexpr double kOutlierSigmas = 2.5;
constexpr double kOutlierFloorPx = 0.3;
// Before the first fit, points further than this from the side's median offset are dropped: a
// wide search band also crosses other dark-to-bright steps (data cells, the tray's edge), while
// a prediction's turn moves the true edge by less than this along a side.
constexpr double kMedianGatePx = 2.5;
constexpr int kFitPasses = 4;
// Along one side the black border and the white margin keep their levels; a point whose dark or
// bright level is further than this share of the side's contrast from the side's medians is on
// something else (a box over the corner, the box's outline against the margin).
constexpr double kLevelTolerance = 0.15;
// Cells: samples at the centre and four points this share of a cell from it.
constexpr double kCellOffset = 0.2;

struct Line {
  Vec2 c;  // centroid of its points
  Vec2 d;  // unit direction
  double rms = 0.0;
  // Variance of the line's normal offset at arc position s from c: v0 + v1 * s^2.
  double v0 = 0.0, v1 = 0.0;
};

double cross(Vec2 a, Vec2 b) { return a.x * b.y - a.y * b.x; }

// Position (relative to 0, along the normal) of the outer edge between -band and +band: the
// strongest dark-to-bright step, located by the area method (the integral of the profile between
// two flat levels fixes the step's position without pixel locking).
struct EdgeHit {
  double s = 0.0;                   // position along the normal (px)
  double dark = 0.0, bright = 0.0;  // the levels either side
};

bool edge_along(const cv::Mat& g, Vec2 p, Vec2 n, double band, double min_step,
                std::vector<double>* profile, EdgeHit* hit) {
  auto at = [&](double s, double* v) {
    return sample_bilinear(g, p.x + s * n.x, p.y + s * n.y, v);
  };
  // Coarse profile for the strongest step (1 px differences), fine profile for its position.
  std::vector<double>& prof = *profile;
  const int m = static_cast<int>(std::ceil((band + 0.5) / kSearchStep));
  prof.assign(static_cast<std::size_t>(2 * m + 1), 0.0);
  for (int i = -m; i <= m; ++i) {
    if (!at(i * kSearchStep, &prof[static_cast<std::size_t>(i + m)])) return false;
  }
  const int lim = static_cast<int>(std::floor(band / kSearchStep));
  int best = 0;
  double best_g = -1e9;
  for (int i = -lim; i <= lim; ++i) {
    const int a = std::max(i - 1, -m), b = std::min(i + 1, m);
    const double gi = prof[static_cast<std::size_t>(b + m)] - prof[static_cast<std::size_t>(a + m)];
    if (gi > best_g) best_g = gi, best = i;
  }
  const double centre = best * kSearchStep;
  const int w = static_cast<int>(std::lround(kAreaHalfPx / kProfileStep));
  const int lv = static_cast<int>(std::lround(kLevelPx / kProfileStep));
  std::array<double, 64> fine{};
  static_assert(2 * kAreaHalfPx / kProfileStep + 1 <= 64, "fine profile buffer");
  for (int i = -w; i <= w; ++i) {
    if (!at(centre + i * kProfileStep, &fine[static_cast<std::size_t>(i + w)])) return false;
  }
  double dark = 0, bright = 0, area = 0;
  for (int k = 0; k <= lv; ++k) {
    dark += fine[static_cast<std::size_t>(k)];
    bright += fine[static_cast<std::size_t>(2 * w - k)];
  }
  dark /= lv + 1;
  bright /= lv + 1;
  if (!(bright - dark >= min_step)) return false;
  for (int i = 0; i < 2 * w; ++i) {
    area += 0.5 * (fine[static_cast<std::size_t>(i)] + fine[static_cast<std::size_t>(i + 1)]);
  }
  area *= kProfileStep;
  const double a = centre - w * kProfileStep, b = centre + w * kProfileStep;
  const double e = (bright * b - dark * a - area) / (bright - dark);
  if (!(e > a && e < b) || std::abs(e) > band) return false;
  *hit = {e, dark, bright};
  return true;
}

// Total least squares through pts, refitted without outliers once.
bool fit_line(std::vector<Vec2>* pts, std::size_t min_pts, Line* out) {
  for (int pass = 0; pass < kFitPasses; ++pass) {
    if (pts->size() < min_pts) return false;
    Vec2 c{0, 0};
    for (const Vec2& p : *pts) c.x += p.x, c.y += p.y;
    const double n = static_cast<double>(pts->size());
    c.x /= n;
    c.y /= n;
    double sxx = 0, sxy = 0, syy = 0;
    for (const Vec2& p : *pts) {
      const double dx = p.x - c.x, dy = p.y - c.y;
      sxx += dx * dx, sxy += dx * dy, syy += dy * dy;
    }
    const double ang = 0.5 * std::atan2(2.0 * sxy, sxx - syy);
    const Vec2 d{std::cos(ang), std::sin(ang)};
    double ss = 0, sss = 0;
    for (const Vec2& p : *pts) {
      const double r = cross(d, {p.x - c.x, p.y - c.y});
      const double s = d.x * (p.x - c.x) + d.y * (p.y - c.y);
      ss += r * r;
      sss += s * s;
    }
    const double dof = std::max(n - 2.0, 1.0);
    const double rms = std::sqrt(ss / dof);
    const double cut = std::max(kOutlierSigmas * rms, kOutlierFloorPx);
    const std::size_t before = pts->size();
    if (pass < kFitPasses - 1) {
      pts->erase(std::remove_if(pts->begin(), pts->end(),
                                [&](const Vec2& p) {
                                  return std::abs(cross(d, {p.x - c.x, p.y - c.y})) > cut;
                                }),
                 pts->end());
    }
    if (pts->size() == before || pass == kFitPasses - 1) {
      if (!(sss > 0.0)) return false;
      *out = {c, d, rms, rms * rms / n, rms * rms / sss};
      return true;
    }
  }
  return false;
}

double median_of(std::vector<double>* v) {
  const auto mid = v->begin() + static_cast<std::ptrdiff_t>(v->size() / 2);
  std::nth_element(v->begin(), mid, v->end());
  return *mid;
}

// Keeps the points whose levels match the side's and whose offset along the normal is near the
// side's median offset.
void gate_by_levels(std::vector<Vec2>* pts, std::vector<EdgeHit>* hits) {
  if (hits->empty()) return;
  std::vector<double> v(hits->size());
  auto med = [&](double EdgeHit::*f) {
    for (std::size_t i = 0; i < hits->size(); ++i) v[i] = (*hits)[i].*f;
    return median_of(&v);
  };
  const double dark = med(&EdgeHit::dark), bright = med(&EdgeHit::bright), s = med(&EdgeHit::s);
  const double tol = kLevelTolerance * (bright - dark);
  std::size_t keep = 0;
  for (std::size_t i = 0; i < pts->size(); ++i) {
    const EdgeHit& h = (*hits)[i];
    if (std::abs(h.dark - dark) <= tol && std::abs(h.bright - bright) <= tol &&
        std::abs(h.s - s) <= kMedianGatePx) {
      (*pts)[keep++] = (*pts)[i];
    }
  }
  pts->resize(keep);
}

bool intersect(const Line& a, const Line& b, Vec2* p) {
  const double den = cross(a.d, b.d);
  if (std::abs(den) < 1e-6) return false;
  const double t = cross({b.c.x - a.c.x, b.c.y - a.c.y}, b.d) / den;
  *p = {a.c.x + t * a.d.x, a.c.y + t * a.d.y};
  return true;
}

// Covariance trace / 2 of the corner p where lines a and b meet (each line's offset variance at p).
double corner_var(const Line& a, const Line& b, Vec2 p) {
  const double sa = a.d.x * (p.x - a.c.x) + a.d.y * (p.y - a.c.y);
  const double sb = b.d.x * (p.x - b.c.x) + b.d.y * (p.y - b.c.y);
  const double va = a.v0 + a.v1 * sa * sa, vb = b.v0 + b.v1 * sb * sb;
  // Normals na, nb; x solves na.x = ca, nb.x = cb: dx = N^-1 dc, so trace = (va + vb) / sin^2.
  const double s = cross(a.d, b.d);
  return 0.5 * (va + vb) / (s * s);
}

}  // namespace

bool sample_bilinear(const cv::Mat& g, double x, double y, double* v) {
  if (!(x >= 0.0 && y >= 0.0 && x <= g.cols - 1.0 && y <= g.rows - 1.0)) return false;
  const int x0 = std::min(static_cast<int>(x), g.cols - 2),
            y0 = std::min(static_cast<int>(y), g.rows - 2);
  if (x0 < 0 || y0 < 0) return false;
  const double fx = x - x0, fy = y - y0;
  const std::uint8_t* r0 = g.ptr<std::uint8_t>(y0) + x0;
  const std::uint8_t* r1 = g.ptr<std::uint8_t>(y0 + 1) + x0;
  *v = (1 - fy) * ((1 - fx) * r0[0] + fx * r0[1]) + fy * ((1 - fx) * r1[0] + fx * r1[1]);
  return true;
}

bool refine_square(const cv::Mat& gray, const std::array<Vec2, 4>& guess, const RefineParams& rp,
                   Square* out) {
  Vec2 centre{0, 0};
  for (const Vec2& c : guess) centre.x += 0.25 * c.x, centre.y += 0.25 * c.y;
  std::array<Line, 4> lines{};
  double worst_rms = 0.0;
  std::vector<Vec2> pts;
  std::vector<double> profile;
  std::vector<EdgeHit> hits;
  for (std::size_t k = 0; k < 4; ++k) {
    const Vec2 a = guess[k], b = guess[(k + 1) % 4];
    const double len = std::hypot(b.x - a.x, b.y - a.y);
    if (!(len > 4.0)) return false;
    const Vec2 d{(b.x - a.x) / len, (b.y - a.y) / len};
    Vec2 n{d.y, -d.x};
    const Vec2 mid{0.5 * (a.x + b.x), 0.5 * (a.y + b.y)};
    if (n.x * (mid.x - centre.x) + n.y * (mid.y - centre.y) < 0) n = {-n.x, -n.y};
    const int count = std::max(kMinPoints, static_cast<int>(len * (1.0 - 2.0 * kSideMargin) /
                                                            std::max(rp.spacing_px, 0.25)));
    pts.clear();
    hits.clear();
    for (int i = 0; i < count; ++i) {
      const double t = kSideMargin + (1.0 - 2.0 * kSideMargin) * (i + 0.5) / count;
      const Vec2 p{a.x + t * (b.x - a.x), a.y + t * (b.y - a.y)};
      EdgeHit h;
      if (edge_along(gray, p, n, rp.band_px, rp.min_step, &profile, &h)) {
        pts.push_back({p.x + h.s * n.x, p.y + h.s * n.y});
        hits.push_back(h);
      }
    }
    gate_by_levels(&pts, &hits);
    const auto need = static_cast<std::size_t>(
        std::max(kMinPoints, static_cast<int>(std::ceil(kMinInlierShare * count))));
    if (!fit_line(&pts, need, &lines[k]) || lines[k].rms > rp.max_rms_px) return false;
    // Edge points must reach both ends of the sampled span: a corner hidden by a box is otherwise
    // extrapolated from what is left of its sides, and the box's own outline can pass as a side.
    double lo = 1.0, hi = 0.0;
    for (const Vec2& p : pts) {
      const double u = (d.x * (p.x - a.x) + d.y * (p.y - a.y)) / len;
      lo = std::min(lo, u), hi = std::max(hi, u);
    }
    if (lo > kSideMargin + rp.max_end_gap || hi < 1.0 - kSideMargin - rp.max_end_gap) return false;
    worst_rms = std::max(worst_rms, lines[k].rms);
  }
  double var_sum = 0.0;
  for (std::size_t k = 0; k < 4; ++k) {
    const Line& prev = lines[(k + 3) % 4];
    if (!intersect(prev, lines[k], &out->corners[k])) return false;
    const Vec2& c = out->corners[k];
    if (!(c.x >= 0 && c.y >= 0 && c.x <= gray.cols - 1.0 && c.y <= gray.rows - 1.0)) return false;
    var_sum += corner_var(prev, lines[k], c);
  }
  out->corner_sigma_px = std::sqrt(var_sum / 4.0);
  out->edge_rms_px = worst_rms;
  return true;
}

bool read_cells(const cv::Mat& gray, const std::array<Vec2, 4>& corners, Cells* out) {
  // Page cells: the black square spans 0..8 cells, TL (0, 0), TR (8, 0), BR (8, 8), BL (0, 8).
  const std::array<cv::Point2f, 4> src{cv::Point2f(0, 0), cv::Point2f(8, 0), cv::Point2f(8, 8),
                                       cv::Point2f(0, 8)};
  std::array<cv::Point2f, 4> dst;
  for (std::size_t k = 0; k < 4; ++k) {
    if (!std::isfinite(corners[k].x) || !std::isfinite(corners[k].y)) return false;
    dst[k] = cv::Point2f(static_cast<float>(corners[k].x), static_cast<float>(corners[k].y));
  }
  const cv::Matx33d h = cv::getPerspectiveTransform(src.data(), dst.data());
  auto cell = [&](double u, double v, double* g) {  // cell centre (u, v) in cells
    double sum = 0;
    const double o = kCellOffset;
    for (const Vec2 d : {Vec2{0, 0}, Vec2{o, 0}, Vec2{-o, 0}, Vec2{0, o}, Vec2{0, -o}}) {
      const double x = u + d.x, y = v + d.y;
      const double w = h(2, 0) * x + h(2, 1) * y + h(2, 2);
      if (!(std::abs(w) > 1e-9)) return false;
      double val = 0;
      if (!sample_bilinear(gray, (h(0, 0) * x + h(0, 1) * y + h(0, 2)) / w,
                           (h(1, 0) * x + h(1, 1) * y + h(1, 2)) / w, &val)) {
        return false;
      }
      sum += val;
    }
    *g = sum / 5.0;
    return true;
  };
  std::vector<double> border, margin;
  double g = 0;
  for (int i = 0; i < 8; ++i) {
    const double c = i + 0.5;
    for (const Vec2 p : {Vec2{c, 0.5}, Vec2{c, 7.5}, Vec2{0.5, c}, Vec2{7.5, c}}) {
      if (!cell(p.x, p.y, &g)) return false;
      border.push_back(g);
    }
    for (const Vec2 p : {Vec2{c, -0.5}, Vec2{c, 8.5}, Vec2{-0.5, c}, Vec2{8.5, c}}) {
      if (cell(p.x, p.y, &g)) margin.push_back(g);
    }
  }
  if (margin.size() < border.size() / 2) return false;
  auto median = [](std::vector<double>* v) {
    const auto mid = v->begin() + static_cast<std::ptrdiff_t>(v->size() / 2);
    std::nth_element(v->begin(), mid, v->end());
    return *mid;
  };
  const double dark = median(&border), white = median(&margin);
  const double threshold = 0.5 * (dark + white);
  std::uint64_t code = 0;
  for (int r = 0; r < 6; ++r) {
    for (int c = 0; c < 6; ++c) {
      if (!cell(c + 1.5, r + 1.5, &g)) return false;
      code = (code << 1) | (g > threshold ? 1U : 0U);
    }
  }
  out->code = code;
  out->contrast = white - dark;
  return true;
}

}  // namespace agv::overhead::detect_detail
