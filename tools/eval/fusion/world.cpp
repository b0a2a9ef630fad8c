// eval_fusion: the simulated drive (synthetic grid or lawnmower route) or a recording's truth and
// odometry.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <random>

#include "agv/fusion/motion_model.hpp"
#include "eval_fusion.hpp"

#ifdef AGV_EVAL_HAVE_RECORDING
#include "agv/recording/recording.hpp"
#endif

namespace eval_fusion {

namespace {

// Trapezoidal profile: speed at time t for a move of length d with limits vmax, a.
struct Profile {
  double d, vmax, a, t_acc, t_cruise, total;
  Profile(double d_in, double vmax_in, double a_in) : d(d_in), vmax(vmax_in), a(a_in) {
    t_acc = vmax / a;
    if (a * t_acc * t_acc > d) {  // triangle
      t_acc = std::sqrt(d / a);
      vmax = a * t_acc;
    }
    t_cruise = (d - a * t_acc * t_acc) / vmax;
    total = 2.0 * t_acc + t_cruise;
  }
  double speed(double t) const {
    if (t <= 0.0 || t >= total) return 0.0;
    if (t < t_acc) return a * t;
    if (t < t_acc + t_cruise) return vmax;
    return a * (total - t);
  }
};

constexpr double kDt = 1e-3;  // truth integration step
constexpr std::int64_t kDtNs = 1'000'000;
constexpr int kOdomEvery = 10;                 // 100 Hz
constexpr std::int64_t kFrameNs = 33'333'333;  // 30 fps

// The vehicle's truth integrated in 1 ms steps, with the odometry (100 Hz) and the gyro sampled
// from it. The odometry, the varying slips and the gyro draw from generators of their own (one
// normal and one uniform distribution shared by all three), so adding one leaves the others of a
// seed unchanged.
class Drive {
 public:
  Drive(const SynthParams& p, World* w)
      : p_(p),
        w_(w),
        rng_(p.seed),
        srng_(p.seed * 104729 + 11),
        bias_(agv::deg_to_rad(p.drift_degps)),
        grng_(p.seed * 7919 + 3),
        gyro_every_(p.gyro_hz > 0.0 ? std::max(1, static_cast<int>(std::lround(1000.0 / p.gyro_hz)))
                                    : 0) {
    w_->truth.t_ns.push_back(0);
    w_->truth.pose.push_back({0.0, 0.0, 0.0});
  }

  // One truth step at speed v and yaw rate om, and the sensor samples due at its end.
  void advance(double v, double om) {
    x_(agv::fusion::kIv) = v;
    x_(agv::fusion::kIomega) = om;
    x_ = agv::fusion::motion_predict(x_, kDt);
    acc_dist_m_ += v * kDt;
    acc_turn_rad_ += om * kDt;
    t_ += kDtNs;
    ++step_;
    w_->truth.t_ns.push_back(t_);
    w_->truth.pose.push_back({x_(0), x_(1), x_(2)});
    gyro_turn_rad_ += om * kDt;
    if (p_.slip_varying) varying_slip(v);
    if (gyro_every_ > 0 && step_ % gyro_every_ == 0) gyro_sample();
    if (step_ % kOdomEvery == 0) odom_sample();
  }

  void dwell(double s) {
    for (int i = 0; i < static_cast<int>(s / kDt); ++i) advance(0.0, 0.0);
  }

  std::int64_t t() const { return t_; }
  std::mt19937_64& rng() { return rng_; }

 private:
  // Varying slips (p.slip_varying): decided per 1 ms truth step.
  void varying_slip(double v) {
    if (t_ < slip_end_ns_) {
      slip_frac_ = std::clamp(slip_frac_ + 0.3 * std::sqrt(kDt) * n01_(srng_), 0.0, 0.6);
      slip_acc_m_ += slip_frac_ * std::abs(v) * kDt;
    } else if (u01_(srng_) < p_.slip_rate_hz * kDt) {
      slip_end_ns_ = t_ + static_cast<std::int64_t>((0.15 + 0.35 * u01_(srng_)) * 1e9);
      slip_frac_ = 0.1 + 0.3 * u01_(srng_);
      slip_sign_ = (srng_() % 2 == 0) ? 1.0 : -1.0;
    }
  }

  void gyro_sample() {
    const SynthParams& p = p_;
    const double T = kDt * gyro_every_;
    const double ts = static_cast<double>(t_) * 1e-9;
    gyro_walk_radps_ += agv::deg_to_rad(p.gyro_bias_walk_degps_rts) * std::sqrt(T) * n01_(grng_);
    double gbias = agv::deg_to_rad(p.gyro_bias_degps) + gyro_walk_radps_;
    if (p.gyro_bias_step_degps != 0.0 && ts >= p.gyro_bias_step_s)
      gbias += agv::deg_to_rad(p.gyro_bias_step_degps);
    double g = (1.0 + p.gyro_scale_error) * gyro_turn_rad_ / T + gbias +
               agv::deg_to_rad(p.gyro_noise_degps_rthz) / std::sqrt(T) * n01_(grng_);
    const double range = agv::deg_to_rad(p.gyro_range_degps);
    g = std::clamp(g, -range, range);
    w_->gyro.push_back({t_ + static_cast<std::int64_t>(p.gyro_latency_ms * 1e6), g});
    gyro_turn_rad_ = 0.0;
  }

  void odom_sample() {
    const SynthParams& p = p_;
    const double T = kDt * kOdomEvery;
    const double v_mean = acc_dist_m_ / T, om_mean = acc_turn_rad_ / T;
    const double ts = static_cast<double>(t_) * 1e-9;
    const double b = bias_ * (1.0 + p.drift_variation * std::sin(2.0 * agv::kPi * ts / 120.0)) +
                     agv::deg_to_rad(p.drift_degpm) * v_mean;
    double v_meas = v_mean * (1.0 + p.scale_error) + p.v_noise_mps * n01_(rng_);
    double om_meas = om_mean * (1.0 + p.scale_error) + b + p.omega_noise_radps * n01_(rng_);
    if (p.slip_varying) {
      const double extra_mps = slip_acc_m_ / T;
      v_meas += 0.5 * extra_mps;
      om_meas += slip_sign_ * extra_mps / (p.wheelbase_mm / 1000.0);
      slip_acc_m_ = 0.0;
    } else if (t_ < slip_end_ns_) {  // one wheel over-reports: half of it in v, all of it in omega
      const double extra_mps = 0.25 * std::abs(v_mean);
      v_meas += 0.5 * extra_mps;
      om_meas += slip_sign_ * extra_mps / (p.wheelbase_mm / 1000.0);
    } else if (u01_(rng_) < p.slip_rate_hz * T) {
      slip_end_ns_ = t_ + 300 * kMsNs;
      slip_sign_ = (rng_() % 2 == 0) ? 1.0 : -1.0;
    }
    w_->odom.push_back({t_, v_meas, om_meas});
    acc_dist_m_ = acc_turn_rad_ = 0.0;
  }

  const SynthParams& p_;
  World* w_;
  std::mt19937_64 rng_;
  std::normal_distribution<double> n01_{0.0, 1.0};
  std::uniform_real_distribution<double> u01_{0.0, 1.0};
  std::int64_t slip_end_ns_ = -1;
  double slip_sign_ = 1.0;
  std::mt19937_64 srng_;
  double slip_frac_ = 0.0, slip_acc_m_ = 0.0;
  const double bias_;
  agv::fusion::StateVec x_ = agv::fusion::StateVec::Zero();
  std::int64_t t_ = 0;
  long step_ = 0;
  double acc_dist_m_ = 0.0, acc_turn_rad_ = 0.0;
  std::mt19937_64 grng_;
  const int gyro_every_;
  double gyro_turn_rad_ = 0.0, gyro_walk_radps_ = 0.0;
};

// Start 1 m before the first landmark of row 0, ramp up, then rows back and forth.
void drive_lawnmower(const SynthParams& p, double grid_mm, std::int64_t end_ns, Drive* d) {
  const double v = p.v_max_mps;
  const Profile ramp(1.0, v, p.accel_mps2);
  for (int i = 0; i < static_cast<int>(std::ceil(ramp.t_acc / kDt)); ++i)
    d->advance(p.accel_mps2 * (i + 0.5) * kDt, 0.0);
  double sign = 1.0;  // left turns going +x, right turns going -x: rows stack up in +y
  while (d->t() < end_ns) {
    const double straight_m = (p.grid_cells - 1) * grid_mm / 1000.0 + 2.0 * p.lawnmower_out_m;
    const double first_m =
        (d->t() < 3'000'000'000LL) ? straight_m - 0.5 * ramp.t_acc * v : straight_m;
    for (int i = 0; i < static_cast<int>(first_m / v / kDt); ++i) d->advance(v, 0.0);
    // Whole 1 ms steps turning exactly pi, so the rows stay on the landmark lines.
    const double radius_m = 0.5 * grid_mm / 1000.0;
    const int n = static_cast<int>(std::lround(agv::kPi * radius_m / v / kDt));
    const double om = agv::kPi / (n * kDt);
    for (int i = 0; i < n; ++i) d->advance(om * radius_m, sign * om);
    sign = -sign;
  }
}

// A random route along the grid's lines: runs of 1..8 cells, turns in place on landmarks.
void drive_grid(const SynthParams& p, double grid_mm, std::int64_t end_ns, Drive* d) {
  std::mt19937_64& rng = d->rng();
  int cx = 0, cy = 0, dir = 0;  // grid cell and heading (0:+x 1:+y 2:-x 3:-y)
  const int dxs[4] = {1, 0, -1, 0}, dys[4] = {0, 1, 0, -1};
  while (d->t() < end_ns) {
    // Longest run possible in the current direction, then a random length 1..8 within it.
    int room = 0;
    while (room < 8) {
      const int nx = cx + dxs[dir] * (room + 1), ny = cy + dys[dir] * (room + 1);
      if (nx < 0 || ny < 0 || nx >= p.grid_cells || ny >= p.grid_cells) break;
      ++room;
    }
    if (room > 0) {
      const int cells = 1 + static_cast<int>(rng() % static_cast<std::uint64_t>(room));
      const Profile prof(cells * grid_mm / 1000.0, p.v_max_mps, p.accel_mps2);
      const int n = static_cast<int>(std::ceil(prof.total / kDt));
      for (int i = 0; i < n; ++i) d->advance(prof.speed((i + 0.5) * kDt), 0.0);
      cx += dxs[dir] * cells;
      cy += dys[dir] * cells;
      d->dwell(0.2);
    }
    // Turn in place on the landmark: +-90 deg, or 180 deg when boxed in.
    const int turn = (room == 0 && rng() % 2 == 0) ? 2 : (rng() % 2 == 0 ? 1 : 3);
    const double angle = (turn == 2 ? agv::kPi : agv::kPi / 2.0);
    const double sign = (turn == 3) ? -1.0 : 1.0;
    const Profile prof(angle, p.omega_max_radps, p.yaw_accel_radps2);
    const int n = static_cast<int>(std::ceil(prof.total / kDt));
    for (int i = 0; i < n; ++i) d->advance(0.0, sign * prof.speed((i + 0.5) * kDt));
    dir = (dir + turn) % 4;
    d->dwell(0.2);
  }
}

}  // namespace

World make_synthetic_world(const SynthParams& p, double grid_mm) {
  World w;
  w.source = "synthetic";
  w.camera_offset_x_mm = p.camera_offset_x_mm;
  Drive d(p, &w);
  const std::int64_t end_ns = static_cast<std::int64_t>(p.duration_s * 1e9);
  d.dwell(1.0);
  if (p.route == "lawnmower") {
    drive_lawnmower(p, grid_mm, end_ns, &d);
  } else {
    drive_grid(p, grid_mm, end_ns, &d);
  }
  for (std::int64_t tf = kFrameNs; tf < d.t(); tf += kFrameNs) w.frames_ns.push_back(tf);
  return w;
}

#ifdef AGV_EVAL_HAVE_RECORDING
bool load_recording_world(const std::string& dir, World* w) {
  agv::recording::Recording rec;
  std::string err;
  if (!agv::recording::read_recording(dir, &rec, &err)) {
    std::fprintf(stderr, "eval_fusion: %s\n", err.c_str());
    return false;
  }
  if (!rec.has_truth || rec.truth.size() < 2 || rec.odom.empty()) {
    std::fprintf(stderr, "eval_fusion: %s needs truth.csv and odom.csv\n", dir.c_str());
    return false;
  }
  w->source = "recording " + dir;
  for (const auto& r : rec.truth) {
    w->truth.t_ns.push_back(r.t_ns);
    w->truth.pose.push_back({r.x_mm, r.y_mm, agv::deg_to_rad(r.theta_deg)});
  }
  for (const auto& r : rec.odom) w->odom.push_back({r.t_ns, r.v_mps, r.omega_radps});
  for (const auto& f : rec.frames) w->frames_ns.push_back(f.t_ns);
  w->camera_offset_x_mm = rec.meta.camera.mount.offset_x_mm;
  w->camera_offset_y_mm = rec.meta.camera.mount.offset_y_mm;
  return true;
}
#endif

}  // namespace eval_fusion
