// Stage 3 of the pipeline (docs/design/vision.md), pose: edge points of the eight border lines
// (Prewitt gradients in bands around the detected square, classified by gradient direction, paper
// 001 fig. 7), robust line fits in the metric frame, heading and centre by the configured method,
// then the joint square fit whose normal equations also give the covariance (covariance.cpp).
#include <Eigen/Dense>
#include <algorithm>
#include <bit>
#include <cmath>
#include <cstdint>
#include <cstring>

#include "agv/common/order_statistic.hpp"
#include "square_fit.hpp"

namespace agv::vision {

namespace {

// A Prewitt kernel sums three neighbouring differences, so a step of C grey levels gives a
// gradient of 3 C: the edge threshold relative to the contrast is scaled by this.
constexpr double kPrewittStepGain = 3.0;
// Cap of the squared gradient threshold before it becomes an int: above the largest reachable
// Prewitt magnitude (2 * (3 * 255)^2 = 1.2e6), so the cap never changes a decision.
constexpr double kMaxGradientThreshold2 = 4.0e6;
// Pixels this close to the image border have no full Prewitt neighbourhood plus the one more
// pixel the non-maximum suppression compares with.
constexpr int kEdgeMarginPx = 2;
// Guards the band half-width against a line parallel to the iteration axis (never chosen: the
// major axis component is at least 0.707).
constexpr double kMinNormalComponent = 1e-6;
// Per-line robust fit: scale floor (mm; the subpixel edge noise on a sharp frame is ~0.02 mm, a
// smaller MAD would reject good points), IRLS iterations (converged after 3-4 in every frame of
// docs/design/accuracy.md), RANSAC inlier band (pixels).
constexpr double kLineMinSigmaMm = 0.02;
constexpr int kLineIrlsIterations = 4;
constexpr double kRansacInlierPx = 0.5;
// Floor of a line angle's variance (rad^2) so a perfect synthetic line gets a finite weight.
constexpr double kMinLineAngleVar = 1e-14;
// Joint fit: Gauss-Newton iterations per robust round, and the rounds (re-weightings) when
// robust; the round ends early once a step is below kConvergedStep (mm and rad). Gauss-Newton
// converges quadratically here: the steps of a round measure about 1e-3, 1e-7, 1e-15 on the cost
// recording, so a step under 1e-6 (a nanometre) leaves an error of about 1e-13, and the round
// ends after two steps instead of three (a third fewer normal-equation passes).
constexpr int kJointIterationsPerRound = 5;
constexpr int kJointRobustRounds = 3;
constexpr double kConvergedStep = 1e-6;
// Joint re-weighting: robust sigma from the MAD (kMadToSigma, order_statistic.hpp) with a floor
// in mm (a perfect frame would otherwise reject everything).
constexpr double kMinJointSigmaMm = 0.005;
// Two lines whose normals' determinant is below this are treated as parallel.
constexpr double kParallelDet = 1e-9;

// Joint model: outward normal of side k in the metric frame is at beta - k * 90 deg (the image
// shows the floor from above, and image y points down, so the clockwise order flips).
Vec2 side_normal_mm(double beta, int k) {
  const double a = beta - k * kPi / 2.0;
  return {std::cos(a), std::sin(a)};
}

Vec2 intersect(const Line2& a, const Line2& b, bool* ok) {
  const double det = a.nx * b.ny - a.ny * b.nx;
  *ok = std::abs(det) > kParallelDet;
  if (!*ok) return {};
  return {(a.d * b.ny - a.ny * b.d) / det, (a.nx * b.d - a.d * b.nx) / det};
}

}  // namespace

FixStatus SquareFit::pose(const cv::Mat& img, Vec2 c_px, double up, double contrast,
                          EdgePoints* pts, LandmarkFix* out, Vec2* c_mm, double* beta_out,
                          Eigen::Matrix3d* cov) {
  // 3a. Classified edge points in bands around the detected square.
  const double w_px = setup.geom.border_width_mm() / setup.mm_per_px;
  const double thr = setup.cfg.edge_threshold_rel * kPrewittStepGain * contrast;
  const int total = collect(img, c_px, up, setup.cfg.band_rel * w_px, thr, pts);
  pixels_.up_angle_px = up;
  if (setup.rows_covered(total) < setup.cfg.min_points_total) return FixStatus::kTooFewEdgePoints;

  // 3b. Metric points and one robust line per edge.
  std::array<LineFit, kNumLines> fits;
  const int used = fit_lines(pts, &fits);
  const auto& line_ok = pts->line_ok;
  std::array<bool, 4> side_ok{};
  for (int k = 0; k < 4; ++k)
    side_ok[k] = line_ok[k * 2] && (setup.outer_only || line_ok[k * 2 + 1]);
  out->sides_used = side_ok[0] + side_ok[1] + side_ok[2] + side_ok[3];
  const bool axis0 = side_ok[0] || side_ok[2], axis1 = side_ok[1] || side_ok[3];
  if (!axis0 || !axis1 || setup.rows_covered(used) < setup.cfg.min_points_total) {
    return FixStatus::kTooFewEdgePoints;
  }
  out->edge_points_used = used;

  // 3c. Heading: initial metric angle of side 0's normal from the pixel angle, then the
  // (weighted) mean of the line angles.
  const FloorProjector& mc = setup.metric_floor;
  Vec2 a0, a1;
  mc.pixel_to_vehicle(c_px, &a0);
  mc.pixel_to_vehicle(
      {c_px.x + kAngleProbePx * std::cos(up), c_px.y + kAngleProbePx * std::sin(up)}, &a1);
  const double beta0 = std::atan2(a1.y - a0.y, a1.x - a0.x);
  SquareModel m;
  m.beta = line_heading(*pts, fits, beta0);
  m.c = {a0.x, a0.y};

  // 3d. Centre by the configured method (the joint fit when a side is missing).
  PoseMethod method = setup.cfg.pose_method;
  if (out->sides_used != 4) method = PoseMethod::kJointSquareFit;
  if (method == PoseMethod::kPaperCornerA) {
    m.c = paper_corner_a_centre(*pts, m.beta);
  } else if (method == PoseMethod::kLineIntersections) {
    if (!intersections_centre(fits, &m.c)) return FixStatus::kTooFewEdgePoints;
  }

  // 3e. Joint fit (also used for the covariance of every method). Parameters: c_x, c_y, beta and,
  // when an axis has both sides, the shared half sizes: the metric frame's scale follows the
  // configured camera height, so a height error of a few millimetres makes the border look a
  // percent smaller or larger, and a fixed size would put every side off by that much.
  // Outer-only (tag family): no inner edge, so only the outer half size is free.
  const bool free_size = (side_ok[0] && side_ok[2]) || (side_ok[1] && side_ok[3]);
  const int n_params = !free_size ? 3 : setup.outer_only ? 4 : 5;
  m.h_out = setup.geom.outer_half_mm();
  m.h_in = setup.geom.inner_half_mm();
  if (method == PoseMethod::kJointSquareFit) m.c = joint_start_centre(*pts, fits, m);
  NormalEquations ne;
  if (!joint_fit(method, n_params, pts, &m, &ne)) return FixStatus::kTooFewEdgePoints;

  // 3f. Covariance, result, overlay geometry.
  *cov = fit_covariance(ne, n_params, setup.cfg);
  out->residual_rms_mm = ne.sum_w > 0 ? std::sqrt(ne.ssr / ne.sum_w) : 0.0;
  if (method == PoseMethod::kJointSquareFit && free_size) {
    out->outer_half_mm = m.h_out;
    if (!setup.outer_only) out->inner_half_mm = m.h_in;
  }
  *c_mm = m.c;
  *beta_out = m.beta;
  keep_overlay_geometry(m);
  return FixStatus::kOk;
}

// Converts every edge point to the metric frame (dropping those the camera model cannot map) and
// fits each line; a line counts when it has enough points and is long enough to carry an angle
// (half the inner side). Returns the number of points on the lines that count.
int SquareFit::fit_lines(EdgePoints* pts, std::array<LineFit, kNumLines>* fits) {
  const FloorProjector& mc = setup.metric_floor;
  pts->line_ok.fill(false);
  int used = 0;
  for (int l = 0; l < kNumLines; ++l) {
    auto& src = pts->px[static_cast<size_t>(l)];
    auto& dst = pts->mm[static_cast<size_t>(l)];
    dst.clear();
    size_t keep = 0;
    for (size_t i = 0; i < src.size(); ++i) {
      Vec2 q;
      if (mc.pixel_to_vehicle(src[i], &q)) {
        src[keep++] = src[i];
        dst.push_back(q);
      }
    }
    src.resize(keep);
    auto& w = pts->weights[static_cast<size_t>(l)];
    w.assign(dst.size(), 1.0);
    if (setup.rows_covered(static_cast<int>(dst.size())) < setup.cfg.min_points_per_line) continue;
    LineFit& fit = (*fits)[static_cast<size_t>(l)];
    bool ok;
    if (setup.cfg.robust) {
      ok = fit_line_robust(dst, setup.cfg.tukey_c, kLineMinSigmaMm, kLineIrlsIterations, w, &fit,
                           setup.cfg.ransac_iterations, kRansacInlierPx * setup.mm_per_px);
    } else {
      ok = fit_line_tls(dst, {}, &fit);
    }
    if (ok && fit.extent >= setup.geom.inner_half_mm()) {
      pts->line_ok[static_cast<size_t>(l)] = true;
      used += fit.n;
    }
  }
  return used;
}

// Line angles reduced to side 0's normal direction, averaged by the configured heading method.
double SquareFit::line_heading(const EdgePoints& pts, const std::array<LineFit, kNumLines>& fits,
                               double beta0) const {
  const auto& line_ok = pts.line_ok;
  std::array<double, kNumLines> ang{}, var_ang{}, k000{};
  for (int l = 0; l < kNumLines; ++l) {
    if (!line_ok[static_cast<size_t>(l)]) continue;
    const LineFit& f = fits[static_cast<size_t>(l)];
    const double nrm_angle = std::atan2(f.line.ny, f.line.nx);
    ang[static_cast<size_t>(l)] = reduce_angle_90(nrm_angle, beta0);
    var_ang[static_cast<size_t>(l)] = std::max(f.var_angle, kMinLineAngleVar);
    // Yang et al. eq. 11 with raw coordinates across the line.
    double sy2 = 0;
    for (const Vec2& p : pts.mm[static_cast<size_t>(l)]) {
      const double y = f.line.nx * p.x + f.line.ny * p.y;
      sy2 += y * y;
    }
    k000[static_cast<size_t>(l)] = weight_000(sy2, f.rms * f.rms * f.sum_w);
  }
  double s = 0, sw = 0;
  for (int l = 0; l < kNumLines; ++l) {
    if (!line_ok[static_cast<size_t>(l)]) continue;
    double w = 1.0;
    if (setup.cfg.heading_method == HeadingMethod::kWeighted000) w = k000[static_cast<size_t>(l)];
    if (setup.cfg.heading_method == HeadingMethod::kInverseVariance) {
      w = 1.0 / var_ang[static_cast<size_t>(l)];
    }
    s += w * (ang[static_cast<size_t>(l)] - beta0);
    sw += w;
  }
  return beta0 + (sw > 0 ? s / sw : 0.0);
}

// Li et al. eq. 8-11 in the frame aligned with the fine heading: corner A of the border's midline
// square from the extreme edge points of the left (side 3) and top (side 0) sides.
Vec2 SquareFit::paper_corner_a_centre(const EdgePoints& pts, double beta) const {
  const double cb = std::cos(beta), sb = std::sin(beta);
  auto to_al = [&](Vec2 p) { return Vec2{cb * p.x + sb * p.y, -sb * p.x + cb * p.y}; };
  // Aligned frame: side 0 normal = +x, side 3 normal = beta + 90 deg = +y.
  auto extreme = [&](int line, bool along_y, double* coord) {
    const auto& v = pts.mm[static_cast<size_t>(line)];
    double best = -1e300;
    for (const Vec2& p : v) {
      const Vec2 q = to_al(p);
      const double t = along_y ? q.y : q.x;
      if (t > best) {
        best = t;
        *coord = along_y ? q.x : q.y;
      }
    }
  };
  double x1 = 0, x2 = 0, y3 = 0, y4 = 0;
  extreme(0, true, &x1);                                // side 0 outer, point with max y -> its x
  extreme(1, true, &x2);                                // side 0 inner
  extreme(6, false, &y3);                               // side 3 outer, point with max x -> its y
  extreme(7, false, &y4);                               // side 3 inner
  const double xa = (x1 + x2) / 2, ya = (y3 + y4) / 2;  // eq. 8-9
  const double half_d = 0.5 * (setup.geom.outer_half_mm() + setup.geom.inner_half_mm());
  const Vec2 o_al{xa - half_d, ya - half_d};  // eq. 10-11 (rotation already removed)
  return {cb * o_al.x - sb * o_al.y, sb * o_al.x + cb * o_al.y};
}

// Centre as the mean of the outer and inner corners (intersections of neighbouring lines).
bool SquareFit::intersections_centre(const std::array<LineFit, kNumLines>& fits, Vec2* c) const {
  Vec2 sum{0, 0};
  int n = 0;
  for (int e = 0; e < 2; ++e) {
    for (int k = 0; k < 4; ++k) {
      bool ok;
      const Vec2 p = intersect(fits[static_cast<size_t>(k * 2 + e)].line,
                               fits[static_cast<size_t>(((k + 1) % 4) * 2 + e)].line, &ok);
      if (ok) {
        sum.x += p.x;
        sum.y += p.y;
        ++n;
      }
    }
  }
  if (n == 0) return false;
  *c = {sum.x / n, sum.y / n};
  return true;
}

// Start of the joint fit: the centre's coordinate along each axis from the line centroids,
// n_k . c = n_k . centroid - h (side k's normal is +-n_(k%2)); an axis without lines keeps m.c.
Vec2 SquareFit::joint_start_centre(const EdgePoints& pts,
                                   const std::array<LineFit, kNumLines>& fits,
                                   const SquareModel& m) const {
  double num[2] = {0, 0};
  int cnt[2] = {0, 0};
  for (int k = 0; k < 4; ++k) {
    const Vec2 n = side_normal_mm(m.beta, k);
    const double sgn = k < 2 ? 1.0 : -1.0;
    for (int e = 0; e < 2; ++e) {
      const int l = k * 2 + e;
      if (!pts.line_ok[static_cast<size_t>(l)]) continue;
      const Vec2 ctr = fits[static_cast<size_t>(l)].centroid;
      num[k % 2] += sgn * (ctr.x * n.x + ctr.y * n.y - (e == 0 ? m.h_out : m.h_in));
      ++cnt[k % 2];
    }
  }
  const Vec2 n0 = side_normal_mm(m.beta, 0), n1 = side_normal_mm(m.beta, 1);
  const double t0 = cnt[0] ? num[0] / cnt[0] : (m.c.x * n0.x + m.c.y * n0.y);
  const double t1 = cnt[1] ? num[1] / cnt[1] : (m.c.x * n1.x + m.c.y * n1.y);
  return {t0 * n0.x + t1 * n1.x, t0 * n0.y + t1 * n1.y};
}

// Gauss-Newton on the joint square model (the non-joint methods only accumulate the normal
// equations at their own centre and heading, for the covariance). Joint robust rounds: after the
// first round, every point of every fitted line (also those the per-line fit rejected) is
// re-weighted (Tukey) by its residual to the joint model with one global scale, so an occluder
// edge that won a single line's vote is rejected by the square. False when a step is not finite.
bool SquareFit::joint_fit(PoseMethod method, int n_params, EdgePoints* pts, SquareModel* m,
                          NormalEquations* ne) {
  const bool joint = method == PoseMethod::kJointSquareFit;
  const int rounds = joint && setup.cfg.robust ? kJointRobustRounds : 1;
  const int iters = joint ? kJointIterationsPerRound * rounds : 1;
  for (int it = 0; it < iters; ++it) {
    if (joint && setup.cfg.robust && it > 0 && it % kJointIterationsPerRound == 0)
      reweight_joint(*m, pts);
    accumulate_normal_equations(*pts, *m, ne);
    if (!joint) break;
    Eigen::Matrix<double, 5, 1> delta = Eigen::Matrix<double, 5, 1>::Zero();
    if (n_params == 5) {
      delta = ne->jtj.ldlt().solve(-ne->jtr);
    } else if (n_params == 4) {
      delta.head<4>() = ne->jtj.topLeftCorner<4, 4>().ldlt().solve(-ne->jtr.head<4>());
    } else {
      delta.head<3>() = ne->jtj.topLeftCorner<3, 3>().ldlt().solve(-ne->jtr.head<3>());
    }
    if (!delta.allFinite()) return false;
    m->c.x += delta(0);
    m->c.y += delta(1);
    m->beta += delta(2);
    if (n_params >= 4) m->h_out += delta(3);
    if (n_params == 5) m->h_in += delta(4);
    if (delta.head(3).norm() < kConvergedStep && (it + 1) % kJointIterationsPerRound != 0) {
      it += kJointIterationsPerRound - 1 - it % kJointIterationsPerRound;  // next round
    }
  }
  return true;
}

void SquareFit::reweight_joint(const SquareModel& m, EdgePoints* pts) {
  const auto& line_ok = pts->line_ok;
  residual_buf.clear();
  for (int k = 0; k < 4; ++k) {
    const Vec2 n = side_normal_mm(m.beta, k);
    for (int e = 0; e < 2; ++e) {
      const int l = k * 2 + e;
      if (!line_ok[static_cast<size_t>(l)]) continue;
      for (const Vec2& p : pts->mm[static_cast<size_t>(l)]) {
        residual_buf.push_back(
            std::abs(n.x * (p.x - m.c.x) + n.y * (p.y - m.c.y) - (e == 0 ? m.h_out : m.h_in)));
      }
    }
  }
  scratch_buf = residual_buf;
  const auto mid = scratch_buf.size() / 2;
  const double sigma = std::max(kMinJointSigmaMm, kMadToSigma * select_kth(scratch_buf, mid));
  const double cut = setup.cfg.tukey_c * sigma;
  size_t idx = 0;
  for (int l = 0; l < kNumLines; ++l) {
    if (!line_ok[static_cast<size_t>(l)]) continue;
    for (double& wi : pts->weights[static_cast<size_t>(l)]) {
      const double u = residual_buf[idx++] / cut;
      wi = u < 1.0 ? (1.0 - u * u) * (1.0 - u * u) : 0.0;
    }
  }
}

// Normal equations of all five parameters. Fixed size: no heap, and the per-point work is six
// sums per line (the Jacobian row is constant along a line except for its angle term).
void SquareFit::accumulate_normal_equations(const EdgePoints& pts, const SquareModel& m,
                                            NormalEquations* ne) const {
  ne->jtj.setZero();
  ne->jtr.setZero();
  ne->ssr = 0;
  ne->sum_w = 0;
  for (int k = 0; k < 4; ++k) {
    const Vec2 n = side_normal_mm(m.beta, k);
    const Vec2 dn{-n.y, n.x};  // d n / d beta
    for (int e = 0; e < 2; ++e) {
      const int l = k * 2 + e;
      if (!pts.line_ok[static_cast<size_t>(l)]) continue;
      const auto& v = pts.mm[static_cast<size_t>(l)];
      const auto& w = pts.weights[static_cast<size_t>(l)];
      const double h = e == 0 ? m.h_out : m.h_in;
      // Row of point i: (-n.x, -n.y, a_i, -[outer], -[inner]) with a_i = dn . (p_i - c).
      double s_w = 0, s_a = 0, s_aa = 0, s_r = 0, s_ar = 0, s_rr = 0;
      for (size_t i = 0; i < v.size(); ++i) {
        const double wi = w[i];
        if (!(wi > 0)) continue;
        const double dx = v[i].x - m.c.x, dy = v[i].y - m.c.y;
        const double r = n.x * dx + n.y * dy - h;
        const double a = dn.x * dx + dn.y * dy;
        s_w += wi;
        s_a += wi * a;
        s_aa += wi * a * a;
        s_r += wi * r;
        s_ar += wi * a * r;
        s_rr += wi * r * r;
      }
      Eigen::Matrix<double, 5, 1> u;
      u << -n.x, -n.y, 0.0, e == 0 ? -1.0 : 0.0, e == 1 ? -1.0 : 0.0;
      ne->jtj.noalias() += s_w * u * u.transpose();
      for (int q = 0; q < 5; ++q) {
        ne->jtj(q, 2) += u(q) * s_a;
        ne->jtj(2, q) += u(q) * s_a;
      }
      ne->jtj(2, 2) += s_aa;
      ne->jtr += s_r * u;
      ne->jtr(2) += s_ar;
      ne->ssr += s_rr;
      ne->sum_w += s_w;
    }
  }
}

// Corners and centre of the fitted square in pixels, for draw_overlay.
void SquareFit::keep_overlay_geometry(const SquareModel& m) {
  const FloorProjector& mc = setup.metric_floor;
  for (int e = 0; e < 2; ++e) {
    const double h = e == 0 ? m.h_out : m.h_in;
    for (int k = 0; k < 4; ++k) {
      const Vec2 n = side_normal_mm(m.beta, k), n2 = side_normal_mm(m.beta, k + 1);
      Vec2 px;
      mc.vehicle_to_pixel({m.c.x + h * (n.x + n2.x), m.c.y + h * (n.y + n2.y)}, &px);
      pixels_.corners_px[static_cast<size_t>(e * 4 + k)] = px;
    }
  }
  mc.vehicle_to_pixel(m.c, &pixels_.centre_px);
}

// Collects classified, non-maximum-suppressed, optionally subpixel edge points of the 8 border
// lines (outer and inner edge of each side). Only pixels inside a band of +-band px around each
// predicted line are visited (rasterised strip), and a pixel is kept for a line only when its
// gradient class (Li et al. fig. 7: direction within the tolerance of the line's normal, outward
// on outer edges, inward on inner edges) is that line's class.
int SquareFit::collect(const cv::Mat& img, Vec2 c, double up, double band, double thr,
                       EdgePoints* pts) {
  const double h_out = setup.geom.outer_half_mm() / setup.mm_per_px;
  const double h_in = setup.geom.inner_half_mm() / setup.mm_per_px;
  const double tan_tol = std::tan(deg_to_rad(setup.cfg.edge_direction_tol_deg));
  // Squared-magnitude threshold in integers (Prewitt sums are exact): a pixel passes when
  // gx^2 + gy^2 >= thr^2.
  const int thr2_int = static_cast<int>(std::ceil(std::min(thr * thr, kMaxGradientThreshold2)));
  int total = 0;
  for (auto& v : pts->px) v.clear();
  for (int k = 0; k < 4; ++k) {
    const double na = up + k * kPi / 2;
    const Vec2 nk{std::cos(na), std::sin(na)};
    for (int e = 0; e < (setup.outer_only ? 1 : 2); ++e) {
      const double h = e == 0 ? h_out : h_in;
      // Expected gradient direction: outward on the outer edge, inward on the inner edge.
      const Vec2 g_dir = e == 0 ? nk : Vec2{-nk.x, -nk.y};
      total += collect_line(img, c, nk, h, g_dir, band, thr2_int, tan_tol,
                            &pts->px[static_cast<size_t>(k * 2 + e)]);
    }
  }
  return total;
}

// One line of collect(): the line is at distance h (px) from c along normal nk.
int SquareFit::collect_line(const cv::Mat& img, Vec2 c, Vec2 nk, double h, Vec2 g_dir, double band,
                            int thr2_int, double tan_tol, std::vector<Vec2>* dst) {
  const std::uint8_t* base = img.data;
  const std::ptrdiff_t step = static_cast<std::ptrdiff_t>(img.step[0]);
  const int x_lo = kEdgeMarginPx, y_lo = kEdgeMarginPx;
  const int x_hi = img.cols - 1 - kEdgeMarginPx, y_hi = img.rows - 1 - kEdgeMarginPx;
  // A strip along a row may be read up to 15 bytes past its end (strip_gradients): its last line
  // is at most row rows - 2 (y_hi + 1), so that lands in the next row when a row has 16 bytes.
  const bool read_past_end = img.cols >= 16;
  const Vec2 tk{-nk.y, nk.x};
  const double t_max = h - band;  // stay away from the corners
  if (t_max <= 0) return 0;
  const Vec2 m{c.x + nk.x * h, c.y + nk.y * h};  // foot of the line
  // Iterate along the pixel axis closest to the line direction.
  const bool by_rows = std::abs(tk.y) >= std::abs(tk.x);
  const double ta = by_rows ? tk.y : tk.x;        // line direction, major component
  const double na_major = by_rows ? nk.x : nk.y;  // normal, across component
  const double m_major = by_rows ? m.y : m.x;
  const double m_minor = by_rows ? m.x : m.y;
  const double t_minor = by_rows ? tk.x : tk.y;
  const double q0 = m_major - std::abs(ta) * t_max, q1 = m_major + std::abs(ta) * t_max;
  // Rows (columns) on the image's grid of the row step, so a slightly different detection
  // (tracked or full search) samples the same rows.
  const int row_step = std::max(1, setup.cfg.edge_row_step);
  int i0 = std::max(static_cast<int>(std::ceil(q0)), by_rows ? y_lo : x_lo);
  i0 += (row_step - i0 % row_step) % row_step;  // i0 >= kEdgeMarginPx > 0
  const int i1 = std::min(static_cast<int>(std::floor(q1)), by_rows ? y_hi : x_hi);
  const double half_w = band / std::max(std::abs(na_major), kMinNormalComponent);
  const int sx = by_rows ? 1 : 0, sy = by_rows ? 0 : 1;  // step across the line
  for (int i = i0; i <= i1; i += row_step) {
    const double tau = (i - m_major) / ta;
    const double centre_minor = m_minor + tau * t_minor;
    const int j0 =
        std::max(static_cast<int>(std::ceil(centre_minor - half_w)), by_rows ? x_lo : y_lo);
    const int j1 =
        std::min(static_cast<int>(std::floor(centre_minor + half_w)), by_rows ? x_hi : y_hi);
    if (j1 < j0) continue;
    // Gradients of the strip's pixels and of one more on each side (the non-maximum
    // suppression compares each pixel with its two neighbours along j, which is the pixel
    // axis closest to the line's normal).
    const int n = j1 - j0 + 3;
    const std::ptrdiff_t dj = by_rows ? 1 : step, di = by_rows ? step : 1;
    const std::uint8_t* p = base + (by_rows ? static_cast<std::ptrdiff_t>(i) * step + (j0 - 2)
                                            : static_cast<std::ptrdiff_t>(j0 - 2) * step + i);
    strip_gradients(p, dj, di, n, thr2_int, read_past_end, &strip);
    const std::int16_t* gx = by_rows ? strip.g_j.data() : strip.g_i.data();
    const std::int16_t* gy = by_rows ? strip.g_i.data() : strip.g_j.data();
    // Gradient component along the expected direction, only where the non-maximum suppression
    // needs it.
    auto along_at = [&](int q) { return gx[q] * g_dir.x + gy[q] * g_dir.y; };
    // Eight screened pixels per 64-bit word, visited in order (the same points in the same order
    // as a pixel-by-pixel loop); q runs over 1 .. n - 2, which have both neighbours.
    static_assert(std::endian::native == std::endian::little, "byte w0 + b is bits 8b .. 8b + 7");
    for (int w0 = 0; w0 + 1 < n; w0 += 8) {
      std::uint64_t word;
      std::memcpy(&word, strip.strong.data() + w0, sizeof word);
      if (w0 == 0) word &= ~std::uint64_t{0xff};
      for (; word != 0; word &= word - 1) {
        const int q = w0 + std::countr_zero(word) / 8;
        if (q + 1 >= n) break;
        if (!gradient_within(gx[q], gy[q], g_dir, tan_tol)) continue;
        const double along = along_at(q);
        const double em = along_at(q - 1);
        const double ep = along_at(q + 1);
        if (!(along >= em && along > ep)) continue;
        double off = 0;
        if (setup.cfg.subpixel) {
          const double den = em - 2 * along + ep;
          if (den < 0) off = std::clamp(0.5 * (em - ep) / den, -0.5, 0.5);
        }
        const int j = j0 - 1 + q;
        const int x = by_rows ? j : i, y = by_rows ? i : j;
        dst->push_back({x + off * sx, y + off * sy});
      }
    }
  }
  return static_cast<int>(dst->size());
}

}  // namespace agv::vision
