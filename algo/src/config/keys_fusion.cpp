// Key table rows of the fusion section: fields of agv::fusion::EkfConfig
// (algo/include/agv/fusion/ekf_config.hpp), one group per part of the filter; the key names are
// the flat names they always had, with angles in degrees and times in ms.
// The texts condense the header comments; measurements: docs/design/fusion.md.
#include "key_builders.hpp"

namespace agv::config::detail {

namespace {

// Wheel odometry (OdometryConfig): first, because without calibration states the core noise
// defaults change (the keys after it override).
void add_fusion_odometry(std::vector<Key>* k) {
  Key cal = boolean("fusion.estimate_odometry_calibration",
                    AGV_AT(fusion.odometry.estimate_calibration), true,
                    "the filter also learns speed scale, yaw-rate scale and bias, and yaw rate "
                    "per speed from the fixes (a 1 % scale error alone is 5 mm midway between "
                    "landmarks 1 m apart). false = the plain 5-state filter, and the defaults of "
                    "the four dead-reckoning noise keys below become 5, 2, 0.1 and 0.3");
  cal.set = [](Config& c, const Value& v) {
    c.fusion.odometry.estimate_calibration = std::get<bool>(v);
    if (!c.fusion.odometry.estimate_calibration) fusion::use_uncalibrated_noise(&c.fusion);
  };
  k->push_back(std::move(cal));
  k->push_back(number("fusion.odom_v_sigma_mps", AGV_AT(fusion.odometry.v_sigma_mps), 1e-6, 10.0,
                      0.005,
                      {"m/s",
                       "noise of one odometry speed sample (encoder quantisation ~0.0015 "
                       "m/s per 10 ms). Larger: σ overstates the error between landmarks"}));
  k->push_back(deg_as_rad("fusion.odom_omega_sigma_degps",
                          AGV_AT(fusion.odometry.omega_sigma_radps), 1e-6, 100.0, 0.2,
                          {"deg/s", "noise of one odometry yaw-rate sample; same role"}));
  k->push_back(number("fusion.init_v_scale_sigma", AGV_AT(fusion.odometry.init_v_scale_sigma), 0.0,
                      1.0, 0.03,
                      {"", "prior σ of the speed scale error (new or re-tyred vehicle)"}));
  k->push_back(number("fusion.init_omega_scale_sigma",
                      AGV_AT(fusion.odometry.init_omega_scale_sigma), 0.0, 1.0, 0.03,
                      {"", "prior σ of the yaw-rate scale error"}));
  k->push_back(deg_as_rad("fusion.init_omega_bias_sigma_degps",
                          AGV_AT(fusion.odometry.init_omega_bias_sigma_radps), 0.0, 90.0, 1.5,
                          {"deg/s", "prior σ of the yaw-rate bias"}));
  k->push_back(deg_as_rad("fusion.init_omega_per_v_sigma_degpm",
                          AGV_AT(fusion.odometry.init_omega_per_v_sigma_radpm), 0.0, 90.0, 1.5,
                          {"deg/m", "prior σ of the yaw rate per speed (wheel radius mismatch)"}));
  k->push_back(number("fusion.v_scale_sigma_per_sqrt_s",
                      AGV_AT(fusion.odometry.v_scale_sigma_per_sqrt_s), 0.0, 1.0, 1e-4,
                      {"per √s",
                       "random walk of the speed scale (wear, load). Larger tracks "
                       "changes faster, absorbs more fix noise"}));
  k->push_back(number("fusion.omega_scale_sigma_per_sqrt_s",
                      AGV_AT(fusion.odometry.omega_scale_sigma_per_sqrt_s), 0.0, 1.0, 1e-4,
                      {"per √s", "random walk of the yaw-rate scale; same trade-off"}));
  k->push_back(deg_as_rad("fusion.omega_bias_sigma_degps_per_sqrt_s",
                          AGV_AT(fusion.odometry.omega_bias_sigma_radps_per_sqrt_s), 0.0, 90.0,
                          0.004,
                          {"deg/s per √s",
                           "random walk of the wheels' yaw-rate bias (wheel wear, "
                           "load). 0.1 (the old default, sized for a drifting gyro "
                           "before the gyro had states of its own) made the heading "
                           "σ grow 1.2° over a 7 s leg; a gyro's bias is "
                           "fusion.gyro_bias_walk_degps_per_sqrt_s"}));
  k->push_back(deg_as_rad("fusion.omega_per_v_sigma_degpm_per_sqrt_s",
                          AGV_AT(fusion.odometry.omega_per_v_sigma_radpm_per_sqrt_s), 0.0, 90.0,
                          0.005, {"deg/m per √s", "random walk of the yaw rate per speed"}));
}

// Odometry timing and gaps (OdometryConfig).
void add_fusion_odometry_timing(std::vector<Key>* k) {
  using Timing = fusion::OdometryConfig::SampleTiming;
  k->push_back(enumeration(
      "fusion.odom_sample_timing", AGV_AT(fusion.odometry.sample_timing),
      std::vector<std::pair<std::string, Timing>>{{"period_mean", Timing::kPeriodMean},
                                                  {"instant", Timing::kInstant}},
      "period_mean",
      "what the vehicle's odometry sample is: the mean over the period ending at its stamp "
      "(encoder ticks per period) or the speed at its stamp. Wrong choice: a yaw-rate step "
      "turns into up to ω·period of heading error"));
  k->push_back(ms_as_ns("fusion.odom_period_ms", AGV_AT(fusion.odometry.period_ns), 0.1, 1000.0,
                        10.0,
                        "the source's sample period; after a gap a period-mean sample covers "
                        "only this much"));
  k->push_back(ms_as_ns("fusion.odom_gap_ms", AGV_AT(fusion.odometry.gap_ns), 0.1, 10000.0, 50.0,
                        "samples further apart are a gap (at least odom_period_ms): motion "
                        "beyond this after the last sample is unknown. Larger tolerates more "
                        "jitter before σ grows"));
  k->push_back(number("fusion.gap_accel_sigma_mps2", AGV_AT(fusion.odometry.gap_accel_sigma_mps2),
                      0.0, 100.0, 0.5,
                      {"m/s² per √s",
                       "speed random walk in a gap; half the vehicle's "
                       "acceleration limit keeps 3σ above full braking for gaps "
                       "up to 3 s"}));
  k->push_back(number("fusion.gap_yaw_accel_sigma_radps2",
                      AGV_AT(fusion.odometry.gap_yaw_accel_sigma_radps2), 0.0, 100.0, 1.0,
                      {"rad/s² per √s", "yaw-rate random walk in a gap"}));
  k->push_back(number("fusion.gap_yaw_rate_change_sigma_radps",
                      AGV_AT(fusion.odometry.gap_yaw_rate_change_sigma_radps), 0.0, 100.0, 0.8,
                      {"rad/s",
                       "the yaw rate may change this much at once in a gap (3σ covers "
                       "a 2 rad/s arc with 20 % to spare: at 0.7 a 5 s gap across an arc "
                       "exit left 3σ coverage at 98.3 %); heading σ grows 0.8 rad/s × "
                       "(gap − odom_gap): lost (3°) after a 115 ms gap. Not used while a "
                       "gyro covers the gap"}));
}

// The core (CoreConfig): process noise and the event history.
void add_fusion_core(std::vector<Key>* k) {
  k->push_back(number("fusion.accel_sigma_mps2", AGV_AT(fusion.core.accel_sigma_mps2), 0.0, 100.0,
                      0.5,
                      {"m/s² per √s",
                       "speed random walk when predicting past the newest "
                       "odometry (within odom_gap_ms). Larger: σ grows faster "
                       "between late samples"}));
  k->push_back(number("fusion.yaw_accel_sigma_radps2", AGV_AT(fusion.core.yaw_accel_sigma_radps2),
                      0.0, 100.0, 1.0, {"rad/s² per √s", "yaw-rate random walk; same role"}));
  k->push_back(number("fusion.along_track_sigma_mm_per_sqrt_m",
                      AGV_AT(fusion.core.along_track_sigma_mm_per_sqrt_m), 0.0, 1000.0, 0.6,
                      {"mm per √m",
                       "dead-reckoning position noise along the travel beyond the "
                       "calibration states (slip, floor). Too small: good fixes "
                       "fail the gate; too large: misreads pass and σ overstates "
                       "the error"}));
  k->push_back(number("fusion.cross_track_sigma_mm_per_sqrt_m",
                      AGV_AT(fusion.core.cross_track_sigma_mm_per_sqrt_m), 0.0, 1000.0, 0.3,
                      {"mm per √m", "the same across the travel"}));
  k->push_back(deg_as_rad("fusion.heading_sigma_deg_per_sqrt_m",
                          AGV_AT(fusion.core.heading_sigma_rad_per_sqrt_m), 0.0, 10.0, 0.01,
                          {"deg per √m",
                           "heading noise per travelled distance (wheel slip). Too "
                           "small: fixes after long stretches fail the gate; too "
                           "large: heading misreads pass"}));
  k->push_back(deg_as_rad("fusion.heading_drift_sigma_deg_per_sqrt_s",
                          AGV_AT(fusion.core.heading_drift_sigma_rad_per_sqrt_s), 0.0, 10.0, 0.03,
                          {"deg per √s",
                           "wheel heading drift with time beyond the estimated bias "
                           "(not used where the gyro carries the heading). Sized with "
                           "`eval_fusion --honesty` so σ tracks the error between "
                           "landmarks: 0.15 made σθ 4x the error and the pose lost "
                           "after 2.5 s"}));
  k->push_back(integer("fusion.history_capacity", AGV_AT(fusion.core.history_capacity), 16, 100000,
                       256,
                       {"events",
                        "kept for re-propagating delayed fixes; must exceed the "
                        "odometry rate × max_fix_delay_ms plus the fixes in that time "
                        "(~0.85 kB each, allocated once)"}));
}

// The gyro (GyroConfig).
void add_fusion_gyro(std::vector<Key>* k) {
  k->push_back(deg_as_rad("fusion.gyro_noise_density_degps_per_sqrt_hz",
                          AGV_AT(fusion.gyro.noise_density_radps_per_sqrt_hz), 1e-5, 10.0, 0.01,
                          {"deg/s per √Hz",
                           "white rate noise of the gyro (angle random walk; datasheet "
                           "'noise density'). The heading σ grows by it × √t between "
                           "landmarks. Too small: fixes after long legs fail the gate; "
                           "too large: σ overstates the error"}));
  k->push_back(deg_as_rad("fusion.gyro_init_bias_sigma_degps",
                          AGV_AT(fusion.gyro.init_bias_sigma_radps), 0.0, 90.0, 0.5,
                          {"deg/s",
                           "what the gyro's bias may be after imu.bias_degps (turn-on "
                           "bias). Learned while standing still and from fixes"}));
  k->push_back(deg_as_rad("fusion.gyro_bias_walk_degps_per_sqrt_s",
                          AGV_AT(fusion.gyro.bias_sigma_radps_per_sqrt_s), 0.0, 90.0, 0.002,
                          {"deg/s per √s",
                           "random walk of the gyro bias (bias instability, temperature). "
                           "Larger follows a drifting bias faster and lets σ grow faster"}));
  k->push_back(number("fusion.gyro_init_scale_sigma", AGV_AT(fusion.gyro.init_scale_sigma), 0.0,
                      0.5, 0.01,
                      {"",
                       "what the gyro's scale may be off by after imu.scale (learned over "
                       "turns between fixes)"}));
  k->push_back(deg_as_rad("fusion.gyro_saturation_degps", AGV_AT(fusion.gyro.saturation_radps), 1.0,
                          10000.0, 245.0,
                          {"deg/s",
                           "samples at or beyond this are clipped by the sensor and not "
                           "used (the wheels carry those periods). Just below the "
                           "configured range"}));
}

// Wheel slip (SlipConfig; its track width is can.odometry.track_width_mm).
void add_fusion_slip(std::vector<Key>* k) {
  k->push_back(deg_as_rad("fusion.slip_yaw_rate_degps", AGV_AT(fusion.slip.yaw_rate_radps), 0.0,
                          1000.0, 3.0,
                          {"deg/s",
                           "wheels and gyro disagreeing by more than this (plus 10 % of the "
                           "rate) is a slip. Smaller catches smaller slips and misfires on "
                           "an uncalibrated track width in turns"}));
  k->push_back(number("fusion.slip_noise_sigmas", AGV_AT(fusion.slip.noise_sigmas), 1.0, 1000.0,
                      3.0,
                      {"σ",
                       "with a gyro, a wheel/gyro yaw-rate difference under the slip "
                       "threshold within this many σ of the sample noise and the wheel "
                       "calibration teaches the calibration; a larger one is a slip: the "
                       "speed is corrected by its speed equivalent (difference × track / 2), "
                       "spin or lock as the speed reading's step says, and keeps the rest "
                       "of the doubt as σ over the run. Larger: fewer small slips are "
                       "corrected and the next fixes may be gated; smaller: noise is taken "
                       "for slips more often"}));
  k->push_back(number("fusion.wheel_step_min_mps", AGV_AT(fusion.slip.wheel_step_min_mps), 0.001,
                      10.0, 0.05,
                      {"m/s",
                       "wheels only: one wheel's reading stepping between two periods by "
                       "more than this plus the acceleration limit while the other wheel "
                       "stays is a slip; the wheel is read less the step until it steps "
                       "back (docs/design/fusion.md \"Wheel slip without a gyro\"). Keep "
                       "it above one encoder count per odometry period: smaller lets "
                       "quantisation start holds; larger leaves smaller slips uncorrected"}));
}

// Landmark fixes (FixConfig).
void add_fusion_fix(std::vector<Key>* k) {
  k->push_back(number("fusion.fix_cov_scale", AGV_AT(fusion.fix.cov_scale), 0.01, 1000.0, 1.0,
                      {"",
                       "fix covariance used = scale × reported + floor². > 1 distrusts an "
                       "optimistic vision covariance"}));
  k->push_back(number("fusion.fix_floor_sigma_mm", AGV_AT(fusion.fix.floor_sigma_mm), 0.0, 100.0,
                      0.1,
                      {"mm",
                       "what vision cannot know: landmark placement and survey error, "
                       "camera mounting"}));
  k->push_back(deg_as_rad("fusion.fix_floor_sigma_deg", AGV_AT(fusion.fix.floor_sigma_rad), 0.0,
                          10.0, 0.01, {"deg", "the same for the heading"}));
  k->push_back(number("fusion.gate_probability", AGV_AT(fusion.fix.gate_probability), 0.5, 0.999999,
                      0.999,
                      {"",
                       "chi-square(3) gate on the fix innovation (0.999 = 16.27). Higher "
                       "accepts more true fixes after poor dead reckoning, lets larger "
                       "misreads through"}));
  k->push_back(ms_as_ns("fusion.max_fix_delay_ms", AGV_AT(fusion.fix.max_delay_ns), 1.0, 10000.0,
                        500.0, "fixes older than this behind the newest event are rejected"));
  k->push_back(ms_as_ns("fusion.max_fix_lead_ms", AGV_AT(fusion.fix.max_lead_ns), 0.0, 10000.0,
                        200.0,
                        "fixes further ahead of the newest odometry are held and fused when it "
                        "catches up; still further ahead of flowing odometry = camera clock "
                        "error, rejected"));
  k->push_back(integer("fusion.held_fix_capacity", AGV_AT(fusion.fix.held_capacity), 1, 1000, 8,
                       {"fixes", "kept while odometry is late (oldest dropped, counted)"}));
}

// Range-bearing observations (RangeBearingConfig).
void add_fusion_range_bearing(std::vector<Key>* k) {
  k->push_back(number("fusion.range_bearing_range_floor_sigma_mm",
                      AGV_AT(fusion.range_bearing.range_floor_sigma_mm), 0.0, 1000.0, 2.0,
                      {"mm",
                       "added to the observation's range σ (in quadrature): the landmark's "
                       "survey error and the camera mount's calibration, which the "
                       "measurement cannot know"}));
  k->push_back(deg_as_rad("fusion.range_bearing_bearing_floor_sigma_deg",
                          AGV_AT(fusion.range_bearing.bearing_floor_sigma_rad), 0.0, 10.0, 0.1,
                          {"deg", "the same for the bearing (the mount's yaw calibration)"}));
  k->push_back(number("fusion.range_bearing_gate_probability",
                      AGV_AT(fusion.range_bearing.gate_probability), 0.5, 0.999999, 0.999,
                      {"",
                       "chi-square(2) gate on the range-bearing innovation (0.999 = 13.8). "
                       "Higher accepts more true observations after poor dead reckoning, lets "
                       "larger misreads and map errors through"}));
  k->push_back(ms_as_ns("fusion.range_bearing_max_delay_ms",
                        AGV_AT(fusion.range_bearing.max_delay_ns), 1.0, 10000.0, 500.0,
                        "observations older than this behind the newest event are rejected "
                        "(fused through the history replay when younger)"));
}

// Recovery (RecoveryConfig): kidnap, re-localisation, unseen slip.
void add_fusion_recovery(std::vector<Key>* k) {
  k->push_back(integer("fusion.kidnap_fixes", AGV_AT(fusion.recovery.kidnap_fixes), 2, 100, 3,
                       {"",
                        "agreeing gate-rejected fixes that re-initialise the pose. Smaller "
                        "recovers faster after the vehicle was moved by hand, larger "
                        "resists repeated misreads"}));
  k->push_back(number("fusion.kidnap_min_separation_mm",
                      AGV_AT(fusion.recovery.kidnap_min_separation_mm), 0.0, 100000.0, 300.0,
                      {"mm",
                       "agreeing fixes closer than this count once (same landmark seen "
                       "again, e.g. one misprint). Larger protects better; the vehicle "
                       "must move to recover"}));
  k->push_back(ms_as_ns("fusion.kidnap_min_duration_ms",
                        AGV_AT(fusion.recovery.kidnap_min_duration_ns), 0.0, 600000.0, 3000.0,
                        "the agreeing fixes must span this long, so a transient disagreement "
                        "(camera clock glitch, burst of misreads) cannot move a healthy pose; "
                        "longer delays recovering a carried vehicle"));
  k->push_back(boolean("fusion.relocalize_from_single_fix",
                       AGV_AT(fusion.recovery.relocalize_from_single_fix), true,
                       "when lost (σ above the limits) one map-verified fix re-initialises the "
                       "pose; false: only the kidnap rule"));
  k->push_back(number("fusion.relocalize_max_fix_sigma_mm",
                      AGV_AT(fusion.recovery.relocalize_max_fix_sigma_mm), 0.001, 1000.0, 2.0,
                      {"mm", "the largest vision position σ such a fix may have"}));
  k->push_back(deg_as_rad("fusion.relocalize_max_fix_sigma_deg",
                          AGV_AT(fusion.recovery.relocalize_max_fix_sigma_rad), 0.001, 90.0, 0.5,
                          {"deg", "the largest vision heading σ such a fix may have"}));
  k->push_back(deg_as_rad("fusion.unseen_slip_max_deg", AGV_AT(fusion.recovery.unseen_slip_max_rad),
                          0.0, 90.0, 20.0,
                          {"deg",
                           "a fix whose payload the map confirmed, gate-rejected with a heading "
                           "change up to this that one turn at a point of the path driven "
                           "since the last fix explains (position too), is fused as a slip the "
                           "wheels did not show (docs/design/fusion.md \"Slips the wheels did "
                           "not show\"). 0: off (such a fix waits for kidnap_fixes). Larger: "
                           "larger unseen turns recover at the next landmark; a landmark's map "
                           "error is more often taken for one"}));
}

// Health (HealthConfig; the odometry timeout is can.odometry.timeout_ms).
void add_fusion_health(std::vector<Key>* k) {
  k->push_back(ms_as_ns("fusion.localized_timeout_ms", AGV_AT(fusion.health.localized_timeout_ns),
                        10.0, 600000.0, 2000.0,
                        "localized while the last fused fix is at most this old, dead "
                        "reckoning afterwards (a 1 m grid at 1 m/s gives a fix every ~1 s)"));
  k->push_back(number("fusion.lost_position_sigma_mm", AGV_AT(fusion.health.lost_position_sigma_mm),
                      0.1, 10000.0, 50.0, {"mm", "lost when the position σ exceeds this"}));
  k->push_back(deg_as_rad("fusion.lost_heading_sigma_deg",
                          AGV_AT(fusion.health.lost_heading_sigma_rad), 0.01, 180.0, 3.0,
                          {"deg", "lost when the heading σ exceeds this"}));
}

}  // namespace

void add_fusion_keys(std::vector<Key>* keys) {
  add_fusion_odometry(keys);
  add_fusion_odometry_timing(keys);
  add_fusion_core(keys);
  add_fusion_gyro(keys);
  add_fusion_slip(keys);
  add_fusion_fix(keys);
  add_fusion_range_bearing(keys);
  add_fusion_recovery(keys);
  add_fusion_health(keys);
}

}  // namespace agv::config::detail
