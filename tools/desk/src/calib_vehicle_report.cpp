// Vehicle calibration: the solved problem (calib_vehicle.cpp) as the report: each global
// parameter with its sigma from the covariance (anchors marginalised) and what it trades off
// against, the passes and the landmarks. Model: calib_vehicle.hpp.
#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <cstdio>

#include "calib_vehicle_problem.hpp"

namespace agv::desk::vcal::detail {

namespace {

// The global parameters' covariance, scaled by the reduced chi-square.
struct GlobalCovariance {
  bool ok = false;
  Eigen::Matrix<double, kNumGlobal, kNumGlobal> c =
      Eigen::Matrix<double, kNumGlobal, kNumGlobal>::Zero();
  double sigma[kNumGlobal];
};

GlobalCovariance global_covariance(Solve& s) {
  ceres::Covariance::Options co;
  // Sparse QR: thousands of anchors; fails (rank deficient) when some direction is not
  // observable at all, which is then reported as such.
  co.algorithm_type = ceres::SPARSE_QR;
  co.num_threads = 2;
  ceres::Covariance cov(co);
  std::vector<std::pair<const double*, const double*>> blocks = {
      {s.mount, s.mount}, {s.odo, s.odo}, {s.dt, s.dt}, {s.mount, s.odo}};
  double cm[kMount * kMount] = {}, cov_odo[kOdo * kOdo] = {}, cdt = 0.0;
  GlobalCovariance g;
  if (cov.Compute(blocks, &s.problem)) {
    g.ok = cov.GetCovarianceBlock(s.mount, s.mount, cm) &&
           cov.GetCovarianceBlock(s.odo, s.odo, cov_odo) &&
           cov.GetCovarianceBlock(s.dt, s.dt, &cdt);
  }
  for (double& v : cm) v *= s.chi2_scale;
  for (double& v : cov_odo) v *= s.chi2_scale;
  cdt *= s.chi2_scale;
  for (int i = 0; i < kMount; ++i)
    g.sigma[i] = g.ok ? std::sqrt(std::max(0.0, cm[i * kMount + i])) : kInf;
  for (int i = 0; i < kOdo; ++i) {
    g.sigma[kMount + i] = g.ok ? std::sqrt(std::max(0.0, cov_odo[i * kOdo + i])) : kInf;
  }
  g.sigma[kNumGlobal - 1] = g.ok ? std::sqrt(std::max(0.0, cdt)) : kInf;
  if (!g.ok) return g;
  for (int i = 0; i < kMount; ++i)
    for (int j = 0; j < kMount; ++j) g.c(i, j) = cm[i * kMount + j];
  for (int i = 0; i < kOdo; ++i)
    for (int j = 0; j < kOdo; ++j) g.c(kMount + i, kMount + j) = cov_odo[i * kOdo + j];
  g.c(kNumGlobal - 1, kNumGlobal - 1) = cdt;
  // Cross blocks.
  double x[kMount * kOdo];
  if (cov.GetCovarianceBlock(s.mount, s.odo, x)) {
    for (int i = 0; i < kMount; ++i)
      for (int j = 0; j < kOdo; ++j) {
        g.c(i, kMount + j) = g.c(kMount + j, i) = s.chi2_scale * x[i * kOdo + j];
      }
  }
  return g;
}

const char* const kNames[kNumGlobal] = {
    "mounting.offset_x_mm",       "mounting.offset_y_mm",    "mounting.yaw_deg",
    "mounting.height_mm",         "mounting.roll_deg",       "mounting.pitch_deg",
    "odometry.speed_scale",       "odometry.yaw_rate_scale", "odometry.yaw_rate_bias_degps",
    "odometry.yaw_per_metre_deg", "camera.time_offset_ms"};

// For each undetermined parameter (sigma over its limit): the parameters it is correlated with
// beyond 0.9, i.e. trades off against.
std::vector<std::string> tradeoffs(const GlobalCovariance& g, const double* limit) {
  std::vector<std::string> tradeoff(kNumGlobal);
  for (int i = 0; i < kNumGlobal; ++i) {
    if (g.sigma[i] <= limit[i]) continue;
    std::string partners;
    for (int j = 0; j < kNumGlobal; ++j) {
      if (j == i || !g.ok || !(g.sigma[j] > 0)) continue;
      const double rho = g.c(i, j) / (g.sigma[i] * g.sigma[j]);
      if (std::abs(rho) > 0.9) partners += (partners.empty() ? "" : ", ") + std::string(kNames[j]);
    }
    tradeoff[static_cast<size_t>(i)] = partners;
  }
  return tradeoff;
}

void parameter_reports(const Options& opt, const VehicleParams& initial, const Solve& s,
                       const GlobalCovariance& g, Result* out) {
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
  const std::vector<std::string> tradeoff = tradeoffs(g, limit);
  const double init[kNumGlobal] = {
      initial.mount.offset_x_mm, initial.mount.offset_y_mm, initial.mount.yaw_rad,
      initial.mount.height_mm,   initial.mount.roll_rad,    initial.mount.pitch_rad,
      initial.speed_scale,       initial.yaw_rate_scale,    initial.yaw_rate_bias_radps,
      initial.yaw_per_metre_rad, initial.time_offset_s};
  const double val[kNumGlobal] = {s.mount[0], s.mount[1], s.mount[2], s.mount[3],
                                  s.mount[4], s.mount[5], s.odo[0],   s.odo[1],
                                  s.odo[2],   s.odo[3],   s.dt[0]};
  const double to_unit[kNumGlobal] = {1, 1, 180 / kPi, 1,         180 / kPi, 180 / kPi,
                                      1, 1, 180 / kPi, 180 / kPi, 1e3};
  const char* units[kNumGlobal] = {"mm", "mm", "deg",   "mm",    "deg", "deg",
                                   "",   "",   "deg/s", "deg/m", "ms"};
  out->params.clear();
  for (int i = 0; i < kNumGlobal; ++i) {
    ParamReport r;
    r.name = kNames[i];
    r.unit = units[i];
    r.initial = init[i] * to_unit[i];
    r.value = val[i] * to_unit[i];
    r.sigma = g.sigma[i] * to_unit[i];
    r.determined = g.ok && g.sigma[i] <= limit[i];
    if (!r.determined) {
      char b[200];
      if (!g.ok) {
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
}

void pass_and_landmark_reports(const Options& opt, const Solve& s, Result* out) {
  out->passes.clear();
  const std::vector<CornerObservation>& obs = s.obs;
  const double t0 = static_cast<double>(obs.front().t_ns - s.t_ref) * 1e-9;
  for (size_t p = 0; p < s.passes.size(); ++p) {
    PassReport pr;
    pr.index = static_cast<int>(p);
    pr.landmark_id = obs[s.passes[p].first].landmark_id;
    pr.t_start_s = static_cast<double>(obs[s.passes[p].first].t_ns - s.t_ref) * 1e-9 - t0;
    pr.t_end_s = static_cast<double>(obs[s.passes[p].second].t_ns - s.t_ref) * 1e-9 - t0;
    pr.frames = static_cast<int>(s.passes[p].second - s.passes[p].first + 1);
    pr.rms_before_px = s.before[p];
    pr.rms_after_px = s.after[p];
    out->passes.push_back(pr);
  }
  out->landmarks.clear();
  for (const auto& [id, li] : s.lm_index) {
    LandmarkReport lr;
    lr.landmark_id = id;
    for (const PassReport& pr : out->passes) {
      if (pr.landmark_id != id) continue;
      ++lr.passes;
      lr.frames += pr.frames;
    }
    lr.rms_before_px = s.lm_before[li];
    lr.rms_after_px = s.lm_after[li];
    lr.sigma_px = opt.model_wear ? s.wear[li].sigma_px : opt.pixel_sigma_px;
    lr.print_offset_mm = opt.model_wear ? s.wear[li].tau_mm : 0.0;
    out->landmarks.push_back(lr);
  }
}

}  // namespace

void report(const Options& opt, const VehicleParams& initial, Solve& s, Result* out) {
  const GlobalCovariance g = global_covariance(s);
  if (!g.ok) {
    out->warnings.push_back(
        "the covariance could not be computed (the problem is rank deficient): no parameter is "
        "written");
  }
  auto& e = out->estimate;
  e.mount.offset_x_mm = s.mount[0];
  e.mount.offset_y_mm = s.mount[1];
  e.mount.yaw_rad = s.mount[2];
  e.mount.height_mm = s.mount[3];
  e.mount.roll_rad = s.mount[4];
  e.mount.pitch_rad = s.mount[5];
  e.speed_scale = s.odo[0];
  e.yaw_rate_scale = s.odo[1];
  e.yaw_rate_bias_radps = s.odo[2];
  e.yaw_per_metre_rad = s.odo[3];
  e.time_offset_s = s.dt[0];
  parameter_reports(opt, initial, s, g, out);
  pass_and_landmark_reports(opt, s, out);
  flag_standing_out(opt, &out->landmarks, &out->warnings);
  out->frames_used = static_cast<int>(s.frame_blocks.size());
  out->subpasses = static_cast<int>(s.subs.size());
}

}  // namespace agv::desk::vcal::detail
