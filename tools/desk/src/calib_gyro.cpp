// Gyro scale, bias and clock offset from a calibration drive (model: calib_gyro.hpp).
#include "calib_gyro.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>

namespace agv::desk::vcal {

namespace {

constexpr int kN = 4;  // alpha, s, c, d (= delta tau)
using Vec = std::array<double, kN>;
using Mat = std::array<std::array<double, kN>, kN>;

// Integral of the raw gyro samples: sample k is the mean rate over (t_{k-1}, t_k].
class GyroIntegral {
 public:
  explicit GyroIntegral(const std::vector<GyroSample>& g) : g_(g), cum_(g.size(), 0.0) {
    for (size_t k = 1; k < g_.size(); ++k) {
      cum_[k] =
          cum_[k - 1] + g_[k].rate_radps * 1e-9 * static_cast<double>(g_[k].t_ns - g_[k - 1].t_ns);
    }
  }
  std::int64_t first_ns() const { return g_.front().t_ns; }
  std::int64_t last_ns() const { return g_.back().t_ns; }
  // Integral from the first sample to t (seconds relative to the first sample) and the rate there.
  void at(double t_s, double* integral, double* rate) const {
    const double t_abs = static_cast<double>(g_.front().t_ns) + t_s * 1e9;
    auto it = std::lower_bound(g_.begin(), g_.end(), t_abs, [](const GyroSample& s, double t) {
      return static_cast<double>(s.t_ns) < t;
    });
    size_t k = static_cast<size_t>(it - g_.begin());
    k = std::clamp<size_t>(k, 1, g_.size() - 1);
    *rate = g_[k].rate_radps;
    *integral =
        cum_[k - 1] + g_[k].rate_radps * (t_abs - static_cast<double>(g_[k - 1].t_ns)) * 1e-9;
  }

 private:
  const std::vector<GyroSample>& g_;
  std::vector<double> cum_;
};

struct Frame {
  double t_s = 0.0;  // camera clock, relative to the first gyro sample
  double h = 0.0;    // heading from the fix
  int pass = 0;
  bool used = true;
  double resid = 0.0;  // last solve: h - model without alpha (unwrapped), minus the local alpha
};

struct Solve {
  Vec x{};
  Mat p{};
  double chi2 = 0.0;
  int n = 0;
  double turned = 0.0;
};

// Kalman filter over the used frames; tau0 the linearisation point (s), prior sigmas on s, c, d.
Solve run_filter(const std::vector<Frame>& frames, const GyroIntegral& gi, double tau0,
                 double r_var, double q_density, double s0, double s_sigma) {
  Solve out;
  Vec& x = out.x;
  Mat& p = out.p;
  x = {0.0, s0, 0.0, 0.0};
  for (auto& row : p) row.fill(0.0);
  p[0][0] = 1e4;
  p[1][1] = s_sigma * s_sigma;
  p[2][2] = std::pow(30.0 * kPi / 180.0, 2);
  p[3][3] = 0.2 * 0.2;
  bool first = true;
  double last_t = 0.0, last_g = 0.0;
  for (const Frame& f : frames) {
    if (!f.used) continue;
    const double tg = f.t_s + tau0;
    double g = 0.0, w = 0.0;
    gi.at(tg, &g, &w);
    if (!first) {
      const double dt = std::max(tg - last_t, 0.0);
      p[0][0] += q_density * q_density * dt;
      out.turned += std::abs(g - last_g);
    }
    const Vec hrow = {1.0, g, tg, w};
    double pred = 0.0;
    for (int i = 0; i < kN; ++i) pred += hrow[static_cast<size_t>(i)] * x[static_cast<size_t>(i)];
    if (first) {
      x[0] = f.h - (pred - x[0]);  // alpha from the first frame
      pred = f.h;
    }
    const double nu = wrap_angle_rad(f.h - pred);
    Vec ph{};
    for (size_t i = 0; i < kN; ++i) {
      for (size_t j = 0; j < kN; ++j) ph[i] += p[i][j] * hrow[j];
    }
    double s = r_var;
    for (size_t i = 0; i < kN; ++i) s += hrow[i] * ph[i];
    for (size_t i = 0; i < kN; ++i) x[i] += ph[i] / s * nu;
    for (size_t i = 0; i < kN; ++i) {
      for (size_t j = 0; j < kN; ++j) p[i][j] -= ph[i] * ph[j] / s;
    }
    if (!first) {
      out.chi2 += nu * nu / s;
      ++out.n;
    }
    first = false;
    last_t = tg;
    last_g = g;
  }
  return out;
}

double median(std::vector<double> v) {
  if (v.empty()) return 0.0;
  const size_t m = v.size() / 2;
  std::nth_element(v.begin(), v.begin() + static_cast<std::ptrdiff_t>(m), v.end());
  return v[m];
}

// Residuals of every frame under (s, c, d, tau0) with the constant alpha removed per window:
// h - s G - c t - d w, unwrapped along the frames; then each frame minus the median of its
// neighbours (+-3 frames of the same pass). Returns the robust noise sigma (first differences).
double residuals(std::vector<Frame>* frames, const GyroIntegral& gi, double tau0, const Vec& x) {
  std::vector<double> a(frames->size());
  double prev = 0.0;
  for (size_t i = 0; i < frames->size(); ++i) {
    const Frame& f = (*frames)[i];
    const double tg = f.t_s + tau0;
    double g = 0.0, w = 0.0;
    gi.at(tg, &g, &w);
    const double v = f.h - x[1] * g - x[2] * tg - x[3] * w;
    a[i] = i == 0 ? v : prev + wrap_angle_rad(v - prev);
    prev = a[i];
  }
  std::vector<double> diffs;
  for (size_t i = 0; i < frames->size(); ++i) {
    std::vector<double> nb;
    for (size_t j = i >= 3 ? i - 3 : 0; j < std::min(frames->size(), i + 4); ++j) {
      if (j != i && (*frames)[j].pass == (*frames)[i].pass) nb.push_back(a[j]);
    }
    (*frames)[i].resid = nb.size() >= 2 ? a[i] - median(nb) : 0.0;
    if (i > 0 && (*frames)[i - 1].pass == (*frames)[i].pass)
      diffs.push_back(std::abs(a[i] - a[i - 1]));
  }
  return diffs.size() >= 5 ? 1.4826 * median(diffs) / std::sqrt(2.0) : 0.0;
}

std::string fmt(const char* f, double v) {
  char b[64];
  std::snprintf(b, sizeof b, f, v);
  return b;
}

}  // namespace

bool frame_heading(const CornerObservation& o, const LandmarkMap& map, double outer_half_mm,
                   double inner_half_mm, const CameraMount& mount, double* heading_rad) {
  const auto e = map.entries.find(o.landmark_id);
  if (e == map.entries.end()) return false;
  const auto corners = landmark_corners(outer_half_mm, inner_half_mm);
  double r[9];
  mount.rotation_vehicle_from_camera(r);
  std::vector<Vec2> q, v;
  for (size_t c = 0; c < 8; ++c) {
    if (!o.valid[c]) continue;
    const double d[3] = {o.xn[c].x, o.xn[c].y, 1.0};
    const double dx = r[0] * d[0] + r[1] * d[1] + r[2] * d[2];
    const double dy = r[3] * d[0] + r[4] * d[1] + r[5] * d[2];
    const double dz = r[6] * d[0] + r[7] * d[1] + r[8] * d[2];
    if (!(dz < -1e-9)) return false;  // ray does not reach the floor
    const double lambda = -mount.height_mm / dz;
    v.push_back({mount.offset_x_mm + lambda * dx, mount.offset_y_mm + lambda * dy});
    q.push_back(corners[c]);
  }
  Pose2 v_from_l;
  if (q.size() < 3 || !fit_rigid(q, v, &v_from_l)) return false;
  const double yaw_in_vehicle = v_from_l.theta_rad;  // landmark frame -> vehicle frame
  *heading_rad = wrap_angle_rad(e->second.pose.theta_rad - yaw_in_vehicle);
  return std::isfinite(*heading_rad);
}

bool calibrate_gyro(const std::vector<GyroSample>& gyro, const std::vector<CornerObservation>& obs,
                    const LandmarkMap& map, double outer_half_mm, double inner_half_mm,
                    const CameraMount& mount, double initial_scale, double initial_clock_offset_s,
                    const GyroOptions& opt, GyroResult* out, std::string* error) {
  *out = GyroResult{};
  if (gyro.size() < 10) {
    *error = "imu.csv has " + std::to_string(gyro.size()) + " gyro samples";
    return false;
  }
  for (size_t k = 1; k < gyro.size(); ++k) {
    if (gyro[k].t_ns <= gyro[k - 1].t_ns) {
      *error = "imu.csv stamps do not increase at row " + std::to_string(k + 1);
      return false;
    }
  }
  const GyroIntegral gi(gyro);
  const double span_s = 1e-9 * static_cast<double>(gi.last_ns() - gi.first_ns());
  std::vector<CornerObservation> sorted = obs;
  std::stable_sort(sorted.begin(), sorted.end(),
                   [](const auto& a, const auto& b) { return a.t_ns < b.t_ns; });
  std::vector<Frame> frames;
  int pass = 0;
  std::uint32_t last_id = 0;
  double last_t = -1e9;
  for (const auto& o : sorted) {
    Frame f;
    // Camera time relative to the first gyro sample (the gyro clock's origin).
    f.t_s = 1e-9 * static_cast<double>(o.t_ns - gi.first_ns());
    const double tg = f.t_s + initial_clock_offset_s;
    if (tg < 0.05 || tg > span_s - 0.05) continue;  // outside the gyro's span (with margin)
    if (!frame_heading(o, map, outer_half_mm, inner_half_mm, mount, &f.h)) continue;
    if (o.landmark_id != last_id || f.t_s - last_t > 0.2) ++pass;
    f.pass = pass;
    last_id = o.landmark_id;
    last_t = f.t_s;
    frames.push_back(f);
  }
  out->frames = static_cast<int>(frames.size());
  if (frames.size() < 10) {
    *error = "only " + std::to_string(frames.size()) +
             " frames with a landmark heading fall inside the gyro samples' time span";
    return false;
  }
  const double q = opt.noise_density_radps_rthz * std::max(initial_scale, 0.1);
  auto solve = [&](double s_sigma, double* tau, double* sigma_h) {
    double r_sigma = std::max(*sigma_h, opt.min_heading_sigma_rad);
    Solve sol;
    for (int it = 0; it < opt.relinearisations; ++it) {
      sol = run_filter(frames, gi, *tau, r_sigma * r_sigma, q, initial_scale, s_sigma);
      const double noise = residuals(&frames, gi, *tau, sol.x);
      if (noise > 0.0) r_sigma = std::max(noise, opt.min_heading_sigma_rad);
      // Relinearise the clock offset: d = s * delta tau.
      *tau += sol.x[3] / std::max(sol.x[1], 0.1);
      for (Frame& f : frames) f.used = std::abs(f.resid) <= opt.outlier_sigmas * r_sigma;
    }
    sol = run_filter(frames, gi, *tau, r_sigma * r_sigma, q, initial_scale, s_sigma);
    *sigma_h = r_sigma;
    return sol;
  };
  double tau = initial_clock_offset_s, sigma_h = deg_to_rad(0.02);
  Solve sol = solve(0.2, &tau, &sigma_h);
  auto fill = [&](const Solve& s) {
    const double k = std::max(1.0, s.n > 0 ? s.chi2 / s.n : 1.0);
    out->chi2_per_frame = s.n > 0 ? s.chi2 / s.n : 0.0;
    out->scale = s.x[1];
    out->scale_sigma = std::sqrt(std::max(s.p[1][1] * k, 0.0));
    out->bias_radps = s.x[2];
    out->bias_sigma_radps = std::sqrt(std::max(s.p[2][2] * k, 0.0));
    out->clock_offset_s = tau;
    out->clock_offset_sigma_s = std::sqrt(std::max(s.p[3][3] * k, 0.0));
    out->turned_deg = rad_to_deg(s.turned);
    out->frames_used = s.n + 1;
  };
  fill(sol);
  out->scale_determined = out->scale_sigma <= opt.max_sigma_scale;
  if (!out->scale_determined) {
    out->why_scale = "sigma " + fmt("%.5f", out->scale_sigma) + " > " +
                     fmt("%.4f", opt.max_sigma_scale) + ": the fixes saw " +
                     fmt("%.0f", out->turned_deg) +
                     " deg of heading change in all; the gyro scale needs turns between fixes "
                     "(the calibration pattern's turns on the spot over a landmark)";
    // The bias for the configured scale.
    tau = initial_clock_offset_s;
    sol = solve(1e-9, &tau, &sigma_h);
    fill(sol);
    out->scale = initial_scale;
    out->scale_sigma = 0.0;
    out->scale_fixed = true;
  }
  out->heading_sigma_deg = rad_to_deg(sigma_h);
  out->frames_rejected = 0;
  for (const Frame& f : frames) out->frames_rejected += f.used ? 0 : 1;
  const double bias_sigma_degps = rad_to_deg(out->bias_sigma_radps);
  out->bias_determined = bias_sigma_degps <= opt.max_sigma_bias_degps;
  if (!out->bias_determined) {
    out->why_bias = "sigma " + fmt("%.4f", bias_sigma_degps) + " deg/s > " +
                    fmt("%.3f", opt.max_sigma_bias_degps) +
                    ": too little time between fixes far apart (a longer drive)";
  }
  out->clock_offset_determined = out->clock_offset_sigma_s * 1e3 <= opt.max_sigma_time_ms;
  if (!out->clock_offset_determined) {
    out->why_clock_offset = "sigma " + fmt("%.2f", out->clock_offset_sigma_s * 1e3) + " ms > " +
                            fmt("%.2f", opt.max_sigma_time_ms) +
                            ": needs turns with a landmark in view";
  }
  out->prior_scale_sigma = std::max(opt.sigma_factor * out->scale_sigma, opt.min_scale_sigma);
  out->prior_bias_sigma_degps =
      std::max(opt.sigma_factor * bias_sigma_degps, opt.min_bias_sigma_degps);
  if (out->frames_rejected > 0) {
    out->warnings.push_back(
        std::to_string(out->frames_rejected) + " of " + std::to_string(out->frames) +
        " landmark frames disagree with the gyro by more than " + fmt("%.0f", opt.outlier_sigmas) +
        " heading-noise sigmas and were left out of the gyro calibration");
  }
  if (out->chi2_per_frame > 4.0) {
    out->warnings.push_back("gyro calibration: fix headings scatter " +
                            fmt("%.1f", std::sqrt(out->chi2_per_frame)) +
                            " x more than the frame noise explains (systematic heading errors: "
                            "mounting, worn landmarks); sigmas scaled up accordingly");
  }
  return true;
}

}  // namespace agv::desk::vcal
