// Gyro calibration from a vehicle calibration drive: the gyro's scale and bias (keys
// imu.scale, imu.bias_degps, applied by localizer::GyroCorrection as
// rate' = scale * rate + bias) and its clock offset, with standard deviations, from the gyro
// samples of imu.csv and the landmark fixes of the drive.
//
// Model. Every frame with a mapped landmark gives the vehicle heading h_i: the landmark corners
// (CornerObservation, undistorted normalised coordinates) are intersected with the floor through
// the calibrated camera mounting (vehicle calibration result, tilt and yaw included), a rigid 2D
// fit to the printed corners gives the landmark's yaw in the vehicle frame, and the map's
// landmark heading minus it is the vehicle heading. The corrected gyro integrates to the true
// heading:
//   h_i = alpha_i + s * G(t_i + tau) + c * (t_i + tau - t_0) + e_i
// with G the integral of the raw samples (each the mean rate over the interval up to its stamp),
// s = imu.scale, c = imu.bias (rad/s), tau the gyro clock minus the camera clock, e_i the fix's
// heading noise (white, sigma estimated from the data) and alpha_i a random walk driven by the
// gyro's white noise (fusion.gyro_noise_density). tau enters linearised (rate * delta tau) and is
// re-linearised a few times. State (alpha, s, c, delta tau): a linear Kalman filter over the
// frames in time order, whose final covariance of (s, c, tau) is that of the batch least squares.
// Robustness: after a first solve, a frame whose residual departs from the median of its
// neighbours in the same landmark pass by more than outlier_sigmas noise sigmas (a bad fix) is
// dropped and the problem solved again. The covariance is scaled by the reduced chi-square of the
// innovations when that exceeds 1 (never shrunk).
// Observability: the scale needs heading change between fixes (turns); without, s * G and c * t
// are the same column and the scale's sigma exceeds its limit: the scale is then reported as not
// determined with the reason, and the bias is solved with the scale fixed at the configured
// imu.scale (the bias then belongs to that scale).
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "agv/common/camera_model.hpp"
#include "agv/common/landmark.hpp"
#include "calib_vehicle.hpp"

namespace agv::desk::vcal {

struct GyroSample {
  std::int64_t t_ns = 0;  // the gyro's own clock
  double rate_radps = 0.0;
};

struct GyroOptions {
  // White rate noise of the gyro, rad/s per sqrt(Hz) (fusion.gyro_noise_density_degps_per_sqrt_hz).
  double noise_density_radps_rthz = 0.01 * kPi / 180.0;
  // Floor of the fix heading noise (rad); the noise itself is estimated from the frames.
  double min_heading_sigma_rad = 0.001 * kPi / 180.0;
  double outlier_sigmas = 6.0;  // a frame's residual beyond this many noise sigmas is dropped
  int relinearisations = 3;
  // Determined (and written) when the standard deviation is at most this.
  double max_sigma_scale = 0.001, max_sigma_bias_degps = 0.02, max_sigma_time_ms = 1.0;
  // Written filter priors (fusion.gyro_init_scale_sigma, fusion.gyro_init_bias_sigma_degps):
  // sigma_factor times the estimate's sigma, at least the floor. The scale floor: what the
  // calibration cannot see (temperature drift of a MEMS scale, about 0.03 %/10 K). The bias
  // floor: a MEMS gyro's turn-on bias repeats only to a few hundredths of a deg/s from one
  // power-up to the next, and the filter learns it at standstill within seconds.
  double sigma_factor = 3.0;
  double min_scale_sigma = 0.0005;
  double min_bias_sigma_degps = 0.05;
};

struct GyroResult {
  double scale = 1.0, scale_sigma = 0.0;                    // imu.scale
  double bias_radps = 0.0, bias_sigma_radps = 0.0;          // imu.bias_degps (rad/s here)
  double clock_offset_s = 0.0, clock_offset_sigma_s = 0.0;  // gyro clock - camera clock
  bool scale_determined = false, bias_determined = false, clock_offset_determined = false;
  bool scale_fixed = false;  // bias solved with the scale fixed at the initial one
  std::string why_scale, why_bias, why_clock_offset;  // when not determined
  int frames = 0, frames_used = 0, frames_rejected = 0;
  double heading_sigma_deg = 0.0;  // estimated fix heading noise
  double turned_deg = 0.0;         // heading change between the fixes used (sum of |delta|)
  double chi2_per_frame = 0.0;
  // Written priors (GyroOptions::sigma_factor, floors).
  double prior_scale_sigma = 0.0, prior_bias_sigma_degps = 0.0;
  std::vector<std::string> warnings;
};

// Vehicle heading (world, rad) of one frame from its landmark corners and the mounting; false
// when the landmark is not in the map, fewer than 3 corners are valid or a ray misses the floor.
bool frame_heading(const CornerObservation& o, const LandmarkMap& map, double outer_half_mm,
                   double inner_half_mm, const CameraMount& mount, double* heading_rad);

// initial_scale: the configured imu.scale (kept when the drive does not determine the scale);
// initial_clock_offset_s: gyro clock - camera clock expected (camera.time_offset +
// imu.time_offset). False with *error when there is nothing to estimate from (no gyro samples,
// fewer than 10 frames with a heading inside the gyro's span).
bool calibrate_gyro(const std::vector<GyroSample>& gyro, const std::vector<CornerObservation>& obs,
                    const LandmarkMap& map, double outer_half_mm, double inner_half_mm,
                    const CameraMount& mount, double initial_scale, double initial_clock_offset_s,
                    const GyroOptions& opt, GyroResult* out, std::string* error);

}  // namespace agv::desk::vcal
