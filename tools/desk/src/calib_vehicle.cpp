// Vehicle calibration by nonlinear least squares (Ceres): the problem built from the drive and
// solved. Model: calib_vehicle.hpp; the costs: calib_vehicle_problem.hpp; the report:
// calib_vehicle_report.cpp.
#include "calib_vehicle.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <memory>

#include "calib_vehicle_problem.hpp"

namespace agv::desk::vcal {

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

namespace detail {
namespace {

double deg(double rad) { return rad * 180.0 / kPi; }

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

// The odometry on the solve's clock (seconds from the first observation). False with *why.
bool load_odometry(const std::vector<OdomSample>& odom, const Options& opt, Solve* s,
                   std::string* why) {
  s->od.quarter_track_sq_mm2 = 0.25 * opt.track_width_mm * opt.track_width_mm;
  for (const OdomSample& o : odom) {
    s->od.t.push_back(static_cast<double>(o.t_ns - s->t_ref) * 1e-9);
    s->od.v_mmps.push_back(o.v_mps * 1000.0);
    s->od.w.push_back(o.omega_radps);
  }
  for (size_t i = 1; i < s->od.t.size(); ++i) {
    if (!(s->od.t[i] > s->od.t[i - 1])) {
      *why = "odometry timestamps are not strictly increasing";
      return false;
    }
  }
  return true;
}

// Observations of mapped landmarks inside the odometry span (with a margin for the offset).
bool select_observations(const std::vector<CornerObservation>& obs_in, const LandmarkMap& map,
                         const VehicleParams& initial, Solve* s, Result* out, std::string* why) {
  size_t unmapped = 0, outside = 0;
  for (const CornerObservation& o : obs_in) {
    if (!map.find(o.landmark_id)) {
      ++unmapped;
      continue;
    }
    const double t = static_cast<double>(o.t_ns - s->t_ref) * 1e-9 + initial.time_offset_s;
    if (t < s->od.t.front() + 0.1 || t > s->od.t.back() - 0.1) {
      ++outside;
      continue;
    }
    s->obs.push_back(o);
  }
  if (s->obs.empty()) {
    char b[200];
    std::snprintf(b, sizeof b,
                  "no observation of a mapped landmark inside the odometry time span (%zu "
                  "observations of landmarks not in the map: wrong map?, %zu outside the "
                  "odometry span)",
                  unmapped, outside);
    *why = b;
    return false;
  }
  if (unmapped > 0) {
    out->warnings.push_back(std::to_string(unmapped) +
                            " frames show landmarks that are not in the map (ignored)");
  }
  return true;
}

// Passes (one landmark, no gap over pass_gap_s, at least min_frames_per_pass frames) and their
// sub-passes (at most max_subpass_s each, one anchor pose each).
bool find_passes(const Options& opt, Solve* s, std::string* why) {
  const std::vector<CornerObservation>& obs = s->obs;
  std::vector<std::pair<size_t, size_t>> pass_range;  // [first, last] obs index
  for (size_t i = 0; i < obs.size(); ++i) {
    const bool new_pass =
        i == 0 || obs[i].landmark_id != obs[i - 1].landmark_id ||
        static_cast<double>(obs[i].t_ns - obs[i - 1].t_ns) * 1e-9 > opt.pass_gap_s;
    if (new_pass) pass_range.push_back({i, i});
    pass_range.back().second = i;
  }
  for (const auto& pr : pass_range) {
    if (static_cast<int>(pr.second - pr.first + 1) >= opt.min_frames_per_pass) {
      s->passes.push_back(pr);
    }
  }
  if (static_cast<int>(s->passes.size()) < opt.min_passes) {
    *why = "too few landmark passes: " + std::to_string(s->passes.size()) + " with at least " +
           std::to_string(opt.min_frames_per_pass) + " frames (need " +
           std::to_string(opt.min_passes) +
           "; drive the calibration pattern of docs/guide/commissioning.md)";
    return false;
  }
  for (size_t p = 0; p < s->passes.size(); ++p) {
    SubPass cur;
    cur.pass = static_cast<int>(p);
    for (size_t i = s->passes[p].first; i <= s->passes[p].second; ++i) {
      if (!cur.frames.empty() &&
          static_cast<double>(obs[i].t_ns - obs[cur.frames.front()].t_ns) * 1e-9 >
              opt.max_subpass_s) {
        s->subs.push_back(cur);
        cur.frames.clear();
      }
      cur.frames.push_back(i);
    }
    s->subs.push_back(cur);
  }
  return true;
}

// The parameters at their initial values, and each sub-pass's anchor from its first frame seen
// through the initial mounting.
bool initial_values(const LandmarkMap& map, const VehicleParams& initial,
                    const std::array<Vec2, 8>& lc, Solve* s, std::string* why) {
  const double mount[kMount] = {initial.mount.offset_x_mm, initial.mount.offset_y_mm,
                                initial.mount.yaw_rad,     initial.mount.height_mm,
                                initial.mount.roll_rad,    initial.mount.pitch_rad};
  const double odo[kOdo] = {initial.speed_scale, initial.yaw_rate_scale,
                            initial.yaw_rate_bias_radps, initial.yaw_per_metre_rad};
  std::copy(mount, mount + kMount, s->mount);
  std::copy(odo, odo + kOdo, s->odo);
  s->dt[0] = initial.time_offset_s;
  CameraModel nominal;
  nominal.mount = initial.mount;
  s->anchors.resize(s->subs.size());
  for (size_t j = 0; j < s->subs.size(); ++j) {
    const CornerObservation& o = s->obs[s->subs[j].frames.front()];
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
      *why = "a landmark observation has fewer than 2 usable corners";
      return false;
    }
    const Pose2 w = compose(map.find(o.landmark_id)->pose, inverse(v_from_l));
    s->anchors[j] = {w.x_mm, w.y_mm, w.theta_rad};
  }
  return true;
}

// One corner cost per frame, and each landmark's corner offsets with their prior (held at the
// printed geometry until the first solve has measured each landmark's wear).
void add_frame_costs(const LandmarkMap& map, const std::array<Vec2, 8>& lc, const Options& opt,
                     Solve* s) {
  for (const SubPass& sp : s->subs) {
    for (size_t i : sp.frames) s->lm_index.emplace(s->obs[i].landmark_id, 0);
  }
  {
    size_t k = 0;
    for (auto& [id, i] : s->lm_index) i = k++;
  }
  s->offsets.resize(s->lm_index.size());
  for (auto& a : s->offsets) a.fill(0.0);
  s->inv_tau.assign(s->lm_index.size(), 1.0 / std::max(opt.min_print_offset_mm, 1e-6));
  const double scale = opt.fx_px / opt.pixel_sigma_px;
  for (size_t j = 0; j < s->subs.size(); ++j) {
    const double ta = static_cast<double>(s->obs[s->subs[j].frames.front()].t_ns - s->t_ref) * 1e-9;
    for (size_t i : s->subs[j].frames) {
      const CornerObservation& o = s->obs[i];
      auto* fc = new FrameCost;
      fc->od = &s->od;
      fc->t_anchor_s = ta;
      fc->t_frame_s = static_cast<double>(o.t_ns - s->t_ref) * 1e-9;
      fc->landmark = map.find(o.landmark_id)->pose;
      fc->local = lc;
      fc->xn = o.xn;
      fc->valid = o.valid;
      fc->scale = scale;
      const size_t li = s->lm_index.at(o.landmark_id);
      const int n_valid = static_cast<int>(std::count(o.valid.begin(), o.valid.end(), true));
      s->frame_blocks.push_back(s->problem.AddResidualBlock(
          new ceres::AutoDiffCostFunction<FrameCost, 16, kMount, kOdo, 1, 3, 16>(fc),
          // Robust: a frame whose corners are off (blur, a mis-fitted edge) by much more than the
          // noise counts linearly, not quadratically (squared norm of the block in sigma units).
          opt.robust_sigmas > 0.0
              ? new ceres::HuberLoss(opt.robust_sigmas *
                                     std::sqrt(2.0 * static_cast<double>(n_valid)))
              : nullptr,
          s->mount, s->odo, s->dt, s->anchors[j].data(), s->offsets[li].data()));
      s->frame_costs.push_back(fc);
      s->frame_pass.push_back(s->subs[j].pass);
      s->frame_lm.push_back(li);
      s->frame_nvalid.push_back(n_valid);
    }
  }
  for (size_t li = 0; li < s->offsets.size(); ++li) {
    s->problem.AddResidualBlock(
        new ceres::AutoDiffCostFunction<OffsetPrior, 16, 16>(new OffsetPrior{&s->inv_tau[li]}),
        nullptr, s->offsets[li].data());
    s->problem.SetParameterBlockConstant(s->offsets[li].data());
  }
}

// The odometry between consecutive sub-pass anchors; returns the total turn (rad) it covers.
double add_links(const Options& opt, Solve* s) {
  const OdomTable& od = s->od;
  const double period = od.t.size() > 1 ? (od.t.back() - od.t.front()) / (od.t.size() - 1) : 0.01;
  double total_turn = 0.0;
  for (size_t j = 0; j + 1 < s->subs.size(); ++j) {
    auto* lk = new LinkCost;
    lk->od = &od;
    lk->t_a_s = static_cast<double>(s->obs[s->subs[j].frames.front()].t_ns - s->t_ref) * 1e-9;
    lk->t_b_s = static_cast<double>(s->obs[s->subs[j + 1].frames.front()].t_ns - s->t_ref) * 1e-9;
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
    s->problem.AddResidualBlock(new ceres::AutoDiffCostFunction<LinkCost, 3, kOdo, 1, 3, 3>(lk),
                                nullptr, s->odo, s->dt, s->anchors[j].data(),
                                s->anchors[j + 1].data());
  }
  return total_turn;
}

// RMS corner residual (px) per pass, per landmark and overall, with the printed geometry (the
// corner offsets set to zero for the evaluation): what the print and the calibration explain.
void rms_px(const Options& opt, Solve& s, std::vector<double>* per_pass,
            std::vector<double>* per_lm, double* all) {
  const auto saved = s.offsets;
  for (auto& a : s.offsets) a.fill(0.0);
  std::vector<double> ss(s.passes.size(), 0.0), sl(s.offsets.size(), 0.0);
  std::vector<int> cnt(s.passes.size(), 0), cl(s.offsets.size(), 0);
  double sa = 0;
  int ca = 0;
  for (size_t b = 0; b < s.frame_blocks.size(); ++b) {
    double cost = 0;
    s.problem.EvaluateResidualBlock(s.frame_blocks[b], false, &cost, nullptr, nullptr);
    // cost = 0.5 |r|^2, r in units of the block's sigma: back to pixels.
    const double px_per_unit = opt.fx_px / s.frame_costs[b]->scale;
    const double sq = 2.0 * cost * px_per_unit * px_per_unit;
    const int nv = std::max(s.frame_nvalid[b], 1);
    ss[static_cast<size_t>(s.frame_pass[b])] += sq;
    cnt[static_cast<size_t>(s.frame_pass[b])] += nv;
    sl[s.frame_lm[b]] += sq;
    cl[s.frame_lm[b]] += nv;
    sa += sq;
    ca += nv;
  }
  s.offsets = saved;
  per_pass->resize(s.passes.size());
  for (size_t p = 0; p < s.passes.size(); ++p) {
    (*per_pass)[p] = cnt[p] > 0 ? std::sqrt(ss[p] / cnt[p]) : 0.0;
  }
  per_lm->resize(s.offsets.size());
  for (size_t l = 0; l < s.offsets.size(); ++l) {
    (*per_lm)[l] = cl[l] > 0 ? std::sqrt(sl[l] / cl[l]) : 0.0;
  }
  *all = ca > 0 ? std::sqrt(sa / ca) : 0.0;
}

// The solve with the printed geometry, then (model_wear) with each landmark's measured wear.
bool solve(const Options& opt, Solve* s, Result* out, std::string* why) {
  ceres::Solver::Options so;
  so.linear_solver_type = ceres::SPARSE_SCHUR;
  so.max_num_iterations = opt.max_iterations;
  so.function_tolerance = 1e-12;
  so.parameter_tolerance = 1e-12;
  so.gradient_tolerance = 1e-14;
  so.num_threads = 2;
  ceres::Solver::Summary summary;
  ceres::Solve(so, &s->problem, &summary);
  if (!summary.IsSolutionUsable()) {
    *why = "the solver failed: " + summary.message;
    return false;
  }
  out->iterations = static_cast<int>(summary.iterations.size());
  s->wear.resize(s->offsets.size());
  if (!opt.model_wear) return true;
  measure_wear(s->problem, s->frame_blocks, s->frame_costs, s->frame_lm, opt, &s->wear);
  for (size_t b = 0; b < s->frame_costs.size(); ++b) {
    s->frame_costs[b]->scale = opt.fx_px / s->wear[s->frame_lm[b]].sigma_px;
  }
  for (size_t li = 0; li < s->offsets.size(); ++li) {
    s->inv_tau[li] = 1.0 / s->wear[li].tau_mm;
    s->offsets[li] = s->wear[li].mean_offset_mm;
    s->problem.SetParameterBlockVariable(s->offsets[li].data());
  }
  ceres::Solve(so, &s->problem, &summary);
  if (!summary.IsSolutionUsable()) {
    *why = "the solver failed: " + summary.message;
    return false;
  }
  out->iterations += static_cast<int>(summary.iterations.size());
  return true;
}

// Whatever the per-landmark model leaves: the covariance grows with the reduced chi-square of
// the corner residuals (never shrinks below the stated pixel noise).
double chi2_scale(const Options& opt, Solve& s) {
  if (!opt.model_wear) return 1.0;
  double chi2 = 0.0;
  double n_res = 0.0;
  for (size_t b = 0; b < s.frame_blocks.size(); ++b) {
    double cost = 0;
    s.problem.EvaluateResidualBlock(s.frame_blocks[b], false, &cost, nullptr, nullptr);
    chi2 += 2.0 * cost;
    n_res += 2.0 * s.frame_nvalid[b];
  }
  const double dof =
      n_res - 3.0 * static_cast<double>(s.subs.size()) - 16.0 * s.offsets.size() - kNumGlobal;
  return dof > 0 ? std::max(1.0, chi2 / dof) : 1.0;
}

// Everything up to the solve: false with *why.
bool build(const std::vector<OdomSample>& odom, const std::vector<CornerObservation>& obs_in,
           const LandmarkMap& map, const std::array<Vec2, 8>& lc, const VehicleParams& initial,
           const Options& opt, Solve* s, Result* out, std::string* why) {
  if (odom.size() < 2) {
    *why = "the recording has no odometry (odom.csv has " + std::to_string(odom.size()) +
           " rows): the odometry scales, bias and time offset need it";
    return false;
  }
  if (obs_in.empty()) {
    *why = "no frame shows a landmark (nothing to calibrate against)";
    return false;
  }
  s->t_ref = obs_in.front().t_ns;
  if (!load_odometry(odom, opt, s, why) ||
      !select_observations(obs_in, map, initial, s, out, why) || !find_passes(opt, s, why) ||
      !initial_values(map, initial, lc, s, why)) {
    return false;
  }
  add_frame_costs(map, lc, opt, s);
  const double total_turn = add_links(opt, s);
  out->turns_seen = total_turn > kPi;
  if (!out->turns_seen) {
    out->warnings.push_back(
        "the drive turns only " + std::to_string(static_cast<int>(deg(total_turn))) +
        " deg in total: the yaw-rate scale and the mounting offset are not observable without "
        "turns (drive the turns on the spot of the calibration pattern)");
  }
  s->problem.SetParameterLowerBound(s->mount, 3, 10.0);
  return true;
}

}  // namespace
}  // namespace detail

std::array<Vec2, 8> landmark_corners(double ho, double hi) {
  return {Vec2{ho, ho}, Vec2{-ho, ho}, Vec2{-ho, -ho}, Vec2{ho, -ho},
          Vec2{hi, hi}, Vec2{-hi, hi}, Vec2{-hi, -hi}, Vec2{hi, -hi}};
}

bool calibrate_vehicle(const std::vector<OdomSample>& odom,
                       const std::vector<CornerObservation>& obs_in, const LandmarkMap& map,
                       double outer_half_mm, double inner_half_mm, const VehicleParams& initial,
                       const Options& opt, Result* out, std::string* error) {
  std::string why;
  auto fail = [&] {
    if (error) *error = why;
    return false;
  };
  const std::array<Vec2, 8> lc = landmark_corners(outer_half_mm, inner_half_mm);
  // Large, and never moved: the problem points into it.
  auto s = std::make_unique<detail::Solve>();
  if (!detail::build(odom, obs_in, map, lc, initial, opt, s.get(), out, &why)) return fail();
  detail::rms_px(opt, *s, &s->before, &s->lm_before, &out->rms_before_px);
  if (!detail::solve(opt, s.get(), out, &why)) return fail();
  detail::rms_px(opt, *s, &s->after, &s->lm_after, &out->rms_after_px);
  s->chi2_scale = detail::chi2_scale(opt, *s);
  detail::report(opt, initial, *s, out);
  return true;
}

}  // namespace agv::desk::vcal
