// eval_fusion: accuracy of agv::fusion::Ekf on a simulated drive over a landmark grid.
//
// Two sources of odometry and ground truth:
//   * synthetic (default): a vehicle drives a random route along the lines of a 1 m landmark
//     grid at up to 1 m/s (trapezoidal speed, turns in place on landmarks); odometry at 100 Hz
//     is the mean speed per period with a scale error, a yaw-rate bias ("heading drift") and
//     noise.
//   * --recording DIR: odom.csv, truth.csv and frames.csv of a simulated recording (the real
//     formats, read with agv::recording::read_recording).
// Landmark fixes are simulated from the truth at the frame times whenever the camera footprint
// contains a grid landmark: the pose of the landmark in the vehicle frame gets noise of
// 0.05-0.3 mm and 0.01-0.05 deg, and the vehicle's world pose is composed from it as the vision
// stage does. Optionally a fraction of fixes is corrupted (wrong coordinates, offsets, heading
// misreads) and fixes are delivered late.
//
// Usage and measured numbers: docs/fusion.md.
#include <Eigen/Core>
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <random>
#include <string>
#include <vector>

#include "agv/common/geometry.hpp"
#include "agv/fusion/ekf.hpp"
#include "agv/fusion/motion_model.hpp"
#include "agv/vision/pose_covariance.hpp"

#ifdef AGV_EVAL_HAVE_RECORDING
#include "agv/recording/recording.hpp"
#endif

namespace {

using agv::Pose2;
using agv::fusion::Ekf;
using agv::fusion::EkfConfig;
using agv::fusion::FixOutcome;
using agv::fusion::PoseEstimate;
using agv::fusion::validate;

constexpr std::int64_t kMsNs = 1'000'000;

// ------------------------------------------------------------------------------------------
// Ground truth and odometry

struct TruthTrack {
  std::vector<std::int64_t> t_ns;
  std::vector<Pose2> pose;

  Pose2 at(std::int64_t t) const {
    if (t <= t_ns.front()) return pose.front();
    if (t >= t_ns.back()) return pose.back();
    const auto it = std::upper_bound(t_ns.begin(), t_ns.end(), t);
    const std::size_t i = static_cast<std::size_t>(it - t_ns.begin());
    const double f =
        static_cast<double>(t - t_ns[i - 1]) / static_cast<double>(t_ns[i] - t_ns[i - 1]);
    const Pose2& a = pose[i - 1];
    const Pose2& b = pose[i];
    return {a.x_mm + f * (b.x_mm - a.x_mm), a.y_mm + f * (b.y_mm - a.y_mm),
            agv::wrap_angle_rad(a.theta_rad + f * agv::wrap_angle_rad(b.theta_rad - a.theta_rad))};
  }
};

struct OdomSample {
  std::int64_t t_ns;
  double v_mps;
  double omega_radps;
};

struct World {
  TruthTrack truth;
  std::vector<OdomSample> odom;
  std::vector<std::int64_t> frames_ns;
  double camera_offset_x_mm = 0.0;
  double camera_offset_y_mm = 0.0;
  std::string source;
};

struct SynthParams {
  double duration_s = 600.0;
  int grid_cells = 12;  // route stays on a 12 x 12 grid of landmarks
  double v_max_mps = 1.0;
  double accel_mps2 = 1.0;
  double omega_max_radps = 1.0;
  double yaw_accel_radps2 = 2.0;
  double scale_error = 0.01;     // odometry reads 1 % high (v and omega)
  double drift_degps = 0.5;      // yaw-rate bias
  double drift_degpm = 0.0;      // yaw-rate error per speed (left/right wheel mismatch), deg/m
  double drift_variation = 0.0;  // bias varies by this fraction, sinusoid with a 120 s period
  double slip_rate_hz = 0.0;     // slip events: one wheel reports 25 % more for 0.3 s
  double wheelbase_mm = 500.0;
  double v_noise_mps = 0.003;  // per 10 ms sample
  double omega_noise_radps = 0.002;
  double camera_offset_x_mm = 0.0;
  // "grid": random runs along the grid lines with turns in place on landmarks. "lawnmower": rows
  // 1 m apart across grid_cells landmarks at v_max, leaving the grid at each end for a leg of
  // lawnmower_out_m straight, a half circle of radius 0.5 grid and the same straight back
  // (5.6 s at 1 m/s with 2 m: the long legs without a landmark), yaw rate stepping at each arc.
  std::string route = "grid";
  double lawnmower_out_m = 2.0;
  std::uint64_t seed = 1;
};

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

World make_synthetic_world(const SynthParams& p, double grid_mm) {
  World w;
  w.source = "synthetic";
  w.camera_offset_x_mm = p.camera_offset_x_mm;
  std::mt19937_64 rng(p.seed);
  std::normal_distribution<double> n01(0.0, 1.0);
  std::uniform_real_distribution<double> u01(0.0, 1.0);
  std::int64_t slip_end_ns = -1;
  double slip_sign = 1.0;
  const double dt = 1e-3;  // truth integration step
  const std::int64_t dt_ns = 1'000'000;
  const int odom_every = 10;  // 100 Hz
  const double bias = agv::deg_to_rad(p.drift_degps);

  agv::fusion::StateVec x = agv::fusion::StateVec::Zero();
  std::int64_t t = 0;
  long step = 0;
  double acc_dist_m = 0.0, acc_turn_rad = 0.0;
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
    if (step % odom_every == 0) {
      const double T = dt * odom_every;
      const double v_mean = acc_dist_m / T, om_mean = acc_turn_rad / T;
      const double ts = static_cast<double>(t) * 1e-9;
      const double b = bias * (1.0 + p.drift_variation * std::sin(2.0 * agv::kPi * ts / 120.0)) +
                       agv::deg_to_rad(p.drift_degpm) * v_mean;
      double v_meas = v_mean * (1.0 + p.scale_error) + p.v_noise_mps * n01(rng);
      double om_meas = om_mean * (1.0 + p.scale_error) + b + p.omega_noise_radps * n01(rng);
      if (t < slip_end_ns) {  // one wheel over-reports: half of it in v, all of it in omega
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

// ------------------------------------------------------------------------------------------
// Fix simulation

struct FixParams {
  double grid_mm = 1000.0;
  // Camera footprint 166 x 125 mm (640x480 at 0.26 mm/px); the whole 60 mm landmark (half
  // diagonal 42 mm) must be inside: centre within +-20 mm along the vehicle x axis (image
  // rows) and +-41 mm across.
  double visible_half_x_mm = 20.5;
  double visible_half_y_mm = 41.0;
  double detect_probability = 0.9;
  double sigma_xy_min_mm = 0.05, sigma_xy_max_mm = 0.3;
  double sigma_th_min_deg = 0.01, sigma_th_max_deg = 0.05;
  // "diag": R = diag(sigma^2) as the simple model; "vision": the full covariance propagated from
  // the landmark-in-vehicle measurement (lever arm correlations), with the sigma the vision
  // stage estimates off by a random factor 0.5..2 per fix.
  bool vision_covariance = false;
  double outlier_fraction = 0.0;
  // Restrict outliers to vision offsets of this magnitude range (mm) when > 0 (detection limit
  // sweep); otherwise all kinds.
  double offset_only_min_mm = 0.0, offset_only_max_mm = 0.0;
  std::int64_t delay_ns = 0;
  // Landmarks exist only for x in [0, grid_max_x_mm] when > 0 (the lawnmower route's grid).
  double grid_max_x_mm = 0.0;
  std::uint64_t seed = 7;
};

enum OutlierKind { kNone = 0, kWrongLandmark, kDigitError, kVisionOffset, kFlip, kSmallHeading };
const char* kOutlierNames[] = {
    "none",           "wrong_landmark", "digit_100mm", "offset_20_100mm", "heading_90_180deg",
    "heading_3_20deg"};

struct SimFix {
  std::int64_t t_exposure_ns;
  std::int64_t t_delivery_ns;
  Pose2 z;
  Eigen::Matrix3d R;
  OutlierKind outlier;
};

std::vector<SimFix> simulate_fixes(const World& w, const FixParams& p) {
  std::vector<SimFix> out;
  std::mt19937_64 rng(p.seed);
  std::uniform_real_distribution<double> u01(0.0, 1.0);
  std::normal_distribution<double> n01(0.0, 1.0);
  const Pose2 mount{w.camera_offset_x_mm, w.camera_offset_y_mm, 0.0};
  for (std::int64_t tf : w.frames_ns) {
    if (tf < w.truth.t_ns.front() || tf > w.truth.t_ns.back()) continue;
    const Pose2 truth = w.truth.at(tf);
    const Pose2 cam = agv::compose(truth, mount);
    const Pose2 lm{std::round(cam.x_mm / p.grid_mm) * p.grid_mm,
                   std::round(cam.y_mm / p.grid_mm) * p.grid_mm, 0.0};
    if (p.grid_max_x_mm > 0.0 && (lm.x_mm < 0.0 || lm.x_mm > p.grid_max_x_mm)) continue;
    const Pose2 in_cam = agv::compose(agv::inverse(cam), lm);
    if (std::abs(in_cam.x_mm) > p.visible_half_x_mm || std::abs(in_cam.y_mm) > p.visible_half_y_mm)
      continue;
    if (u01(rng) > p.detect_probability) continue;
    // Measurement of V<-L with noise in the vehicle frame.
    const double sxy = p.sigma_xy_min_mm + (p.sigma_xy_max_mm - p.sigma_xy_min_mm) * u01(rng);
    const double sth =
        agv::deg_to_rad(p.sigma_th_min_deg + (p.sigma_th_max_deg - p.sigma_th_min_deg) * u01(rng));
    Pose2 vl = agv::compose(agv::inverse(truth), lm);
    vl.x_mm += sxy * n01(rng);
    vl.y_mm += sxy * n01(rng);
    vl.theta_rad = agv::wrap_angle_rad(vl.theta_rad + sth * n01(rng));
    Pose2 world_lm = lm;  // what the payload/map says

    OutlierKind kind = kNone;
    if (u01(rng) < p.outlier_fraction) {
      if (p.offset_only_max_mm > 0.0) {
        kind = kVisionOffset;
      } else {
        kind = static_cast<OutlierKind>(1 + rng() % 5);
      }
      const double sgn = (rng() % 2 == 0) ? 1.0 : -1.0;
      switch (kind) {
        case kWrongLandmark: {
          int dx = 0, dy = 0;
          while (dx == 0 && dy == 0) {
            dx = static_cast<int>(rng() % 7) - 3;
            dy = static_cast<int>(rng() % 7) - 3;
          }
          world_lm.x_mm += dx * p.grid_mm;
          world_lm.y_mm += dy * p.grid_mm;
          break;
        }
        case kDigitError:
          (rng() % 2 == 0 ? world_lm.x_mm : world_lm.y_mm) += sgn * 100.0;
          break;
        case kVisionOffset: {
          const double lo = p.offset_only_max_mm > 0.0 ? p.offset_only_min_mm : 20.0;
          const double hi = p.offset_only_max_mm > 0.0 ? p.offset_only_max_mm : 100.0;
          const double m = lo + (hi - lo) * u01(rng);
          const double a = 2.0 * agv::kPi * u01(rng);
          vl.x_mm += m * std::cos(a);
          vl.y_mm += m * std::sin(a);
          break;
        }
        case kFlip:
          vl.theta_rad = agv::wrap_angle_rad(vl.theta_rad + (rng() % 3 + 1) * agv::kPi / 2.0);
          break;
        case kSmallHeading:
          vl.theta_rad =
              agv::wrap_angle_rad(vl.theta_rad + sgn * agv::deg_to_rad(3.0 + 17.0 * u01(rng)));
          break;
        case kNone:
          break;
      }
    }
    SimFix f;
    f.t_exposure_ns = tf;
    f.t_delivery_ns = tf + p.delay_ns;
    f.z = agv::compose(world_lm, agv::inverse(vl));
    f.outlier = kind;
    if (p.vision_covariance) {
      const double k = 0.5 + 1.5 * u01(rng);  // the vision estimate of its own sigma is off
      Eigen::Matrix3d cov_vl = Eigen::Matrix3d::Zero();
      cov_vl(0, 0) = cov_vl(1, 1) = k * k * sxy * sxy;
      cov_vl(2, 2) = k * k * sth * sth;
      f.R = agv::vision::vehicle_in_world_covariance(world_lm, vl, cov_vl);
    } else {
      f.R = Eigen::Matrix3d::Zero();
      f.R(0, 0) = f.R(1, 1) = sxy * sxy;
      f.R(2, 2) = sth * sth;
    }
    out.push_back(f);
  }
  std::stable_sort(out.begin(), out.end(), [](const SimFix& a, const SimFix& b) {
    return a.t_delivery_ns < b.t_delivery_ns;
  });
  return out;
}

// ------------------------------------------------------------------------------------------
// Run and metrics

double percentile(std::vector<double> v, double q) {
  if (v.empty()) return std::nan("");
  std::sort(v.begin(), v.end());
  const std::size_t idx =
      static_cast<std::size_t>(std::max(0.0, std::ceil(q * static_cast<double>(v.size())) - 1.0));
  return v[std::min(idx, v.size() - 1)];
}

struct RunResult {
  std::vector<double> at_landmark_mm, at_landmark_deg;
  std::vector<double> midway_mm, all_mm, all_deg;
  std::vector<double> between_mm;  // ticks >= 200 ms after the last fused fix (as replay's)
  long good_fixes = 0, good_fused = 0, good_rejected = 0;
  long outliers = 0, outliers_accepted = 0;
  long outliers_by_kind[6] = {}, accepted_by_kind[6] = {};
  double max_err_after_outlier_mm = 0.0;
  long health_counts[4] = {};
  Ekf::Counters counters;
};

RunResult run(const World& w, const std::vector<SimFix>& fixes, const EkfConfig& cfg,
              double grid_mm, bool use_fixes = true) {
  RunResult r;
  Ekf ekf(cfg);
  std::size_t next_fix = 0;
  const Pose2 mount{w.camera_offset_x_mm, w.camera_offset_y_mm, 0.0};
  const std::int64_t warmup_ns = 2'000'000'000;  // metrics after the first fixes
  for (const OdomSample& o : w.odom) {
    ekf.add_odometry(o.t_ns, o.v_mps, o.omega_radps);
    while (next_fix < fixes.size() && fixes[next_fix].t_delivery_ns <= o.t_ns) {
      const SimFix& f = fixes[next_fix++];
      if (!use_fixes && ekf.initialised()) continue;
      const FixOutcome out = ekf.add_fix(f.t_exposure_ns, f.z, f.R);
      const bool accepted = out == FixOutcome::kFused || out == FixOutcome::kInitialised ||
                            out == FixOutcome::kReinitialised;
      if (f.outlier != kNone) {
        ++r.outliers;
        ++r.outliers_by_kind[f.outlier];
        if (accepted) {
          ++r.outliers_accepted;
          ++r.accepted_by_kind[f.outlier];
          const PoseEstimate e = ekf.estimate_at(f.t_exposure_ns);
          const Pose2 tr = w.truth.at(f.t_exposure_ns);
          r.max_err_after_outlier_mm = std::max(
              r.max_err_after_outlier_mm, std::hypot(e.pose.x_mm - tr.x_mm, e.pose.y_mm - tr.y_mm));
        }
        continue;
      }
      ++r.good_fixes;
      if (out == FixOutcome::kFused) {
        ++r.good_fused;
        const PoseEstimate e = ekf.estimate_at(f.t_exposure_ns);
        const Pose2 tr = w.truth.at(f.t_exposure_ns);
        // "At a landmark" means passing it at speed; most fixes come from standing or turning
        // on a landmark, where the error is smaller, and would flatter the statistics.
        const Pose2 tr_b = w.truth.at(f.t_exposure_ns - 5 * kMsNs);
        if (std::hypot(tr.x_mm - tr_b.x_mm, tr.y_mm - tr_b.y_mm) < 2.5) continue;  // < 0.5 m/s
        r.at_landmark_mm.push_back(std::hypot(e.pose.x_mm - tr.x_mm, e.pose.y_mm - tr.y_mm));
        r.at_landmark_deg.push_back(
            std::abs(agv::rad_to_deg(agv::wrap_angle_rad(e.pose.theta_rad - tr.theta_rad))));
      } else if (out == FixOutcome::kRejectedGate) {
        ++r.good_rejected;
      }
    }
    // Output tick at the odometry rate with what is known now.
    const PoseEstimate e = ekf.estimate_at(o.t_ns);
    r.health_counts[static_cast<int>(e.health)]++;
    if (!e.valid || o.t_ns < warmup_ns) continue;
    const Pose2 tr = w.truth.at(o.t_ns);
    const double err = std::hypot(e.pose.x_mm - tr.x_mm, e.pose.y_mm - tr.y_mm);
    r.all_mm.push_back(err);
    r.all_deg.push_back(
        std::abs(agv::rad_to_deg(agv::wrap_angle_rad(e.pose.theta_rad - tr.theta_rad))));
    const Pose2 cam = agv::compose(tr, mount);
    const double lx = std::round(cam.x_mm / grid_mm) * grid_mm;
    const double ly = std::round(cam.y_mm / grid_mm) * grid_mm;
    if (std::hypot(cam.x_mm - lx, cam.y_mm - ly) >= 0.45 * grid_mm) r.midway_mm.push_back(err);
    if (e.time_since_fix_ns >= 200 * kMsNs) r.between_mm.push_back(err);
  }
  r.counters = ekf.counters();
  return r;
}

void print_header() {
  std::printf("%-34s %5s %7s %7s %7s %8s | %7s %7s %7s | %7s %7s %7s | %6s %6s %5s %7s | %5s\n",
              "scenario", "lm_n", "lm_p50", "lm_p95", "lm_max", "lm_p95d", "mid_p50", "mid_p95",
              "btw_p95", "all_p95", "all_max", "all95d", "fixes", "rejG", "outl", "outlAcc",
              "reini");
}

void print_row(const char* name, const RunResult& r) {
  std::printf(
      "%-34s %5zu %7.3f %7.3f %7.3f %8.4f | %7.2f %7.2f %7.2f | %7.2f %7.2f %7.3f | %6ld %6ld "
      "%5ld %7ld | %5llu\n",
      name, r.at_landmark_mm.size(), percentile(r.at_landmark_mm, 0.5),
      percentile(r.at_landmark_mm, 0.95), percentile(r.at_landmark_mm, 1.0),
      percentile(r.at_landmark_deg, 0.95), percentile(r.midway_mm, 0.5),
      percentile(r.midway_mm, 0.95), percentile(r.between_mm, 0.95), percentile(r.all_mm, 0.95),
      percentile(r.all_mm, 1.0), percentile(r.all_deg, 0.95), r.good_fixes, r.good_rejected,
      r.outliers, r.outliers_accepted,
      static_cast<unsigned long long>(r.counters.reinitialisations));
}

void usage() {
  std::fprintf(stderr,
               "usage: eval_fusion [--recording DIR] [--duration S] [--seed N] [--drift DEGPS]\n"
               "                   [--scale-error F] [--grid MM] [--window full|partial]\n"
               "                   [--kidnap-fixes N] [--route grid|lawnmower]\n"
               "                   [--lawnmower-out M] [--quick]\n");
}

}  // namespace

int main(int argc, char** argv) {
  std::string recording;
  SynthParams sp;
  double grid_mm = 1000.0;
  bool partial_window = false;
  int kidnap_fixes = EkfConfig{}.kidnap_fixes;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    auto next = [&]() -> const char* {
      if (i + 1 >= argc) {
        usage();
        std::exit(2);
      }
      return argv[++i];
    };
    if (a == "--recording") {
      recording = next();
    } else if (a == "--duration") {
      sp.duration_s = std::atof(next());
    } else if (a == "--seed") {
      sp.seed = std::strtoull(next(), nullptr, 10);
    } else if (a == "--drift") {
      sp.drift_degps = std::atof(next());
    } else if (a == "--scale-error") {
      sp.scale_error = std::atof(next());
    } else if (a == "--grid") {
      grid_mm = std::atof(next());
    } else if (a == "--kidnap-fixes") {
      kidnap_fixes = std::atoi(next());
    } else if (a == "--window") {
      const std::string v = next();
      if (v == "partial") {
        partial_window = true;
      } else if (v != "full") {
        usage();
        return 2;
      }
    } else if (a == "--route") {
      sp.route = next();
      if (sp.route != "grid" && sp.route != "lawnmower") {
        usage();
        return 2;
      }
    } else if (a == "--lawnmower-out") {
      sp.lawnmower_out_m = std::atof(next());
    } else if (a == "--quick") {
      sp.duration_s = 60.0;
    } else {
      usage();
      return 2;
    }
  }
  if (!(sp.duration_s > 5.0) || !(grid_mm > 100.0)) {
    usage();
    return 2;
  }

  EkfConfig cfg;  // documented defaults
  cfg.kidnap_fixes = kidnap_fixes;
  if (!validate(cfg).empty()) {
    std::fprintf(stderr, "eval_fusion: %s\n", validate(cfg).c_str());
    return 2;
  }
  auto synth = [&](double drift, double offset_x, double drift_degpm = 0.0, double variation = 0.0,
                   double slip_hz = 0.0) {
    SynthParams p = sp;
    p.drift_degps = drift;
    p.camera_offset_x_mm = offset_x;
    p.drift_degpm = drift_degpm;
    p.drift_variation = variation;
    p.slip_rate_hz = slip_hz;
    return make_synthetic_world(p, grid_mm);
  };
  World base;
  if (!recording.empty()) {
#ifdef AGV_EVAL_HAVE_RECORDING
    if (!load_recording_world(recording, &base)) return 1;
#else
    std::fprintf(stderr, "eval_fusion: built without the recording reader\n");
    return 1;
#endif
  } else {
    base = synth(sp.drift_degps, 0.0);
  }
  std::printf("eval_fusion: source %s, %.1f s, %zu odometry samples, %zu frames, grid %.0f mm\n",
              base.source.c_str(),
              static_cast<double>(base.truth.t_ns.back() - base.truth.t_ns.front()) * 1e-9,
              base.odom.size(), base.frames_ns.size(), grid_mm);
  if (recording.empty())
    std::printf("odometry: scale error %+.1f %%, heading drift %.2f deg/s, seed %llu\n",
                100.0 * sp.scale_error, sp.drift_degps, static_cast<unsigned long long>(sp.seed));
  std::printf("gate chi2(3) at %.4f: %.3f\n", cfg.gate_probability, Ekf(cfg).gate_threshold());
  std::printf(
      "columns: lm_* = position error (mm) at the fix exposure after fusing it, for fixes "
      "taken\n  at >= 0.5 m/s (lm_n of them), lm_p95d heading (deg);\n  mid_* = real-time error "
      "(mm) with the camera >= 0.45 grid from any landmark; "
      "btw_p95 at ticks >= 200 ms after the last fused fix;\n  all_* over all"
      "\n  output ticks after 2 s; fixes = good fixes, rejG = good fixes rejected "
      "by the gate,\n  outl/outlAcc = corrupted fixes / accepted; reini = re-initialisations\n");

  FixParams fp;
  fp.grid_mm = grid_mm;
  if (sp.route == "lawnmower") fp.grid_max_x_mm = (sp.grid_cells - 1) * grid_mm;
  if (partial_window) {
    // The vision stage also measures a landmark cut by the image border as long as the QR code
    // and one complete side per axis are inside: centre within about +-40 / +-60 mm.
    fp.visible_half_x_mm = 40.0;
    fp.visible_half_y_mm = 60.0;
  }
  std::printf(
      "fix window: landmark centre within +-%.1f mm along, +-%.1f mm across the vehicle\n\n",
      fp.visible_half_x_mm, fp.visible_half_y_mm);
  print_header();
  auto with = [&](FixParams p, auto&& mod) {
    mod(p);
    return p;
  };

  const RunResult r0 = run(base, simulate_fixes(base, fp), cfg, grid_mm);
  print_row("baseline (delay 0, diag R)", r0);
  const RunResult r50 =
      run(base, simulate_fixes(base, with(fp, [](FixParams& p) { p.delay_ns = 50 * kMsNs; })), cfg,
          grid_mm);
  print_row("delay 50 ms", r50);
  const RunResult rv =
      run(base, simulate_fixes(base, with(fp, [](FixParams& p) { p.vision_covariance = true; })),
          cfg, grid_mm);
  print_row("vision R (full, sigma x0.5..2)", rv);
  const RunResult rv50 = run(base,
                             simulate_fixes(base, with(fp,
                                                       [](FixParams& p) {
                                                         p.vision_covariance = true;
                                                         p.delay_ns = 50 * kMsNs;
                                                       })),
                             cfg, grid_mm);
  print_row("vision R, delay 50 ms", rv50);
  const RunResult ro = run(base,
                           simulate_fixes(base, with(fp,
                                                     [](FixParams& p) {
                                                       p.outlier_fraction = 0.05;
                                                       p.delay_ns = 50 * kMsNs;
                                                       p.vision_covariance = true;
                                                     })),
                           cfg, grid_mm);
  print_row("5 % outliers, vision R, delay 50", ro);
  const RunResult ro20 = run(base,
                             simulate_fixes(base, with(fp,
                                                       [](FixParams& p) {
                                                         p.outlier_fraction = 0.2;
                                                         p.seed = 11;
                                                       })),
                             cfg, grid_mm);
  print_row("20 % outliers", ro20);

  World offset_world;
  if (recording.empty()) {
    offset_world = synth(sp.drift_degps, 150.0);
    print_row("camera 150 mm ahead, vision R",
              run(offset_world,
                  simulate_fixes(offset_world,
                                 with(fp, [](FixParams& p) { p.vision_covariance = true; })),
                  cfg, grid_mm));
    for (double drift : {0.0, 0.25, 1.0, 2.0, 4.0}) {
      const World wd = synth(drift, 0.0);
      char name[64];
      std::snprintf(name, sizeof name, "heading drift %.2f deg/s", drift);
      print_row(name, run(wd, simulate_fixes(wd, fp), cfg, grid_mm));
    }
    const World wm = synth(0.0, 0.0, 0.46);
    print_row("drift 0.46 deg/m (wheel mismatch)", run(wm, simulate_fixes(wm, fp), cfg, grid_mm));
    const World wvar = synth(1.0, 0.0, 0.0, 0.5);
    print_row("drift 1 deg/s varying +-50 %", run(wvar, simulate_fixes(wvar, fp), cfg, grid_mm));
    const World wslip = synth(sp.drift_degps, 0.0, 0.0, 0.0, 0.05);
    print_row("slips 0.05/s (wheel +25 %, 0.3 s)",
              run(wslip, simulate_fixes(wslip, fp), cfg, grid_mm));
    EkfConfig cfg_k2 = cfg;
    cfg_k2.kidnap_fixes = 2;
    print_row("slips, kidnap_fixes 2", run(wslip, simulate_fixes(wslip, fp), cfg_k2, grid_mm));
    print_row("kidnap_fixes 2, 20 % outliers", run(base,
                                                   simulate_fixes(base, with(fp,
                                                                             [](FixParams& p) {
                                                                               p.outlier_fraction =
                                                                                   0.2;
                                                                               p.seed = 11;
                                                                             })),
                                                   cfg_k2, grid_mm));
  }
  // The plain 5-state filter of paper 000 (no odometry calibration states), same data.
  EkfConfig cfg5 = cfg;
  agv::fusion::use_uncalibrated_noise(&cfg5);
  const RunResult r5 = run(base, simulate_fixes(base, fp), cfg5, grid_mm);
  print_row("5-state (no calibration)", r5);
  print_row("5-state, delay 50 ms",
            run(base, simulate_fixes(base, with(fp, [](FixParams& p) { p.delay_ns = 50 * kMsNs; })),
                cfg5, grid_mm));
  print_row("5-state, 5 % outliers, delay 50",
            run(base,
                simulate_fixes(base, with(fp,
                                          [](FixParams& p) {
                                            p.outlier_fraction = 0.05;
                                            p.delay_ns = 50 * kMsNs;
                                            p.vision_covariance = true;
                                          })),
                cfg5, grid_mm));
  if (recording.empty()) {
    for (double drift : {0.0, 1.0, 2.0}) {
      const World wd = synth(drift, 0.0);
      char name[64];
      std::snprintf(name, sizeof name, "5-state, heading drift %.2f deg/s", drift);
      print_row(name, run(wd, simulate_fixes(wd, fp), cfg5, grid_mm));
    }
  }
  // Odometry only after the initial fix: the dead-reckoning error the fixes must remove.
  print_row("odometry only (first fix only)", run(base, simulate_fixes(base, fp), cfg, grid_mm,
                                                  /*use_fixes=*/false));

  std::printf("\noutliers by kind (5 %% run / 20 %% run): corrupted -> accepted\n");
  for (int k = 1; k < 6; ++k)
    std::printf("  %-18s %4ld -> %ld   /  %4ld -> %ld\n", kOutlierNames[k], ro.outliers_by_kind[k],
                ro.accepted_by_kind[k], ro20.outliers_by_kind[k], ro20.accepted_by_kind[k]);
  std::printf("  max position error right after an accepted outlier: %.2f mm / %.2f mm\n",
              ro.max_err_after_outlier_mm, ro20.max_err_after_outlier_mm);

  std::printf(
      "\nvision-offset detection limit (every fix corrupted by an offset of the given size, "
      "so each gated one is compared with dead reckoning since the last good landmark):\n");
  for (double m : {2.0, 5.0, 10.0, 15.0, 20.0, 30.0}) {
    // Only 10 % corrupted so the track stays anchored by good fixes.
    const RunResult rs = run(base,
                             simulate_fixes(base, with(fp,
                                                       [m](FixParams& p) {
                                                         p.outlier_fraction = 0.1;
                                                         p.offset_only_min_mm = m;
                                                         p.offset_only_max_mm = m;
                                                         p.seed = 23;
                                                       })),
                             cfg, grid_mm);
    std::printf("  offset %5.1f mm: %4ld corrupted, %4ld accepted (%.0f %%)\n", m, rs.outliers,
                rs.outliers_accepted,
                rs.outliers ? 100.0 * static_cast<double>(rs.outliers_accepted) /
                                  static_cast<double>(rs.outliers)
                            : 0.0);
  }

  const double mid0 = percentile(r0.midway_mm, 0.95), mid50 = percentile(r50.midway_mm, 0.95);
  const double lm0 = percentile(r0.at_landmark_mm, 0.95),
               lm50 = percentile(r50.at_landmark_mm, 0.95);
  std::printf("\ntargets:\n");
  std::printf("  error at a landmark <= 1 mm: p95 %.3f mm, max %.3f mm -> %s\n", lm0,
              percentile(r0.at_landmark_mm, 1.0),
              percentile(r0.at_landmark_mm, 1.0) <= 1.0 ? "met" : "NOT met");
  std::printf("  midway p95 <= 10 mm: %.2f mm -> %s\n", mid0, mid0 <= 10.0 ? "met" : "NOT met");
  std::printf("  0 accepted outliers at 5 %%: %ld accepted -> %s\n", ro.outliers_accepted,
              ro.outliers_accepted == 0 ? "met" : "NOT met");
  std::printf(
      "  50 ms delay within 5 %%: midway p95 %.3f vs %.3f (ratio %.4f), landmark p95 %.4f vs %.4f "
      "(ratio %.4f) -> %s\n",
      mid50, mid0, mid50 / mid0, lm50, lm0, lm50 / lm0,
      (std::abs(mid50 / mid0 - 1.0) <= 0.05 && std::abs(lm50 / lm0 - 1.0) <= 0.05) ? "met"
                                                                                   : "NOT met");
  return 0;
}
