// Vehicle calibration (issue 16): camera mounting (offset, yaw, height, roll, pitch), odometry
// (speed scale, yaw-rate scale, yaw-rate bias) and the camera-odometry time offset, estimated
// jointly by nonlinear least squares (Ceres) from a calibration drive over mapped landmarks.
//
// Model (all in the world frame W of the map, docs/frames.md):
//  - Odometry. Sample k, stamped T_k on the odometry clock, reports (v_k, omega_k) as the mean
//    over (T_{k-1}, T_k]. The true rates are  v = speed_scale * v_k,
//    omega = yaw_rate_scale * omega_k + yaw_rate_bias  (piecewise constant). An instant at
//    camera time t is stamped t + time_offset on the odometry clock (odometry clock = camera
//    clock + time_offset; time_offset > 0: odometry stamps are late). The relative motion
//    from camera time a to b is the unicycle integral of those rates over
//    [a + time_offset, b + time_offset] (midpoint heading per piece).
//  - Anchors. The drive is cut into landmark passes (consecutive frames seeing one landmark);
//    each pass is cut into sub-passes of at most `max_subpass_s` (default: one frame each).
//    Sub-pass j has a free vehicle pose A_j (x, y, theta) at the time of its first frame.
//  - Frames. The vehicle pose at a frame of sub-pass j is A_j (+) odometry(t_j -> t). Each
//    mapped landmark corner (outer and inner border corners, landmark frame (+-h, +-h)) is
//    projected through the mounting (CameraMount, tilt included) to undistorted normalised image
//    coordinates; residual = (predicted - observed) * fx / pixel_sigma_px.
//  - Odometry links. Consecutive sub-passes j, j+1: residual = A_{j+1} (-) (A_j (+) odometry(
//    t_j -> t_{j+1})), weighted by the odometry noise accumulated over the interval (white
//    noise per sample in v and omega; the heading noise adds dist * sigma_theta / sqrt(3)
//    across track).
// The map fixes the gauge: absolute heading comes from driving along the vehicle's x axis
// between landmarks, the camera yaw from the landmark's orientation in the image, the offset
// from rotations (turns), height from the landmark size, tilt from the perspective across the
// image, scales and bias from odometry vs vision over turns and straights, the time offset from
// speed changes with a landmark in view.
//
// Observability: the standard deviation of every global parameter comes from Ceres' covariance
// (anchors marginalised). A parameter whose sigma exceeds its limit, or that lies in a
// (near-)null space of the problem, is reported as not determined, with the parameters it
// trades off against, and is never written to the configuration snippet.
#pragma once

#include <array>
#include <cstdint>
#include <string>
#include <vector>

#include "agv/common/camera_model.hpp"
#include "agv/common/landmark.hpp"

namespace agv::desk::vcal {

struct OdomSample {
  std::int64_t t_ns = 0;  // odometry clock
  double v_mps = 0.0, omega_radps = 0.0;
};

// One frame's raw landmark observation: undistorted normalised image coordinates (x/z, y/z in
// the OpenCV camera frame) of the border corners: outer 0..3 at landmark (h_out, h_out),
// (-h_out, h_out), (-h_out, -h_out), (h_out, -h_out), inner 4..7 the same with h_in.
struct CornerObservation {
  std::int64_t t_ns = 0;  // camera clock (exposure mid-time)
  std::uint32_t landmark_id = 0;
  std::array<Vec2, 8> xn{};
  std::array<bool, 8> valid{};
};

// The estimated quantities. time_offset_s: odometry clock = camera clock + time_offset_s. The
// configuration keys `odometry.*` and localizer::OdometryCorrection apply exactly this model.
struct VehicleParams {
  CameraMount mount;
  double speed_scale = 1.0;
  double yaw_rate_scale = 1.0;
  double yaw_rate_bias_radps = 0.0;
  double time_offset_s = 0.0;
};

struct Options {
  double fx_px = 769.0;         // to express residuals in pixels
  double pixel_sigma_px = 0.1;  // corner noise
  // Huber loss per frame beyond this many sigmas (RMS over the frame's corners); 0 = plain
  // least squares.
  double robust_sigmas = 3.0;
  double odom_v_sigma_mps = 0.002;       // per odometry sample (white)
  double odom_omega_sigma_radps = 0.01;  // per odometry sample (white)
  // Frames of one pass closer than this share one free pose (exact odometry in between).
  // 0 = every frame has its own pose, linked by odometry: the odometry noise is then modelled
  // correctly (a shared pose treats noisy odometry as exact and biases the speed scale low).
  double max_subpass_s = 0.0;
  double pass_gap_s = 0.2;  // a longer gap without observation ends a pass
  int min_passes = 4;
  int min_frames_per_pass = 3;
  // A parameter is determined (and written) when its standard deviation is at most this:
  // offset/height mm, angles deg, scales relative, bias deg/s, time offset ms.
  double max_sigma_mm = 0.25, max_sigma_yaw_deg = 0.05, max_sigma_tilt_deg = 0.05;
  double max_sigma_scale = 0.001, max_sigma_bias_degps = 0.02, max_sigma_time_ms = 1.0;
  int max_iterations = 200;
};

struct ParamReport {
  std::string name;  // configuration-style name
  std::string unit;
  double initial = 0.0, value = 0.0, sigma = 0.0;  // in `unit`
  bool determined = false;
  std::string why;  // when not determined
};

struct PassReport {
  int index = 0;
  std::uint32_t landmark_id = 0;
  double t_start_s = 0.0, t_end_s = 0.0;  // relative to the first frame
  int frames = 0;
  double rms_before_px = 0.0, rms_after_px = 0.0;
};

struct Result {
  VehicleParams estimate;
  std::vector<ParamReport> params;  // ordered: mounting (6), odometry (3), time offset
  std::vector<PassReport> passes;
  std::vector<std::string> warnings;
  int frames_used = 0, subpasses = 0, iterations = 0;
  double rms_before_px = 0.0, rms_after_px = 0.0;
  bool turns_seen = false;
};

// False with *error naming what is missing (no odometry, no observation of a mapped landmark,
// too few passes, no frame inside the odometry span, solver failure).
bool calibrate_vehicle(const std::vector<OdomSample>& odom,
                       const std::vector<CornerObservation>& obs, const LandmarkMap& map,
                       double outer_half_mm, double inner_half_mm, const VehicleParams& initial,
                       const Options& opt, Result* out, std::string* error);

// Corners of the landmark in its own frame (the order of CornerObservation::xn).
std::array<Vec2, 8> landmark_corners(double outer_half_mm, double inner_half_mm);

}  // namespace agv::desk::vcal
