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

}  // namespace

World make_synthetic_world(const SynthParams& p, double grid_mm) {
  World w;
  w.source = "synthetic";
  w.camera_offset_x_mm = p.camera_offset_x_mm;
  std::mt19937_64 rng(p.seed);
  std::normal_distribution<double> n01(0.0, 1.0);
  std::uniform_real_distribution<double> u01(0.0, 1.0);
  std::int64_t slip_end_ns = -1;
  double slip_sign = 1.0;
  // Varying slips (p.slip_varying): their own generator, decided per 1 ms truth step.
  std::mt19937_64 srng(p.seed * 104729 + 11);
  double slip_frac = 0.0, slip_acc_m = 0.0;
  const double dt = 1e-3;  // truth integration step
  const std::int64_t dt_ns = 1'000'000;
  const int odom_every = 10;  // 100 Hz
  const double bias = agv::deg_to_rad(p.drift_degps);

  agv::fusion::StateVec x = agv::fusion::StateVec::Zero();
  std::int64_t t = 0;
  long step = 0;
  double acc_dist_m = 0.0, acc_turn_rad = 0.0;
  // Gyro: its own generator, so adding it leaves the odometry of a seed unchanged.
  std::mt19937_64 grng(p.seed * 7919 + 3);
  const int gyro_every =
      p.gyro_hz > 0.0 ? std::max(1, static_cast<int>(std::lround(1000.0 / p.gyro_hz))) : 0;
  double gyro_turn_rad = 0.0, gyro_walk_radps = 0.0;
  auto advance = [&](double v, double om) {
    x(agv::fusion::kIv) = v;
    x(agv::fusion::kIomega) = om;
    x = agv::fusion::motion_predict(x, dt);
    acc_dist_m += v * dt;
    acc_turn_rad += om * dt;
    t += dt_ns;
    ++step;
    w.truth.t_ns.push_back(t);
    w.truth.pose.push_back({x(0), x(1), x(2)});
    gyro_turn_rad += om * dt;
    if (p.slip_varying) {
      if (t < slip_end_ns) {
        slip_frac = std::clamp(slip_frac + 0.3 * std::sqrt(dt) * n01(srng), 0.0, 0.6);
        slip_acc_m += slip_frac * std::abs(v) * dt;
      } else if (u01(srng) < p.slip_rate_hz * dt) {
        slip_end_ns = t + static_cast<std::int64_t>((0.15 + 0.35 * u01(srng)) * 1e9);
        slip_frac = 0.1 + 0.3 * u01(srng);
        slip_sign = (srng() % 2 == 0) ? 1.0 : -1.0;
      }
    }
    if (gyro_every > 0 && step % gyro_every == 0) {
      const double T = dt * gyro_every;
      const double ts = static_cast<double>(t) * 1e-9;
      gyro_walk_radps += agv::deg_to_rad(p.gyro_bias_walk_degps_rts) * std::sqrt(T) * n01(grng);
      double gbias = agv::deg_to_rad(p.gyro_bias_degps) + gyro_walk_radps;
      if (p.gyro_bias_step_degps != 0.0 && ts >= p.gyro_bias_step_s)
        gbias += agv::deg_to_rad(p.gyro_bias_step_degps);
      double g = (1.0 + p.gyro_scale_error) * gyro_turn_rad / T + gbias +
                 agv::deg_to_rad(p.gyro_noise_degps_rthz) / std::sqrt(T) * n01(grng);
      const double range = agv::deg_to_rad(p.gyro_range_degps);
      g = std::clamp(g, -range, range);
      w.gyro.push_back({t + static_cast<std::int64_t>(p.gyro_latency_ms * 1e6), g});
      gyro_turn_rad = 0.0;
    }
    if (step % odom_every == 0) {
      const double T = dt * odom_every;
      const double v_mean = acc_dist_m / T, om_mean = acc_turn_rad / T;
      const double ts = static_cast<double>(t) * 1e-9;
      const double b = bias * (1.0 + p.drift_variation * std::sin(2.0 * agv::kPi * ts / 120.0)) +
                       agv::deg_to_rad(p.drift_degpm) * v_mean;
      double v_meas = v_mean * (1.0 + p.scale_error) + p.v_noise_mps * n01(rng);
      double om_meas = om_mean * (1.0 + p.scale_error) + b + p.omega_noise_radps * n01(rng);
      if (p.slip_varying) {
        const double extra_mps = slip_acc_m / T;
        v_meas += 0.5 * extra_mps;
        om_meas += slip_sign * extra_mps / (p.wheelbase_mm / 1000.0);
        slip_acc_m = 0.0;
      } else if (t < slip_end_ns) {  // one wheel over-reports: half of it in v, all of it in omega
        const double extra_mps = 0.25 * std::abs(v_mean);
        v_meas += 0.5 * extra_mps;
        om_meas += slip_sign * extra_mps / (p.wheelbase_mm / 1000.0);
      } else if (u01(rng) < p.slip_rate_hz * T) {
        slip_end_ns = t + 300 * kMsNs;
        slip_sign = (rng() % 2 == 0) ? 1.0 : -1.0;
      }
      w.odom.push_back({t, v_meas, om_meas});
      acc_dist_m = acc_turn_rad = 0.0;
    }
  };
  w.truth.t_ns.push_back(0);
  w.truth.pose.push_back({0.0, 0.0, 0.0});
  auto dwell = [&](double s) {
    for (int i = 0; i < static_cast<int>(s / dt); ++i) advance(0.0, 0.0);
  };

  int cx = 0, cy = 0, dir = 0;  // grid cell and heading (0:+x 1:+y 2:-x 3:-y)
  const int dxs[4] = {1, 0, -1, 0}, dys[4] = {0, 1, 0, -1};
  const std::int64_t end_ns = static_cast<std::int64_t>(p.duration_s * 1e9);
  dwell(1.0);
  if (p.route == "lawnmower") {
    // Start 1 m before the first landmark of row 0, ramp up, then rows back and forth.
    const double v = p.v_max_mps;
    const Profile ramp(1.0, v, p.accel_mps2);
    for (int i = 0; i < static_cast<int>(std::ceil(ramp.t_acc / dt)); ++i)
      advance(p.accel_mps2 * (i + 0.5) * dt, 0.0);
    double sign = 1.0;  // left turns going +x, right turns going -x: rows stack up in +y
    while (t < end_ns) {
      const double straight_m = (p.grid_cells - 1) * grid_mm / 1000.0 + 2.0 * p.lawnmower_out_m;
      const double first_m = (t < 3'000'000'000LL) ? straight_m - 0.5 * ramp.t_acc * v : straight_m;
      for (int i = 0; i < static_cast<int>(first_m / v / dt); ++i) advance(v, 0.0);
      // Whole 1 ms steps turning exactly pi, so the rows stay on the landmark lines.
      const double radius_m = 0.5 * grid_mm / 1000.0;
      const int n = static_cast<int>(std::lround(agv::kPi * radius_m / v / dt));
      const double om = agv::kPi / (n * dt);
      for (int i = 0; i < n; ++i) advance(om * radius_m, sign * om);
      sign = -sign;
    }
    const std::int64_t frame_ns = 33'333'333;
    for (std::int64_t tf = frame_ns; tf < t; tf += frame_ns) w.frames_ns.push_back(tf);
    return w;
  }
  while (t < end_ns) {
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
      const int n = static_cast<int>(std::ceil(prof.total / dt));
      for (int i = 0; i < n; ++i) advance(prof.speed((i + 0.5) * dt), 0.0);
      cx += dxs[dir] * cells;
      cy += dys[dir] * cells;
      dwell(0.2);
    }
    // Turn in place on the landmark: +-90 deg, or 180 deg when boxed in.
    const int turn = (room == 0 && rng() % 2 == 0) ? 2 : (rng() % 2 == 0 ? 1 : 3);
    const double angle = (turn == 2 ? agv::kPi : agv::kPi / 2.0);
    const double sign = (turn == 3) ? -1.0 : 1.0;
    const Profile prof(angle, p.omega_max_radps, p.yaw_accel_radps2);
    const int n = static_cast<int>(std::ceil(prof.total / dt));
    for (int i = 0; i < n; ++i) advance(0.0, sign * prof.speed((i + 0.5) * dt));
    dir = (dir + turn) % 4;
    dwell(0.2);
  }
  const std::int64_t frame_ns = 33'333'333;  // 30 fps
  for (std::int64_t tf = frame_ns; tf < t; tf += frame_ns) w.frames_ns.push_back(tf);
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
