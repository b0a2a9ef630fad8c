// Validation of the EKF configuration, part by part.
#include "agv/fusion/ekf_config.hpp"

#include <cmath>

namespace agv::fusion {

namespace {

bool finite_nonneg(double v) { return std::isfinite(v) && v >= 0.0; }
bool finite_pos(double v) { return std::isfinite(v) && v > 0.0; }

}  // namespace

std::string validate(const CoreConfig& c) {
  if (!finite_nonneg(c.accel_sigma_mps2) || !finite_nonneg(c.yaw_accel_sigma_radps2))
    return "accel_sigma_mps2 and yaw_accel_sigma_radps2 must be finite and >= 0";
  if (!finite_nonneg(c.along_track_sigma_mm_per_sqrt_m) ||
      !finite_nonneg(c.cross_track_sigma_mm_per_sqrt_m) ||
      !finite_nonneg(c.heading_sigma_rad_per_sqrt_m) ||
      !finite_nonneg(c.heading_drift_sigma_rad_per_sqrt_s) ||
      !finite_nonneg(c.turn_heading_sigma_rad_per_sqrt_rad))
    return "process noise densities must be finite and >= 0";
  if (c.history_capacity < 8) return "history_capacity must be >= 8";
  return {};
}

std::string validate(const OdometryConfig& c) {
  if (!finite_pos(c.v_sigma_mps) || !finite_pos(c.omega_sigma_radps))
    return "odom_v_sigma_mps and odom_omega_sigma_radps must be finite and > 0";
  if (!finite_pos(c.max_abs_v_mps) || !finite_pos(c.max_abs_omega_radps))
    return "max_abs_v_mps and max_abs_omega_radps must be finite and > 0";
  if (!finite_nonneg(c.init_v_scale_sigma) || !finite_nonneg(c.init_omega_scale_sigma) ||
      !finite_nonneg(c.init_omega_bias_sigma_radps) || !finite_nonneg(c.v_scale_sigma_per_sqrt_s) ||
      !finite_nonneg(c.omega_scale_sigma_per_sqrt_s) ||
      !finite_nonneg(c.omega_bias_sigma_radps_per_sqrt_s) ||
      !finite_nonneg(c.init_omega_per_v_sigma_radpm) ||
      !finite_nonneg(c.omega_per_v_sigma_radpm_per_sqrt_s))
    return "odometry calibration sigmas must be finite and >= 0";
  if (c.period_ns <= 0 || c.gap_ns < c.period_ns)
    return "odom_period_ns must be > 0 and odom_gap_ns >= odom_period_ns";
  if (!finite_nonneg(c.gap_accel_sigma_mps2) || !finite_nonneg(c.gap_yaw_accel_sigma_radps2) ||
      !finite_nonneg(c.gap_yaw_rate_change_sigma_radps))
    return "gap sigmas must be finite and >= 0";
  return {};
}

std::string validate(const GyroConfig& c) {
  if (!finite_pos(c.noise_density_radps_per_sqrt_hz) || !finite_nonneg(c.init_bias_sigma_radps) ||
      !finite_nonneg(c.bias_sigma_radps_per_sqrt_s) || !finite_nonneg(c.init_scale_sigma) ||
      !finite_nonneg(c.scale_sigma_per_sqrt_s))
    return "gyro noise density must be finite and > 0, gyro calibration sigmas finite and >= 0";
  if (!finite_pos(c.saturation_radps)) return "gyro_saturation_radps must be finite and > 0";
  if (c.gap_ns <= 0 || c.capacity < 8) return "gyro_gap_ns must be > 0 and gyro_capacity >= 8";
  if (!finite_nonneg(c.standstill_v_mps) || !finite_nonneg(c.standstill_omega_radps) ||
      !finite_pos(c.standstill_omega_sigma_radps))
    return "standstill limits must be finite and >= 0, standstill_omega_sigma_radps > 0";
  return {};
}

std::string validate(const SlipConfig& c) {
  if (!finite_nonneg(c.yaw_rate_radps) || !finite_nonneg(c.yaw_rate_fraction) ||
      !finite_pos(c.wheel_track_mm) || c.max_duration_ns < 0 || !finite_pos(c.noise_sigmas) ||
      !finite_nonneg(c.max_accel_mps2) || !finite_pos(c.wheel_step_min_mps) ||
      !finite_nonneg(c.hold_sigma_fraction))
    return "slip limits and max_accel_mps2 must be finite and >= 0, wheel_track_mm, "
           "slip_noise_sigmas and wheel_step_min_mps > 0";
  return {};
}

std::string validate(const FixConfig& c) {
  if (!finite_pos(c.cov_scale)) return "fix_cov_scale must be finite and > 0";
  if (!finite_nonneg(c.floor_sigma_mm) || !finite_nonneg(c.floor_sigma_rad))
    return "fix floor sigmas must be finite and >= 0";
  if (!(c.gate_probability > 0.0 && c.gate_probability < 1.0))
    return "gate_probability must be in (0, 1)";
  if (!finite_pos(c.init_v_sigma_mps) || !finite_pos(c.init_omega_sigma_radps))
    return "init sigmas must be finite and > 0";
  if (c.held_capacity < 1) return "held_fix_capacity must be >= 1";
  if (c.max_delay_ns <= 0 || c.max_lead_ns < 0)
    return "max_fix_delay_ns must be > 0 and max_fix_lead_ns >= 0";
  return {};
}

std::string validate(const RangeBearingConfig& c) {
  if (!finite_nonneg(c.range_floor_sigma_mm) || !finite_nonneg(c.bearing_floor_sigma_rad))
    return "range-bearing floor sigmas must be finite and >= 0";
  if (!(c.gate_probability > 0.0 && c.gate_probability < 1.0))
    return "range-bearing gate_probability must be in (0, 1)";
  if (c.max_delay_ns <= 0) return "range-bearing max_delay_ns must be > 0";
  return {};
}

std::string validate(const RecoveryConfig& c) {
  if (c.kidnap_fixes < 2) return "kidnap_fixes must be >= 2";
  if (!finite_nonneg(c.kidnap_min_separation_mm) || c.kidnap_min_duration_ns < 0)
    return "kidnap_min_separation_mm and kidnap_min_duration_ns must be finite and >= 0";
  if (!finite_pos(c.relocalize_max_fix_sigma_mm) || !finite_pos(c.relocalize_max_fix_sigma_rad))
    return "relocalize_max_fix sigmas must be finite and > 0";
  if (!finite_nonneg(c.unseen_slip_max_rad)) return "unseen_slip_max_rad must be finite and >= 0";
  return {};
}

std::string validate(const HealthConfig& c) {
  if (c.localized_timeout_ns <= 0 || c.odom_timeout_ns <= 0)
    return "localized_timeout_ns and odom_timeout_ns must be > 0";
  if (!finite_pos(c.lost_position_sigma_mm) || !finite_pos(c.lost_heading_sigma_rad))
    return "lost sigma limits must be finite and > 0";
  return {};
}

std::string validate(const EkfConfig& c) {
  for (const std::string& err :
       {validate(c.core), validate(c.odometry), validate(c.gyro), validate(c.slip), validate(c.fix),
        validate(c.range_bearing), validate(c.recovery), validate(c.health)}) {
    if (!err.empty()) return err;
  }
  return {};
}

}  // namespace agv::fusion
