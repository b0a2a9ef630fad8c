// Vehicle calibration by nonlinear least squares (Ceres). Model: calib_vehicle.hpp.
#include "calib_vehicle.hpp"

#include <ceres/ceres.h>

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <map>
#include <memory>

#include "agv/vision/edges.hpp"

namespace agv::desk::vcal {

namespace {

constexpr int kMount = 6;  // offset_x_mm, offset_y_mm, yaw_rad, height_mm, roll_rad, pitch_rad
constexpr int kOdo = 4;    // speed_scale, yaw_rate_scale, yaw_rate_bias_radps, yaw_per_metre_rad
constexpr int kNumGlobal = kMount + kOdo + 1;
constexpr double kInf = std::numeric_limits<double>::infinity();

inline double as_double(double x) { return x; }
template <typename T, int N>
double as_double(const ceres::Jet<T, N>& j) {
  return j.a;
}

// Odometry on the odometry clock, seconds relative to a reference (for precision).
struct OdomTable {
  std::vector<double> t;  // stamps T_k, s
  std::vector<double> v_mmps, w;
  double quarter_track_sq_mm2 = 0.0;  // track^2 / 4: the unequal wheels' speed term
};

// Relative motion (dx, dy, dtheta) in the frame at camera time a, from a to b (b >= a), with
// the rates of calib_vehicle.hpp.
template <typename T>
void integrate(const OdomTable& od, double a_s, double b_s, const T* odo, const T* dt, T* rel) {
  const T a = T(a_s) + dt[0], b = T(b_s) + dt[0];
  T x(0.0), y(0.0), th(0.0);
  // First sample whose interval (T_{k-1}, T_k] can overlap [a, b].
  const double a_d = a_s + as_double(dt[0]) - 1e-3;  // generous margin
  size_t k = static_cast<size_t>(std::lower_bound(od.t.begin(), od.t.end(), a_d) - od.t.begin());
  if (k == 0) k = 1;
  for (; k < od.t.size(); ++k) {
    const T lo_k(od.t[k - 1]), hi_k(od.t[k]);
    if (!(lo_k < b)) break;
    const T lo = a > lo_k ? a : lo_k;
    const T hi = b < hi_k ? b : hi_k;
    if (!(hi > lo)) continue;
    const T h = hi - lo;
    const T dth = (odo[1] * od.w[k] + odo[2] + odo[3] * (1e-3 * od.v_mmps[k])) * h;
    const T mid = th + 0.5 * dth;
    const T ds = (odo[0] * od.v_mmps[k] + odo[3] * (1e-3 * od.quarter_track_sq_mm2) * od.w[k]) * h;
    x += ds * cos(mid);
    y += ds * sin(mid);
    th += dth;
  }
  rel[0] = x;
  rel[1] = y;
  rel[2] = th;
}

template <typename T>
void rotation_vc(const T* m, T r[9]) {
  const T cy = cos(m[2]), sy = sin(m[2]), cp = cos(m[5]), sp = sin(m[5]), cr = cos(m[4]),
          sr = sin(m[4]);
  const T b[9] = {cy * cp,
                  cy * sp * sr - sy * cr,
                  cy * sp * cr + sy * sr,
                  sy * cp,
                  sy * sp * sr + cy * cr,
                  sy * sp * cr - cy * sr,
                  -sp,
                  cp * sr,
                  cp * cr};
  for (int i = 0; i < 3; ++i) {
    r[3 * i + 0] = -b[3 * i + 1];
    r[3 * i + 1] = -b[3 * i + 0];
    r[3 * i + 2] = -b[3 * i + 2];
  }
}

struct FrameCost {
  const OdomTable* od;
  double t_anchor_s, t_frame_s;
  Pose2 landmark;             // world <- landmark
  std::array<Vec2, 8> local;  // printed corners in the landmark frame
  std::array<Vec2, 8> xn;
  std::array<bool, 8> valid;
  double scale;  // fx / sigma; the landmark's sigma after the first solve

  // off: the landmark's corner offsets (x, y per corner, landmark frame, mm).
  template <typename T>
  bool operator()(const T* mount, const T* odo, const T* dt, const T* anchor, const T* off,
                  T* res) const {
    T rel[3];
    integrate(*od, t_anchor_s, t_frame_s, odo, dt, rel);
    const T ca = cos(anchor[2]), sa = sin(anchor[2]);
    const T px = anchor[0] + ca * rel[0] - sa * rel[1];
    const T py = anchor[1] + sa * rel[0] + ca * rel[1];
    const T th = anchor[2] + rel[2];
    const T c = cos(th), s = sin(th);
    T r[9];
    rotation_vc(mount, r);
    const double cl = std::cos(landmark.theta_rad), sl = std::sin(landmark.theta_rad);
    for (int i = 0; i < 8; ++i) {
      if (!valid[static_cast<size_t>(i)]) {
        res[2 * i] = T(0.0);
        res[2 * i + 1] = T(0.0);
        continue;
      }
      const T lx = T(local[static_cast<size_t>(i)].x) + off[2 * i],
              ly = T(local[static_cast<size_t>(i)].y) + off[2 * i + 1];
      const T wx = T(landmark.x_mm) + cl * lx - sl * ly - px,
              wy = T(landmark.y_mm) + sl * lx + cl * ly - py;
      const T vx = c * wx + s * wy - mount[0], vy = -s * wx + c * wy - mount[1], vz = -mount[3];
      const T xc = r[0] * vx + r[3] * vy + r[6] * vz;
      const T yc = r[1] * vx + r[4] * vy + r[7] * vz;
      const T zc = r[2] * vx + r[5] * vy + r[8] * vz;
      res[2 * i] = (xc / zc - xn[static_cast<size_t>(i)].x) * scale;
      res[2 * i + 1] = (yc / zc - xn[static_cast<size_t>(i)].y) * scale;
    }
    return true;
  }
};

struct LinkCost {
  const OdomTable* od;
  double t_a_s, t_b_s;
  double inv_sigma_pos, inv_sigma_th;

  template <typename T>
  bool operator()(const T* odo, const T* dt, const T* a, const T* b, T* res) const {
    T rel[3];
    integrate(*od, t_a_s, t_b_s, odo, dt, rel);
    // Relative pose A^-1 B vs the odometry's, in A's frame.
    const T ca = cos(a[2]), sa = sin(a[2]);
    const T dx = b[0] - a[0], dy = b[1] - a[1];
    const T lx = ca * dx + sa * dy, ly = -sa * dx + ca * dy;
    T dth = b[2] - a[2] - rel[2];
    // Wrap to (-pi, pi].
    while (dth > T(kPi)) dth -= T(2.0 * kPi);
    while (dth <= T(-kPi)) dth += T(2.0 * kPi);
    res[0] = (lx - rel[0]) * inv_sigma_pos;
    res[1] = (ly - rel[1]) * inv_sigma_pos;
    res[2] = dth * inv_sigma_th;
    return true;
  }
};

// The N(0, tau^2) prior of one landmark's corner offsets; tau is set after the first solve.
struct OffsetPrior {
  const double* inv_tau;
  template <typename T>
  bool operator()(const T* off, T* res) const {
    for (int i = 0; i < 16; ++i) res[i] = off[i] * *inv_tau;
    return true;
  }
};

struct SubPass {
  int pass = 0;
  std::vector<size_t> frames;  // indices into obs
};

// Rigid 2D fit: V<-L from landmark-frame points and their vehicle-frame images.
bool fit_rigid(const std::vector<Vec2>& l, const std::vector<Vec2>& v, Pose2* v_from_l) {
  if (l.size() < 2) return false;
  Vec2 ml{0, 0}, mv{0, 0};
  for (size_t i = 0; i < l.size(); ++i) {
    ml = {ml.x + l[i].x, ml.y + l[i].y};
    mv = {mv.x + v[i].x, mv.y + v[i].y};
  }
  const double n = static_cast<double>(l.size());
  ml = {ml.x / n, ml.y / n};
  mv = {mv.x / n, mv.y / n};
  double sc = 0, ss = 0;
  for (size_t i = 0; i < l.size(); ++i) {
    const double ax = l[i].x - ml.x, ay = l[i].y - ml.y, bx = v[i].x - mv.x, by = v[i].y - mv.y;
    sc += ax * bx + ay * by;
    ss += ax * by - ay * bx;
  }
  const double th = std::atan2(ss, sc), c = std::cos(th), s = std::sin(th);
  *v_from_l = {mv.x - (c * ml.x - s * ml.y), mv.y - (s * ml.x + c * ml.y), th};
  return true;
}

double deg(double rad) { return rad * 180.0 / kPi; }

struct WearStats {
  double sigma_px = 0.0;  // corner noise about the per-corner means (at least pixel_sigma_px)
  double tau_mm = 0.0;    // RMS of the per-corner means (at least min_print_offset_mm)
  std::array<double, 16> mean_offset_mm{};
};

// After the first solve (printed geometry): every corner residual is mapped to the landmark
// plane through the frame's own image of the landmark (the affine map its outer corners give,
// exact enough over 60 mm) and averaged per landmark corner over all frames. The mean is what is
// the same in every frame (the print's deviation from the square), the scatter about it the
// noise; parameters that absorbed part of the deviation leave it out of both.
void measure_wear(ceres::Problem& problem, const std::vector<ceres::ResidualBlockId>& blocks,
                  const std::vector<FrameCost*>& costs, const std::vector<size_t>& lm,
                  const Options& opt, std::vector<WearStats>* out) {
  const size_t n_lm = out->size();
  std::vector<std::array<double, 16>> sum(n_lm), sum2(n_lm);
  std::vector<std::array<int, 8>> cnt(n_lm);
  std::vector<double> px_per_mm(n_lm, 0.0), n_res(n_lm, 0.0), n_dof(n_lm, 0.0);
  std::vector<int> frames(n_lm, 0);
  for (size_t l = 0; l < n_lm; ++l) {
    sum[l].fill(0.0);
    sum2[l].fill(0.0);
    cnt[l].fill(0);
  }
  for (size_t b = 0; b < blocks.size(); ++b) {
    const FrameCost& f = *costs[b];
    if (!(f.valid[0] && f.valid[1] && f.valid[3])) continue;
    double res[16], cost = 0.0;
    problem.EvaluateResidualBlock(blocks[b], false, &cost, res, nullptr);
    // Landmark mm -> normalised image: corner 1 - corner 0 is (-2h, 0), corner 3 - corner 0 is
    // (0, -2h) on the print.
    const double two_h = f.local[0].x - f.local[1].x;
    const double a = (f.xn[0].x - f.xn[1].x) / two_h, c = (f.xn[0].y - f.xn[1].y) / two_h;
    const double bx = (f.xn[0].x - f.xn[3].x) / two_h, d = (f.xn[0].y - f.xn[3].y) / two_h;
    const double det = a * d - bx * c;
    if (!(std::abs(det) > 1e-12)) continue;
    const size_t l = lm[b];
    px_per_mm[l] += opt.fx_px * std::sqrt(std::abs(det));
    ++frames[l];
    // The frame's own pose takes 3 of its residuals' degrees of freedom: the scatter about the
    // fit is that much smaller than the noise.
    const double nv = 2.0 * static_cast<double>(std::count(f.valid.begin(), f.valid.end(), true));
    n_res[l] += nv;
    n_dof[l] += std::max(1.0, nv - 3.0);
    for (size_t i = 0; i < 8; ++i) {
      if (!f.valid[i]) continue;
      // residual = (predicted - observed) * scale; a corner printed off by delta is observed
      // M delta away from the prediction.
      const double rx = res[2 * i] / f.scale, ry = res[2 * i + 1] / f.scale;
      const double dx = -(d * rx - bx * ry) / det, dy = -(-c * rx + a * ry) / det;
      sum[l][2 * i] += dx;
      sum[l][2 * i + 1] += dy;
      sum2[l][2 * i] += dx * dx;
      sum2[l][2 * i + 1] += dy * dy;
      ++cnt[l][i];
    }
  }
  for (size_t l = 0; l < n_lm; ++l) {
    WearStats& w = (*out)[l];
    w.mean_offset_mm.fill(0.0);
    double mean2 = 0.0, var = 0.0;
    int corners = 0;
    for (size_t i = 0; i < 8; ++i) {
      if (cnt[l][i] < 2) continue;
      const double n = cnt[l][i];
      for (size_t k = 2 * i; k < 2 * i + 2; ++k) {
        const double m = sum[l][k] / n;
        w.mean_offset_mm[k] = m;
        mean2 += m * m;
        var += std::max(0.0, sum2[l][k] / n - m * m);
      }
      ++corners;
    }
    const double scale_px = frames[l] > 0 ? px_per_mm[l] / frames[l] : 0.0;
    if (n_dof[l] > 0) var *= n_res[l] / n_dof[l];
    w.tau_mm =
        std::max(opt.min_print_offset_mm, corners > 0 ? std::sqrt(mean2 / (2 * corners)) : 0.0);
    w.sigma_px =
        std::max(opt.pixel_sigma_px, corners > 0 ? std::sqrt(var / (2 * corners)) * scale_px : 0.0);
  }
}

}  // namespace

std::array<Vec2, 8> landmark_corners(double ho, double hi) {
  return {Vec2{ho, ho}, Vec2{-ho, ho}, Vec2{-ho, -ho}, Vec2{ho, -ho},
          Vec2{hi, hi}, Vec2{-hi, hi}, Vec2{-hi, -hi}, Vec2{hi, -hi}};
}

bool calibrate_vehicle(const std::vector<OdomSample>& odom,
                       const std::vector<CornerObservation>& obs_in, const LandmarkMap& map,
                       double outer_half_mm, double inner_half_mm, const VehicleParams& initial,
                       const Options& opt, Result* out, std::string* error) {
  auto fail = [&](const std::string& m) {
    if (error) *error = m;
    return false;
  };
  if (odom.size() < 2) {
    return fail("the recording has no odometry (odom.csv has " + std::to_string(odom.size()) +
                " rows): the odometry scales, bias and time offset need it");
  }
  if (obs_in.empty()) return fail("no frame shows a landmark (nothing to calibrate against)");
  // Observations of mapped landmarks inside the odometry span (with a margin for the offset).
  const std::int64_t t_ref = obs_in.front().t_ns;
  OdomTable od;
  od.quarter_track_sq_mm2 = 0.25 * opt.track_width_mm * opt.track_width_mm;
  for (const OdomSample& o : odom) {
    od.t.push_back(static_cast<double>(o.t_ns - t_ref) * 1e-9);
    od.v_mmps.push_back(o.v_mps * 1000.0);
    od.w.push_back(o.omega_radps);
  }
  for (size_t i = 1; i < od.t.size(); ++i) {
    if (!(od.t[i] > od.t[i - 1])) return fail("odometry timestamps are not strictly increasing");
  }
  std::vector<CornerObservation> obs;
  size_t unmapped = 0, outside = 0;
  for (const CornerObservation& o : obs_in) {
    if (!map.find(o.landmark_id)) {
      ++unmapped;
      continue;
    }
    const double t = static_cast<double>(o.t_ns - t_ref) * 1e-9 + initial.time_offset_s;
    if (t < od.t.front() + 0.1 || t > od.t.back() - 0.1) {
      ++outside;
      continue;
    }
    obs.push_back(o);
  }
  if (obs.empty()) {
    char b[200];
    std::snprintf(b, sizeof b,
                  "no observation of a mapped landmark inside the odometry time span (%zu "
                  "observations of landmarks not in the map: wrong map?, %zu outside the "
                  "odometry span)",
                  unmapped, outside);
    return fail(b);
  }
  if (unmapped > 0) {
    out->warnings.push_back(std::to_string(unmapped) +
                            " frames show landmarks that are not in the map (ignored)");
  }

  // Passes and sub-passes.
  std::vector<SubPass> subs;
  std::vector<std::pair<size_t, size_t>> pass_range;  // [first, last] obs index
  for (size_t i = 0; i < obs.size(); ++i) {
    const bool new_pass =
        i == 0 || obs[i].landmark_id != obs[i - 1].landmark_id ||
        static_cast<double>(obs[i].t_ns - obs[i - 1].t_ns) * 1e-9 > opt.pass_gap_s;
    if (new_pass) pass_range.push_back({i, i});
    pass_range.back().second = i;
  }
  std::vector<std::pair<size_t, size_t>> passes;
  for (const auto& pr : pass_range) {
    if (static_cast<int>(pr.second - pr.first + 1) >= opt.min_frames_per_pass) passes.push_back(pr);
  }
  if (static_cast<int>(passes.size()) < opt.min_passes) {
    return fail("too few landmark passes: " + std::to_string(passes.size()) + " with at least " +
                std::to_string(opt.min_frames_per_pass) + " frames (need " +
                std::to_string(opt.min_passes) +
                "; drive the calibration pattern of docs/guide/commissioning.md)");
  }
  for (size_t p = 0; p < passes.size(); ++p) {
    SubPass cur;
    cur.pass = static_cast<int>(p);
    for (size_t i = passes[p].first; i <= passes[p].second; ++i) {
      if (!cur.frames.empty() &&
          static_cast<double>(obs[i].t_ns - obs[cur.frames.front()].t_ns) * 1e-9 >
              opt.max_subpass_s) {
        subs.push_back(cur);
        cur.frames.clear();
      }
      cur.frames.push_back(i);
    }
    subs.push_back(cur);
  }

  // Parameters.
  double mount[kMount] = {initial.mount.offset_x_mm, initial.mount.offset_y_mm,
                          initial.mount.yaw_rad,     initial.mount.height_mm,
                          initial.mount.roll_rad,    initial.mount.pitch_rad};
  double odo[kOdo] = {initial.speed_scale, initial.yaw_rate_scale, initial.yaw_rate_bias_radps,
                      initial.yaw_per_metre_rad};
  double dt[1] = {initial.time_offset_s};
  const std::array<Vec2, 8> lc = landmark_corners(outer_half_mm, inner_half_mm);
  CameraModel nominal;
  nominal.mount = initial.mount;
  std::vector<std::array<double, 3>> anchors(subs.size());
  for (size_t j = 0; j < subs.size(); ++j) {
    const CornerObservation& o = obs[subs[j].frames.front()];
    std::vector<Vec2> l, v;
    for (size_t c = 0; c < 8; ++c) {
      if (!o.valid[c]) continue;
      // Ray of the undistorted normalised point through the initial mounting to the floor.
      double r[9];
      nominal.mount.rotation_vehicle_from_camera(r);
      const double rx = r[0] * o.xn[c].x + r[1] * o.xn[c].y + r[2];
      const double ry = r[3] * o.xn[c].x + r[4] * o.xn[c].y + r[5];
      const double rz = r[6] * o.xn[c].x + r[7] * o.xn[c].y + r[8];
      if (!(rz < -1e-9)) continue;
      const double t = nominal.mount.height_mm / -rz;
      l.push_back(lc[c]);
      v.push_back({nominal.mount.offset_x_mm + t * rx, nominal.mount.offset_y_mm + t * ry});
    }
    Pose2 v_from_l;
    if (!fit_rigid(l, v, &v_from_l)) {
      return fail("a landmark observation has fewer than 2 usable corners");
    }
    const Pose2 w = compose(map.find(o.landmark_id)->pose, inverse(v_from_l));
    anchors[j] = {w.x_mm, w.y_mm, w.theta_rad};
  }

  ceres::Problem problem;
  std::vector<ceres::ResidualBlockId> frame_blocks;
  std::vector<FrameCost*> frame_costs;  // owned by the problem
  std::vector<int> frame_pass, frame_nvalid;
  std::vector<size_t> frame_lm;
  // Landmarks in id order, each with its 16 corner offsets and the inverse of their prior sigma.
  std::map<std::uint32_t, size_t> lm_index;
  for (const SubPass& sp : subs) {
    for (size_t i : sp.frames) lm_index.emplace(obs[i].landmark_id, 0);
  }
  {
    size_t k = 0;
    for (auto& [id, i] : lm_index) i = k++;
  }
  std::vector<std::array<double, 16>> offsets(lm_index.size());
  for (auto& a : offsets) a.fill(0.0);
  std::vector<double> inv_tau(lm_index.size(), 1.0 / std::max(opt.min_print_offset_mm, 1e-6));
  const double scale = opt.fx_px / opt.pixel_sigma_px;
  for (size_t j = 0; j < subs.size(); ++j) {
    const double ta = static_cast<double>(obs[subs[j].frames.front()].t_ns - t_ref) * 1e-9;
    for (size_t i : subs[j].frames) {
      const CornerObservation& o = obs[i];
      auto* fc = new FrameCost;
      fc->od = &od;
      fc->t_anchor_s = ta;
      fc->t_frame_s = static_cast<double>(o.t_ns - t_ref) * 1e-9;
      fc->landmark = map.find(o.landmark_id)->pose;
      fc->local = lc;
      fc->xn = o.xn;
      fc->valid = o.valid;
      fc->scale = scale;
      const size_t li = lm_index.at(o.landmark_id);
      frame_blocks.push_back(problem.AddResidualBlock(
          new ceres::AutoDiffCostFunction<FrameCost, 16, kMount, kOdo, 1, 3, 16>(fc),
          // Robust: a frame whose corners are off (blur, a mis-fitted edge) by much more than the
          // noise counts linearly, not quadratically (squared norm of the block in sigma units).
          opt.robust_sigmas > 0.0
              ? new ceres::HuberLoss(opt.robust_sigmas *
                                     std::sqrt(2.0 * static_cast<double>(std::count(
                                                         o.valid.begin(), o.valid.end(), true))))
              : nullptr,
          mount, odo, dt, anchors[j].data(), offsets[li].data()));
      frame_costs.push_back(fc);
      frame_pass.push_back(subs[j].pass);
      frame_lm.push_back(li);
      frame_nvalid.push_back(static_cast<int>(std::count(o.valid.begin(), o.valid.end(), true)));
    }
  }
  // The printed geometry is exact until the first solve has measured each landmark's wear.
  for (size_t li = 0; li < offsets.size(); ++li) {
    problem.AddResidualBlock(
        new ceres::AutoDiffCostFunction<OffsetPrior, 16, 16>(new OffsetPrior{&inv_tau[li]}),
        nullptr, offsets[li].data());
    problem.SetParameterBlockConstant(offsets[li].data());
  }
  const double period = od.t.size() > 1 ? (od.t.back() - od.t.front()) / (od.t.size() - 1) : 0.01;
  double total_turn = 0.0;
  for (size_t j = 0; j + 1 < subs.size(); ++j) {
    auto* lk = new LinkCost;
    lk->od = &od;
    lk->t_a_s = static_cast<double>(obs[subs[j].frames.front()].t_ns - t_ref) * 1e-9;
    lk->t_b_s = static_cast<double>(obs[subs[j + 1].frames.front()].t_ns - t_ref) * 1e-9;
    const double n = std::max(1.0, (lk->t_b_s - lk->t_a_s) / period);
    double dist = 0.0;
    for (size_t k = 1; k < od.t.size(); ++k) {
      if (od.t[k] > lk->t_a_s && od.t[k] <= lk->t_b_s) {
        dist += std::abs(od.v_mmps[k]) * period;
        total_turn += std::abs(od.w[k]) * period;
      }
    }
    const double s_th = opt.odom_omega_sigma_radps * period * std::sqrt(n);
    const double s_pos = std::sqrt(std::pow(opt.odom_v_sigma_mps * 1000.0 * period, 2) * n +
                                   dist * dist * s_th * s_th / 3.0);
    lk->inv_sigma_pos = 1.0 / std::max(s_pos, 1e-3);
    lk->inv_sigma_th = 1.0 / std::max(s_th, 1e-7);
    problem.AddResidualBlock(new ceres::AutoDiffCostFunction<LinkCost, 3, kOdo, 1, 3, 3>(lk),
                             nullptr, odo, dt, anchors[j].data(), anchors[j + 1].data());
  }
  out->turns_seen = total_turn > kPi;
  if (!out->turns_seen) {
    out->warnings.push_back(
        "the drive turns only " + std::to_string(static_cast<int>(deg(total_turn))) +
        " deg in total: the yaw-rate scale and the mounting offset are not observable without "
        "turns (drive the turns on the spot of the calibration pattern)");
  }
  problem.SetParameterLowerBound(mount, 3, 10.0);

  // RMS corner residual (px) per pass, per landmark and overall, with the printed geometry (the
  // corner offsets set to zero for the evaluation): what the print and the calibration explain.
  auto rms_px = [&](std::vector<double>* per_pass, std::vector<double>* per_lm, double* all) {
    const auto saved = offsets;
    for (auto& a : offsets) a.fill(0.0);
    std::vector<double> ss(passes.size(), 0.0), sl(offsets.size(), 0.0);
    std::vector<int> cnt(passes.size(), 0), cl(offsets.size(), 0);
    double sa = 0;
    int ca = 0;
    for (size_t b = 0; b < frame_blocks.size(); ++b) {
      double cost = 0;
      problem.EvaluateResidualBlock(frame_blocks[b], false, &cost, nullptr, nullptr);
      // cost = 0.5 |r|^2, r in units of the block's sigma: back to pixels.
      const double px_per_unit = opt.fx_px / frame_costs[b]->scale;
      const double sq = 2.0 * cost * px_per_unit * px_per_unit;
      const int nv = std::max(frame_nvalid[b], 1);
      ss[static_cast<size_t>(frame_pass[b])] += sq;
      cnt[static_cast<size_t>(frame_pass[b])] += nv;
      sl[frame_lm[b]] += sq;
      cl[frame_lm[b]] += nv;
      sa += sq;
      ca += nv;
    }
    offsets = saved;
    per_pass->resize(passes.size());
    for (size_t p = 0; p < passes.size(); ++p) {
      (*per_pass)[p] = cnt[p] > 0 ? std::sqrt(ss[p] / cnt[p]) : 0.0;
    }
    per_lm->resize(offsets.size());
    for (size_t l = 0; l < offsets.size(); ++l) {
      (*per_lm)[l] = cl[l] > 0 ? std::sqrt(sl[l] / cl[l]) : 0.0;
    }
    *all = ca > 0 ? std::sqrt(sa / ca) : 0.0;
  };
  std::vector<double> before, after, lm_before, lm_after;
  rms_px(&before, &lm_before, &out->rms_before_px);

  ceres::Solver::Options so;
  so.linear_solver_type = ceres::SPARSE_SCHUR;
  so.max_num_iterations = opt.max_iterations;
  so.function_tolerance = 1e-12;
  so.parameter_tolerance = 1e-12;
  so.gradient_tolerance = 1e-14;
  so.num_threads = 2;
  ceres::Solver::Summary summary;
  ceres::Solve(so, &problem, &summary);
  if (!summary.IsSolutionUsable()) return fail("the solver failed: " + summary.message);
  out->iterations = static_cast<int>(summary.iterations.size());
  std::vector<WearStats> wear(offsets.size());
  if (opt.model_wear) {
    measure_wear(problem, frame_blocks, frame_costs, frame_lm, opt, &wear);
    for (size_t b = 0; b < frame_costs.size(); ++b) {
      frame_costs[b]->scale = opt.fx_px / wear[frame_lm[b]].sigma_px;
    }
    for (size_t li = 0; li < offsets.size(); ++li) {
      inv_tau[li] = 1.0 / wear[li].tau_mm;
      offsets[li] = wear[li].mean_offset_mm;
      problem.SetParameterBlockVariable(offsets[li].data());
    }
    ceres::Solve(so, &problem, &summary);
    if (!summary.IsSolutionUsable()) return fail("the solver failed: " + summary.message);
    out->iterations += static_cast<int>(summary.iterations.size());
  }
  rms_px(&after, &lm_after, &out->rms_after_px);
  // Whatever the per-landmark model leaves: the covariance grows with the reduced chi-square of
  // the corner residuals (never shrinks below the stated pixel noise).
  double chi2_scale = 1.0;
  if (opt.model_wear) {
    double chi2 = 0.0;
    double n_res = 0.0;
    for (size_t b = 0; b < frame_blocks.size(); ++b) {
      double cost = 0;
      problem.EvaluateResidualBlock(frame_blocks[b], false, &cost, nullptr, nullptr);
      chi2 += 2.0 * cost;
      n_res += 2.0 * frame_nvalid[b];
    }
    const double dof =
        n_res - 3.0 * static_cast<double>(subs.size()) - 16.0 * offsets.size() - kNumGlobal;
    if (dof > 0) chi2_scale = std::max(1.0, chi2 / dof);
  }

  // Covariance of the global parameters (anchors marginalised).
  ceres::Covariance::Options co;
  // Sparse QR: thousands of anchors; fails (rank deficient) when some direction is not
  // observable at all, which is then reported as such.
  co.algorithm_type = ceres::SPARSE_QR;
  co.num_threads = 2;
  ceres::Covariance cov(co);
  std::vector<std::pair<const double*, const double*>> blocks = {
      {mount, mount}, {odo, odo}, {dt, dt}, {mount, odo}};
  double cm[kMount * kMount] = {}, cov_odo[kOdo * kOdo] = {}, cdt = 0.0;
  bool cov_ok = false;
  if (cov.Compute(blocks, &problem)) {
    cov_ok = cov.GetCovarianceBlock(mount, mount, cm) &&
             cov.GetCovarianceBlock(odo, odo, cov_odo) && cov.GetCovarianceBlock(dt, dt, &cdt);
  }
  for (double& v : cm) v *= chi2_scale;
  for (double& v : cov_odo) v *= chi2_scale;
  cdt *= chi2_scale;
  // Trade-offs: the information matrix of the global parameters with the anchors eliminated,
  // scaled to the reporting limits; its weakest eigenvectors name the parameters that trade off.
  std::vector<std::string> names = {
      "mounting.offset_x_mm",       "mounting.offset_y_mm",    "mounting.yaw_deg",
      "mounting.height_mm",         "mounting.roll_deg",       "mounting.pitch_deg",
      "odometry.speed_scale",       "odometry.yaw_rate_scale", "odometry.yaw_rate_bias_degps",
      "odometry.yaw_per_metre_deg", "camera.time_offset_ms"};
  const double limit[kNumGlobal] = {opt.max_sigma_mm,
                                    opt.max_sigma_mm,
                                    opt.max_sigma_yaw_deg * kPi / 180.0,
                                    opt.max_sigma_mm,
                                    opt.max_sigma_tilt_deg * kPi / 180.0,
                                    opt.max_sigma_tilt_deg * kPi / 180.0,
                                    opt.max_sigma_scale,
                                    opt.max_sigma_scale,
                                    opt.max_sigma_bias_degps * kPi / 180.0,
                                    opt.max_sigma_yaw_per_metre_deg * kPi / 180.0,
                                    opt.max_sigma_time_ms * 1e-3};
  double sigma[kNumGlobal];
  for (int i = 0; i < kMount; ++i)
    sigma[i] = cov_ok ? std::sqrt(std::max(0.0, cm[i * kMount + i])) : kInf;
  for (int i = 0; i < kOdo; ++i) {
    sigma[kMount + i] = cov_ok ? std::sqrt(std::max(0.0, cov_odo[i * kOdo + i])) : kInf;
  }
  sigma[kNumGlobal - 1] = cov_ok ? std::sqrt(std::max(0.0, cdt)) : kInf;
  std::vector<std::string> tradeoff(kNumGlobal);
  {
    // Scaled covariance -> correlations of undetermined parameters.
    Eigen::Matrix<double, kNumGlobal, kNumGlobal> c =
        Eigen::Matrix<double, kNumGlobal, kNumGlobal>::Zero();
    if (cov_ok) {
      for (int i = 0; i < kMount; ++i)
        for (int j = 0; j < kMount; ++j) c(i, j) = cm[i * kMount + j];
      for (int i = 0; i < kOdo; ++i)
        for (int j = 0; j < kOdo; ++j) c(kMount + i, kMount + j) = cov_odo[i * kOdo + j];
      c(kNumGlobal - 1, kNumGlobal - 1) = cdt;
      // Cross blocks.
      double x[kMount * kOdo];
      if (cov.GetCovarianceBlock(mount, odo, x)) {
        for (int i = 0; i < kMount; ++i)
          for (int j = 0; j < kOdo; ++j) {
            c(i, kMount + j) = c(kMount + j, i) = chi2_scale * x[i * kOdo + j];
          }
      }
    }
    for (int i = 0; i < kNumGlobal; ++i) {
      if (!(sigma[i] <= limit[i])) {
        std::string partners;
        for (int j = 0; j < kNumGlobal; ++j) {
          if (j == i || !cov_ok || !(sigma[j] > 0)) continue;
          const double rho = c(i, j) / (sigma[i] * sigma[j]);
          if (std::abs(rho) > 0.9)
            partners += (partners.empty() ? "" : ", ") + names[static_cast<size_t>(j)];
        }
        tradeoff[static_cast<size_t>(i)] = partners;
      }
    }
  }
  if (!cov_ok) {
    out->warnings.push_back(
        "the covariance could not be computed (the problem is rank deficient): no parameter is "
        "written");
  }

  auto& e = out->estimate;
  e.mount.offset_x_mm = mount[0];
  e.mount.offset_y_mm = mount[1];
  e.mount.yaw_rad = mount[2];
  e.mount.height_mm = mount[3];
  e.mount.roll_rad = mount[4];
  e.mount.pitch_rad = mount[5];
  e.speed_scale = odo[0];
  e.yaw_rate_scale = odo[1];
  e.yaw_rate_bias_radps = odo[2];
  e.yaw_per_metre_rad = odo[3];
  e.time_offset_s = dt[0];
  const double init[kNumGlobal] = {
      initial.mount.offset_x_mm, initial.mount.offset_y_mm, initial.mount.yaw_rad,
      initial.mount.height_mm,   initial.mount.roll_rad,    initial.mount.pitch_rad,
      initial.speed_scale,       initial.yaw_rate_scale,    initial.yaw_rate_bias_radps,
      initial.yaw_per_metre_rad, initial.time_offset_s};
  const double val[kNumGlobal] = {mount[0], mount[1], mount[2], mount[3], mount[4], mount[5],
                                  odo[0],   odo[1],   odo[2],   odo[3],   dt[0]};
  const double to_unit[kNumGlobal] = {1, 1, 180 / kPi, 1,         180 / kPi, 180 / kPi,
                                      1, 1, 180 / kPi, 180 / kPi, 1e3};
  const char* units[kNumGlobal] = {"mm", "mm", "deg",   "mm",    "deg", "deg",
                                   "",   "",   "deg/s", "deg/m", "ms"};
  out->params.clear();
  for (int i = 0; i < kNumGlobal; ++i) {
    ParamReport r;
    r.name = names[static_cast<size_t>(i)];
    r.unit = units[i];
    r.initial = init[i] * to_unit[i];
    r.value = val[i] * to_unit[i];
    r.sigma = sigma[i] * to_unit[i];
    r.determined = cov_ok && sigma[i] <= limit[i];
    if (!r.determined) {
      char b[200];
      if (!cov_ok) {
        std::snprintf(b, sizeof b, "not observable (rank-deficient problem)");
      } else {
        std::snprintf(b, sizeof b, "sigma %.3g %s exceeds the limit %.3g %s", r.sigma,
                      r.unit.c_str(), limit[i] * to_unit[i], r.unit.c_str());
      }
      r.why = b;
      if (!tradeoff[static_cast<size_t>(i)].empty()) {
        r.why += "; trades off against " + tradeoff[static_cast<size_t>(i)];
      }
      out->warnings.push_back(r.name + " is not determined: " + r.why);
    }
    out->params.push_back(r);
  }
  out->passes.clear();
  const double t0 = static_cast<double>(obs.front().t_ns - t_ref) * 1e-9;
  for (size_t p = 0; p < passes.size(); ++p) {
    PassReport pr;
    pr.index = static_cast<int>(p);
    pr.landmark_id = obs[passes[p].first].landmark_id;
    pr.t_start_s = static_cast<double>(obs[passes[p].first].t_ns - t_ref) * 1e-9 - t0;
    pr.t_end_s = static_cast<double>(obs[passes[p].second].t_ns - t_ref) * 1e-9 - t0;
    pr.frames = static_cast<int>(passes[p].second - passes[p].first + 1);
    pr.rms_before_px = before[p];
    pr.rms_after_px = after[p];
    out->passes.push_back(pr);
  }
  out->landmarks.clear();
  for (const auto& [id, li] : lm_index) {
    LandmarkReport lr;
    lr.landmark_id = id;
    for (const PassReport& pr : out->passes) {
      if (pr.landmark_id != id) continue;
      ++lr.passes;
      lr.frames += pr.frames;
    }
    lr.rms_before_px = lm_before[li];
    lr.rms_after_px = lm_after[li];
    lr.sigma_px = opt.model_wear ? wear[li].sigma_px : opt.pixel_sigma_px;
    lr.print_offset_mm = opt.model_wear ? wear[li].tau_mm : 0.0;
    out->landmarks.push_back(lr);
  }
  flag_standing_out(opt, &out->landmarks, &out->warnings);
  out->frames_used = static_cast<int>(frame_blocks.size());
  out->subpasses = static_cast<int>(subs.size());
  return true;
}

}  // namespace agv::desk::vcal
