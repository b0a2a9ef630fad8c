// Simulated calibration drive for the vehicle-calibration tests (simulated observations, not
// rendered frames): the documented pattern over landmarks on a line 1 m apart — straight passes in
// both directions that stop over each landmark, and turns on the spot over them — with a true
// camera mounting and odometry errors (scales, yaw-rate bias, time offset, white noise), and the
// landmark corners as the vision stage's raw observation (undistorted normalised coordinates with
// pixel noise).
#pragma once

#include <array>
#include <cmath>
#include <cstdint>
#include <map>
#include <random>
#include <string>
#include <vector>

#include "calib_gyro.hpp"
#include "calib_vehicle.hpp"

namespace agv::calibtest {

struct DriveTruth {
  desk::vcal::VehicleParams p;  // true mounting, odometry errors, time offset
  double corner_noise_px = 0.05;
  double odom_v_noise_mps = 0.002, odom_w_noise_radps = 0.01;
  bool turns = true;       // false: straight passes in one direction only (degenerate)
  int landmarks = 3;       // on a line 1 m apart along x
  double duration_s = 60;  // the pattern repeats until this time
  unsigned seed = 1;
  // Worn landmarks: every corner of these carries its own fixed offset in the landmark
  // frame (a scuffed edge, faded ink, dirt that the robust edge fit leaves: the same in every
  // frame, so it does not average out), N(0, wear_mm) per axis, and wear_noise_px more white
  // noise. Their own random streams, so the other landmarks see what they saw before.
  std::vector<std::uint32_t> worn;
  double wear_mm = 0.1;
  double wear_noise_px = 0.2;
  // Gyro (Drive::gyro): reported = (1 + gyro_scale_error) * true mean rate over the
  // sample period + gyro_bias_radps + white noise, stamped late by gyro_latency_s. Its own random
  // stream, so the odometry and the corners are what they were without it.
  double gyro_scale_error = 0.0, gyro_bias_radps = 0.0;
  double gyro_noise_radps_rthz = 0.01 * kPi / 180.0;
  double gyro_latency_s = 0.0;
  int gyro_period_ms = 5;
};

// The perturbed vehicle the calibration tests start from (mount, odometry and clock all off).
inline DriveTruth perturbed_drive(unsigned seed = 1) {
  DriveTruth t;
  t.seed = seed;
  t.p.mount = CameraModel::default_640x480().mount;
  t.p.mount.offset_x_mm = 8.0;
  t.p.mount.offset_y_mm = -6.0;
  t.p.mount.yaw_rad = deg_to_rad(1.8);
  t.p.mount.height_mm = 204.5;
  t.p.mount.roll_rad = deg_to_rad(1.2);
  t.p.mount.pitch_rad = deg_to_rad(-1.4);
  t.p.speed_scale = 1.028;
  t.p.yaw_rate_scale = 0.972;
  t.p.yaw_rate_bias_radps = deg_to_rad(0.45);
  // Unequal wheels: the right one reads 0.4 % more on a 0.5 m track (the simulator's default
  // --odom-asymmetry), so a straight run curves 0.46 deg/m.
  t.p.yaw_per_metre_rad = -0.004 / 0.5;
  t.p.time_offset_s = 0.027;
  return t;
}

struct Drive {
  LandmarkMap map;
  std::vector<desk::vcal::OdomSample> odom;
  std::vector<desk::vcal::CornerObservation> obs;
  std::vector<desk::vcal::GyroSample> gyro;
};

namespace detail {
struct Move {
  bool rotate;
  double amount;  // mm or rad (signed)
};
// Trapezoid profile: peak rate, acceleration; returns rate at time t of a move of `amount`.
inline double trapezoid(double amount, double peak, double acc, double t, double* duration) {
  const double a = std::abs(amount), sgn = amount < 0 ? -1.0 : 1.0;
  double tr = peak / acc, cruise;
  if (acc * tr * tr > a) {
    tr = std::sqrt(a / acc);
    peak = acc * tr;
    cruise = 0.0;
  } else {
    cruise = (a - acc * tr * tr) / peak;
  }
  *duration = 2 * tr + cruise;
  if (t < 0 || t > *duration) return 0.0;
  if (t < tr) return sgn * acc * t;
  if (t < tr + cruise) return sgn * peak;
  return sgn * acc * (*duration - t);
}
}  // namespace detail

inline Drive make_calibration_drive(const DriveTruth& tr) {
  using detail::Move;
  Drive d;
  for (int i = 0; i < tr.landmarks; ++i) {
    d.map.entries[static_cast<std::uint32_t>(i + 1)] = {static_cast<std::uint32_t>(i + 1),
                                                        {1000.0 * i, 0.0, 0.0}};
  }
  // Pattern: start 400 mm before landmark 1; drive to each landmark, stop, turn on the spot
  // (+360, then -180 at the last one), come back the other way, turn, and repeat.
  std::vector<Move> pattern;
  pattern.push_back({false, 400.0});
  const double span = 1000.0 * (tr.landmarks - 1);
  for (int rep = 0; rep < 20; ++rep) {
    if (tr.turns) {
      pattern.push_back({true, 2 * kPi});
      for (int i = 1; i < tr.landmarks; ++i) {
        pattern.push_back({false, 1000.0});
        pattern.push_back({true, i % 2 ? -kPi / 2 : kPi / 2});
        pattern.push_back({true, i % 2 ? kPi / 2 : -kPi / 2});
      }
      pattern.push_back({true, kPi});
      for (int i = 1; i < tr.landmarks; ++i) pattern.push_back({false, 1000.0});
      pattern.push_back({true, -kPi});
    } else {
      for (int i = 1; i < tr.landmarks; ++i) pattern.push_back({false, 1000.0});
      pattern.push_back({false, -span});  // reverse back (no turn)
    }
  }
  // True motion at 1 kHz.
  const double dt_fine = 1e-3, peak_v = 500.0, acc_v = 1500.0, peak_w = 0.8, acc_w = 3.0;
  std::vector<double> t_f, v_f, w_f;
  std::vector<Pose2> pose_f;
  Pose2 pose{-400.0, 0.0, 0.0};
  double t = 0.0;
  // Stand still for 0.5 s at the start.
  for (size_t mi = 0; mi < pattern.size() && t < tr.duration_s + 1.0; ++mi) {
    const Move& m = pattern[mi];
    double dur = 0;
    detail::trapezoid(m.amount, m.rotate ? peak_w : peak_v, m.rotate ? acc_w : acc_v, 0, &dur);
    const double pause = 0.3;
    for (double u = 0; u < dur + pause; u += dt_fine) {
      double dd = 0;
      const double r = detail::trapezoid(m.amount, m.rotate ? peak_w : peak_v,
                                         m.rotate ? acc_w : acc_v, u + 0.5 * dt_fine, &dd);
      const double v = m.rotate ? 0.0 : r, w = m.rotate ? r : 0.0;
      t_f.push_back(t);
      pose_f.push_back(pose);
      v_f.push_back(v);
      w_f.push_back(w);
      const double mid = pose.theta_rad + 0.5 * w * dt_fine;
      pose.x_mm += v * dt_fine * std::cos(mid);
      pose.y_mm += v * dt_fine * std::sin(mid);
      pose.theta_rad += w * dt_fine;
      t += dt_fine;
    }
  }
  std::mt19937 rng(tr.seed);
  std::normal_distribution<double> n01(0.0, 1.0);
  // Odometry every 10 ms: mean over the period, as reported with the errors, stamped late by
  // the time offset (odometry clock = camera clock + time offset).
  const std::int64_t t0_ns = 10'000'000'000LL;
  for (size_t k = 10; k < t_f.size(); k += 10) {
    double sv = 0, sw = 0;
    for (size_t j = k - 10; j < k; ++j) {
      sv += v_f[j];
      sw += w_f[j];
    }
    const double v = sv / 10.0 / 1000.0, w = sw / 10.0;  // m/s, rad/s
    desk::vcal::OdomSample o;
    o.t_ns = t0_ns + static_cast<std::int64_t>(std::llround((t_f[k] + tr.p.time_offset_s) * 1e9));
    // The inverse of the model (calib_vehicle.hpp, track 500 mm: Options' default):
    //   v = s_v v_k + c q omega_k,  omega = s_w omega_k + b + c v_k,  q = track^2 / 4.
    const double c = tr.p.yaw_per_metre_rad, q = 0.25 * 0.5 * 0.5;
    const double s_v = tr.p.speed_scale, s_w = tr.p.yaw_rate_scale, b = tr.p.yaw_rate_bias_radps;
    const double v_k = (v - c * q * (w - b) / s_w) / (s_v - c * c * q / s_w);
    const double w_k = (w - b - c * v_k) / s_w;
    o.v_mps = v_k + tr.odom_v_noise_mps * n01(rng);
    o.omega_radps = w_k + tr.odom_w_noise_radps * n01(rng);
    d.odom.push_back(o);
  }
  // Gyro samples: the mean true rate over the period, with the errors.
  {
    std::mt19937 grng(tr.seed * 15485863u + 3u);
    const size_t per = static_cast<size_t>(tr.gyro_period_ms);
    const double white = tr.gyro_noise_radps_rthz / std::sqrt(1e-3 * tr.gyro_period_ms);
    for (size_t k = per; k < t_f.size(); k += per) {
      double sw = 0;
      for (size_t j = k - per; j < k; ++j) sw += w_f[j];
      const double w = sw / static_cast<double>(per);
      desk::vcal::GyroSample g;
      g.t_ns = t0_ns + static_cast<std::int64_t>(std::llround((t_f[k] + tr.gyro_latency_s) * 1e9));
      g.rate_radps = (1.0 + tr.gyro_scale_error) * w + tr.gyro_bias_radps + white * n01(grng);
      d.gyro.push_back(g);
    }
  }
  // Frames at 30 Hz.
  CameraModel cam = CameraModel::default_640x480();
  cam.mount = tr.p.mount;
  const auto corners = desk::vcal::landmark_corners(30.0, 24.0);
  std::map<std::uint32_t, std::array<Vec2, 8>> wear;
  for (std::uint32_t id : tr.worn) {
    std::mt19937 wr(tr.seed * 7919u + id);
    for (Vec2& b : wear[id]) b = {tr.wear_mm * n01(wr), tr.wear_mm * n01(wr)};
  }
  std::mt19937 wear_rng(tr.seed * 104729u + 17u);
  for (double tc = 0.0; tc < std::min(t, tr.duration_s); tc += 1.0 / 30.0) {
    const size_t k = std::min(t_f.size() - 1, static_cast<size_t>(tc / dt_fine));
    const double f = (tc - t_f[k]) / dt_fine;
    Pose2 p = pose_f[k];
    p.x_mm += f * v_f[k] * dt_fine * std::cos(p.theta_rad);
    p.y_mm += f * v_f[k] * dt_fine * std::sin(p.theta_rad);
    p.theta_rad += f * w_f[k] * dt_fine;
    const Pose2 v_from_w = inverse(p);
    for (const auto& [id, e] : d.map.entries) {
      desk::vcal::CornerObservation o;
      o.t_ns = t0_ns + static_cast<std::int64_t>(std::llround(tc * 1e9));
      o.landmark_id = id;
      bool all = true;
      const auto worn = wear.find(id);
      for (size_t c = 0; c < 8; ++c) {
        Vec2 q = corners[c];
        if (worn != wear.end()) q = {q.x + worn->second[c].x, q.y + worn->second[c].y};
        Vec2 px;
        if (!cam.vehicle_to_pixel(transform(v_from_w, transform(e.pose, q)), &px) || px.x < 2 ||
            px.y < 2 || px.x > 637 || px.y > 477) {
          all = false;
          break;
        }
        px.x += tr.corner_noise_px * n01(rng);
        px.y += tr.corner_noise_px * n01(rng);
        if (worn != wear.end()) {
          px.x += tr.wear_noise_px * n01(wear_rng);
          px.y += tr.wear_noise_px * n01(wear_rng);
        }
        o.xn[c] = {(px.x - cam.intrinsics.cx) / cam.intrinsics.fx,
                   (px.y - cam.intrinsics.cy) / cam.intrinsics.fy};
        o.valid[c] = true;
      }
      if (all) d.obs.push_back(o);
    }
  }
  return d;
}

// The landmarks' half-sizes the drives' observations are of (outer square, inner square, mm).
inline constexpr double kOuterHalfMm = 30.0;
inline constexpr double kInnerHalfMm = 24.0;

// The vehicle calibration of a drive from the nominal configuration the tests start from (the
// default camera's mounting); false with *error as calibrate_vehicle.
inline bool calibrate_from_nominal(const Drive& d, const desk::vcal::Options& opt,
                                   desk::vcal::Result* r, std::string* error) {
  desk::vcal::VehicleParams nominal;
  nominal.mount = CameraModel::default_640x480().mount;
  return desk::vcal::calibrate_vehicle(d.odom, d.obs, d.map, kOuterHalfMm, kInnerHalfMm, nominal,
                                       opt, r, error);
}

// The true parameters in the order and units of the calibration's report (Result::params): mm and
// degrees for the mounting, the scales, deg/s and deg/m, and the time offset in ms.
inline std::array<double, 11> reported_truth(const desk::vcal::VehicleParams& p) {
  return {p.mount.offset_x_mm,
          p.mount.offset_y_mm,
          rad_to_deg(p.mount.yaw_rad),
          p.mount.height_mm,
          rad_to_deg(p.mount.roll_rad),
          rad_to_deg(p.mount.pitch_rad),
          p.speed_scale,
          p.yaw_rate_scale,
          rad_to_deg(p.yaw_rate_bias_radps),
          rad_to_deg(p.yaw_per_metre_rad),
          p.time_offset_s * 1e3};
}

}  // namespace agv::calibtest
