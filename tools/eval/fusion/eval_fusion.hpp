// eval_fusion internals shared by its files: simulated world (truth, odometry, frame times) and
// simulated landmark fixes. Not part of agv_algo.
#pragma once

#include <Eigen/Core>
#include <algorithm>
#include <cstdint>
#include <string>
#include <vector>

#include "agv/common/geometry.hpp"

namespace eval_fusion {

using agv::Pose2;

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

struct GyroSample {
  std::int64_t t_ns;
  double rate_radps;  // mean over the interval since the previous sample
};

struct World {
  TruthTrack truth;
  std::vector<OdomSample> odom;
  std::vector<GyroSample> gyro;  // empty: no gyro
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
  // Slips as a floor makes them, not as the simulator found them easiest: starting and ending
  // anywhere inside an odometry period, lasting 0.15-0.5 s, 10-40 % over at the start and
  // random-walking (0.3 per sqrt(s)) while they last.
  bool slip_varying = false;
  double wheelbase_mm = 500.0;
  double v_noise_mps = 0.003;  // per 10 ms sample
  double omega_noise_radps = 0.002;
  double camera_offset_x_mm = 0.0;
  // "grid": random runs along the grid lines with turns in place on landmarks. "lawnmower": rows
  // 1 m apart across grid_cells landmarks at v_max, leaving the grid at each end for a leg of
  // lawnmower_out_m straight, a half circle of radius 0.5 grid and the same straight back
  // (5.6 s at 1 m/s with 2 m: the long legs without a landmark), yaw rate stepping at each arc.
  // Gyro (0 Hz: none): a MEMS part with white rate noise, a constant bias, a bias random walk,
  // a scale error and a range; samples are means over their interval, stamped late by
  // gyro_latency_ms. gyro_bias_step_degps is added from gyro_bias_step_s on.
  double gyro_hz = 0.0;
  double gyro_noise_degps_rthz = 0.01;
  double gyro_bias_degps = 0.2;
  double gyro_bias_walk_degps_rts = 0.002;
  double gyro_scale_error = 0.003;
  double gyro_range_degps = 250.0;
  double gyro_latency_ms = 0.0;
  double gyro_bias_step_degps = 0.0;
  double gyro_bias_step_s = 0.0;
  std::string route = "grid";
  double lawnmower_out_m = 2.0;
  std::uint64_t seed = 1;
};

World make_synthetic_world(const SynthParams& p, double grid_mm);
#ifdef AGV_EVAL_HAVE_RECORDING
bool load_recording_world(const std::string& dir, World* w);
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
inline const char* const kOutlierNames[] = {
    "none",           "wrong_landmark", "digit_100mm", "offset_20_100mm", "heading_90_180deg",
    "heading_3_20deg"};

struct SimFix {
  std::int64_t t_exposure_ns;
  std::int64_t t_delivery_ns;
  Pose2 z;
  Eigen::Matrix3d R;
  OutlierKind outlier;
};

std::vector<SimFix> simulate_fixes(const World& w, const FixParams& p);

// q-quantile (0..1) of v (nearest rank); NaN when empty.
double percentile(std::vector<double> v, double q);

// --honesty: sigma against error between landmarks (honesty.cpp). 0 when every row meets the
// targets.
int run_honesty_table(const SynthParams& base, double grid_mm, int seeds);

}  // namespace eval_fusion
