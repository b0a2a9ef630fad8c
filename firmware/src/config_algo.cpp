// Reading of the algorithm sections of the configuration (vision, fusion). Key names are the
// C++ field names; meanings, trade-offs and defaults are documented next to the fields in
// algo/include/agv/vision/landmark_localizer.hpp and algo/include/agv/fusion/ekf.hpp, and
// summarised in docs/config.md.
#include <cmath>

#include "config.hpp"
#include "yaml_checker.hpp"

namespace agv::config {

namespace {

void read_vision(YamlChecker& c, const YAML::Node& root, vision::VisionConfig* v) {
  const std::string p = "vision";
  const YAML::Node n = c.section(root, "", "vision");
  c.number(n, p, "adaptive_block_mm", 2.0, 200.0, &v->adaptive_block_mm);
  c.number(n, p, "adaptive_offset", 0.0, 100.0, &v->adaptive_offset);
  c.number(n, p, "corner_threshold", 0.1, 0.99, &v->corner_threshold);
  c.boolean(n, p, "qr_guided", &v->qr_guided);
  c.integer(n, p, "qr_max_missing_modules", 0, 625, &v->qr_max_missing_modules);
  c.boolean(n, p, "qr_try_harder", &v->qr_try_harder);
  c.number(n, p, "map_tolerance_mm", 0.0, 1000.0, &v->map_tolerance_mm);
  c.number(n, p, "map_tolerance_deg", 0.0, 180.0, &v->map_tolerance_deg);
  c.number(n, p, "logo_threshold", 0.0, 1.0, &v->logo_threshold);
  c.number(n, p, "logo_margin", 0.0, 1.0, &v->logo_margin);
  c.number(n, p, "edge_threshold_rel", 0.01, 1.0, &v->edge_threshold_rel);
  c.number(n, p, "edge_direction_tol_deg", 1.0, 45.0, &v->edge_direction_tol_deg);
  c.boolean(n, p, "subpixel", &v->subpixel);
  c.boolean(n, p, "robust", &v->robust);
  c.integer(n, p, "min_points_per_line", 3, 10000, &v->min_points_per_line);
  c.integer(n, p, "min_points_total", 8, 100000, &v->min_points_total);
  c.boolean(n, p, "allow_partly_outside", &v->allow_partly_outside);
  c.number(n, p, "cov_inflation", 0.1, 1000.0, &v->cov_inflation);
  c.number(n, p, "sigma_floor_mm", 0.0, 100.0, &v->sigma_floor_mm);
  c.number(n, p, "sigma_floor_deg", 0.0, 10.0, &v->sigma_floor_deg);
  c.finish_map(n, p);
}

void read_ms(YamlChecker& c, const YAML::Node& n, const std::string& p, const char* key, double lo,
             double hi, std::int64_t* ns) {
  double ms = static_cast<double>(*ns) / 1e6;
  c.number(n, p, key, lo, hi, &ms);
  *ns = static_cast<std::int64_t>(std::llround(ms * 1e6));
}

void read_deg(YamlChecker& c, const YAML::Node& n, const std::string& p, const char* key, double lo,
              double hi, double* rad) {
  double deg = rad_to_deg(*rad);
  c.number(n, p, key, lo, hi, &deg);
  *rad = deg_to_rad(deg);
}

void read_fusion(YamlChecker& c, const YAML::Node& root, fusion::EkfConfig* f) {
  const std::string p = "fusion";
  const YAML::Node n = c.section(root, "", "fusion");
  // First: without calibration states the noise defaults change (keys below still override).
  c.boolean(n, p, "estimate_odometry_calibration", &f->estimate_odometry_calibration);
  if (!f->estimate_odometry_calibration) fusion::use_uncalibrated_noise(f);
  c.number(n, p, "accel_sigma_mps2", 0.0, 100.0, &f->accel_sigma_mps2);
  c.number(n, p, "yaw_accel_sigma_radps2", 0.0, 100.0, &f->yaw_accel_sigma_radps2);
  c.number(n, p, "along_track_sigma_mm_per_sqrt_m", 0.0, 1000.0,
           &f->along_track_sigma_mm_per_sqrt_m);
  c.number(n, p, "cross_track_sigma_mm_per_sqrt_m", 0.0, 1000.0,
           &f->cross_track_sigma_mm_per_sqrt_m);
  read_deg(c, n, p, "heading_sigma_deg_per_sqrt_m", 0.0, 10.0, &f->heading_sigma_rad_per_sqrt_m);
  read_deg(c, n, p, "heading_drift_sigma_deg_per_sqrt_s", 0.0, 10.0,
           &f->heading_drift_sigma_rad_per_sqrt_s);
  c.number(n, p, "odom_v_sigma_mps", 1e-6, 10.0, &f->odom_v_sigma_mps);
  read_deg(c, n, p, "odom_omega_sigma_degps", 1e-6, 100.0, &f->odom_omega_sigma_radps);
  c.number(n, p, "fix_cov_scale", 0.01, 1000.0, &f->fix_cov_scale);
  c.number(n, p, "fix_floor_sigma_mm", 0.0, 100.0, &f->fix_floor_sigma_mm);
  read_deg(c, n, p, "fix_floor_sigma_deg", 0.0, 10.0, &f->fix_floor_sigma_rad);
  c.number(n, p, "gate_probability", 0.5, 0.999999, &f->gate_probability);
  c.integer(n, p, "kidnap_fixes", 2, 100, &f->kidnap_fixes);
  c.number(n, p, "kidnap_min_separation_mm", 0.0, 100000.0, &f->kidnap_min_separation_mm);
  read_ms(c, n, p, "kidnap_min_duration_ms", 0.0, 600000.0, &f->kidnap_min_duration_ns);
  c.number(n, p, "init_v_scale_sigma", 0.0, 1.0, &f->init_v_scale_sigma);
  c.number(n, p, "init_omega_scale_sigma", 0.0, 1.0, &f->init_omega_scale_sigma);
  read_deg(c, n, p, "init_omega_bias_sigma_degps", 0.0, 90.0, &f->init_omega_bias_sigma_radps);
  read_deg(c, n, p, "init_omega_per_v_sigma_degpm", 0.0, 90.0, &f->init_omega_per_v_sigma_radpm);
  c.number(n, p, "v_scale_sigma_per_sqrt_s", 0.0, 1.0, &f->v_scale_sigma_per_sqrt_s);
  c.number(n, p, "omega_scale_sigma_per_sqrt_s", 0.0, 1.0, &f->omega_scale_sigma_per_sqrt_s);
  read_deg(c, n, p, "omega_bias_sigma_degps_per_sqrt_s", 0.0, 90.0,
           &f->omega_bias_sigma_radps_per_sqrt_s);
  read_deg(c, n, p, "omega_per_v_sigma_degpm_per_sqrt_s", 0.0, 90.0,
           &f->omega_per_v_sigma_radpm_per_sqrt_s);
  std::int64_t hist = static_cast<std::int64_t>(f->history_capacity);
  c.integer(n, p, "history_capacity", 16, 100000, &hist);
  f->history_capacity = static_cast<std::size_t>(hist);
  read_ms(c, n, p, "max_fix_delay_ms", 1.0, 10000.0, &f->max_fix_delay_ns);
  read_ms(c, n, p, "max_fix_lead_ms", 0.0, 10000.0, &f->max_fix_lead_ns);
  std::int64_t held = static_cast<std::int64_t>(f->held_fix_capacity);
  c.integer(n, p, "held_fix_capacity", 1, 1000, &held);
  f->held_fix_capacity = static_cast<std::size_t>(held);
  std::string timing = f->odom_sample_timing == fusion::EkfConfig::OdomSampleTiming::kInstant
                           ? "instant"
                           : "period_mean";
  c.choice(n, p, "odom_sample_timing", {"period_mean", "instant"}, &timing);
  f->odom_sample_timing = timing == "instant" ? fusion::EkfConfig::OdomSampleTiming::kInstant
                                              : fusion::EkfConfig::OdomSampleTiming::kPeriodMean;
  read_ms(c, n, p, "odom_period_ms", 0.1, 1000.0, &f->odom_period_ns);
  read_ms(c, n, p, "odom_gap_ms", 0.1, 10000.0, &f->odom_gap_ns);
  c.number(n, p, "gap_accel_sigma_mps2", 0.0, 100.0, &f->gap_accel_sigma_mps2);
  c.number(n, p, "gap_yaw_accel_sigma_radps2", 0.0, 100.0, &f->gap_yaw_accel_sigma_radps2);
  c.number(n, p, "gap_yaw_rate_change_sigma_radps", 0.0, 100.0,
           &f->gap_yaw_rate_change_sigma_radps);
  c.boolean(n, p, "relocalize_from_single_fix", &f->relocalize_from_single_fix);
  c.number(n, p, "relocalize_max_fix_sigma_mm", 0.001, 1000.0, &f->relocalize_max_fix_sigma_mm);
  read_deg(c, n, p, "relocalize_max_fix_sigma_deg", 0.001, 90.0, &f->relocalize_max_fix_sigma_rad);
  read_ms(c, n, p, "localized_timeout_ms", 10.0, 600000.0, &f->localized_timeout_ns);
  read_ms(c, n, p, "odom_timeout_ms", 5.0, 10000.0, &f->odom_timeout_ns);
  c.number(n, p, "lost_position_sigma_mm", 0.1, 10000.0, &f->lost_position_sigma_mm);
  read_deg(c, n, p, "lost_heading_sigma_deg", 0.01, 180.0, &f->lost_heading_sigma_rad);
  c.finish_map(n, p);
}

}  // namespace

void read_algo_sections(YamlChecker& c, const YAML::Node& root, Config* cfg) {
  read_vision(c, root, &cfg->vision);
  read_fusion(c, root, &cfg->fusion);
  const YAML::Node r = c.section(root, "", "replay");
  c.number(r, "replay", "fix_delay_ms", 0.0, 1000.0, &cfg->replay_fix_delay_ms);
  c.finish_map(r, "replay");
  const std::string err = fusion::validate(cfg->fusion);
  if (!err.empty()) c.error("fusion", err);
}

protocol::ProtocolConfig protocol_config(const Config& cfg) {
  protocol::ProtocolConfig p;
  p.base_id = cfg.can.base_id;
  p.extended_ids = cfg.can.extended_ids;
  p.odometry.mode = cfg.can.odometry_mode == "wheels" ? protocol::OdometryMode::kWheels
                                                      : protocol::OdometryMode::kTwist;
  p.odometry.can_id = cfg.can.odometry_id;
  p.odometry.extended_id = cfg.can.extended_ids;
  p.odometry.protected_e2e = cfg.can.odometry_protected;
  p.odometry.track_width_mm = cfg.can.track_width_mm;
  p.odometry.speed_scale = cfg.can.wheel_speed_scale;
  return p;
}

}  // namespace agv::config
