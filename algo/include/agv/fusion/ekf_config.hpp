// Configuration of the fusion EKF, one struct per part of the filter: the core (process noise,
// event history), each aid source (odometry, gyro, wheel slip, landmark fix, range-bearing), the
// recovery rules and the health limits. The key table (algo/src/config/keys_fusion.cpp) maps the
// user-facing keys (fusion.*, unchanged names) onto these fields.
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>

#include "agv/common/geometry.hpp"
#include "agv/common/track_width.hpp"

namespace agv::fusion {

// Prediction and the event history (ekf_core.cpp). Process noise is added per prediction step;
// all are white-noise densities.
struct CoreConfig {
  // Random walk of the speed (m/s^2 per sqrt(s)) when predicting past the newest odometry
  // sample, within odometry.gap_ns of it (each sample replaces v and omega with their covariance;
  // beyond it the odometry's gap model applies): 0.11 m/s after 50 ms. Larger: the pose
  // sigma grows faster between late samples and at fix times ahead of the odometry.
  double accel_sigma_mps2 = 0.5;
  // Random walk of the yaw rate (rad/s^2 per sqrt(s)); same role (0.22 rad/s after 50 ms).
  double yaw_accel_sigma_radps2 = 1.0;
  // Position error of dead reckoning per travelled distance, along and across the direction of
  // travel (vehicle frame), as sigma per sqrt(metre), beyond what the calibration states model
  // (scale errors and biases are states, with their own uncertainty): noise, slip, floor
  // unevenness. Too small: good fixes fail the gate and the reported sigma is too small; too
  // large: the gate accepts larger misreads and sigma overstates the error (the fault suite
  // checks both: 3 sigma covers >= 99 % of ticks, sigma at most 5x too large). The earlier
  // 5 / 2 mm per sqrt(m) also had to cover a 1 % scale error; with the calibration estimated that
  // made sigma ~6x too large. Without calibration states use_uncalibrated_noise() restores them.
  double along_track_sigma_mm_per_sqrt_m = 0.6;
  double cross_track_sigma_mm_per_sqrt_m = 0.3;
  // Heading error growth: with travelled distance (wheel slip), with time (gyro/odometry heading
  // drift beyond the estimated bias, rad per sqrt(s)) and with turned angle (yaw scale error
  // beyond the estimated one). Too small: fixes after long or turning stretches fail the gate.
  // Too large: heading misreads of a few degrees pass the gate. 0.15 deg/sqrt(s): lawnmower
  // between-landmark p95 4.8-6.0 mm (eval_fusion --route lawnmower, 3 seeds); 0.1 is 0.5-1 mm
  // worse there, 0.3 makes sigma 6x too large on the fault suite.
  // Re-sized for an honest sigma by `eval_fusion --honesty` (sigma against error on 5-7 s legs
  // off the grid): the old 0.05 deg/sqrt(m), 0.15 deg/sqrt(s), 0.0125 rad/sqrt(rad) made the
  // heading sigma 4x the error and the pose lost 2.5 s after a fix. None applies where the gyro
  // carries the heading.
  double heading_sigma_rad_per_sqrt_m = deg_to_rad(0.01);
  double heading_drift_sigma_rad_per_sqrt_s = deg_to_rad(0.03);
  double turn_heading_sigma_rad_per_sqrt_rad = 0.003;
  // Events (odometry samples, fused fixes) kept for re-propagation. Must exceed the odometry rate
  // times fix.max_delay_ns plus the fixes in that time: 256 covers 1.5 s at 100 Hz odometry and
  // 30 Hz fixes. Memory: ~0.85 kB per event, allocated once.
  std::size_t history_capacity = 256;
};

// Wheel odometry: the input that drives the motion, its calibration states, timing and gaps
// (aid_odometry.cpp).
struct OdometryConfig {
  // Estimate s_v, s_omega, b_omega and c_omega_v from the fixes. A 1 % scale error alone is 5 mm at
  // the midpoint of a 1 m landmark spacing and a 0.5 deg/s yaw-rate bias another ~1-3 mm; learning
  // them (a few landmarks suffice) removes most of that. false: the plain 5-state filter of
  // Yang et al. (the calibration states stay exactly 0); set it with use_uncalibrated_noise(),
  // whose process noise covers the uncalibrated errors.
  bool estimate_calibration = true;
  // Prior sigmas of the calibration (what a new or re-tyred vehicle may be off by).
  double init_v_scale_sigma = 0.03;
  double init_omega_scale_sigma = 0.03;
  double init_omega_bias_sigma_radps = deg_to_rad(1.5);
  double init_omega_per_v_sigma_radpm = deg_to_rad(1.5);  // 1.5 deg per metre
  // Random walk of the calibration (tyre wear, load, temperature), per sqrt(s). Larger tracks
  // changes faster but lets the calibration absorb noise of individual fixes and widens the
  // heading gate. The wheels' yaw-rate bias walks slowly (wheel wear, load); a drifting gyro has
  // its own bias state (gyro.bias_sigma_radps_per_sqrt_s).
  double v_scale_sigma_per_sqrt_s = 1e-4;
  double omega_scale_sigma_per_sqrt_s = 1e-4;
  double omega_bias_sigma_radps_per_sqrt_s = deg_to_rad(0.004);
  double omega_per_v_sigma_radpm_per_sqrt_s = deg_to_rad(0.005);

  // Noise of one sample: the pose sigma grows by it per period (0.005 m/s over 10 ms = 0.05 mm,
  // a random walk). A real encoder's tick quantisation is about 0.0015 m/s per 10 ms; the
  // simulator's noise is 0.002 m/s. Larger: sigma overstates the error between landmarks.
  double v_sigma_mps = 0.005;
  double omega_sigma_radps = deg_to_rad(0.2);
  // Plausibility limits: samples beyond them are rejected as invalid input.
  double max_abs_v_mps = 5.0;
  double max_abs_omega_radps = 10.0;

  // What one odometry sample means. kPeriodMean: the mean speed over the period_ns ending at
  // its stamp (encoder ticks per period, what most motor controllers send); kInstant: the speed
  // at its stamp (a controller that reports its speed loop's current value). A filter set for the
  // wrong one turns every yaw-rate step into a heading error of up to omega * period.
  enum class SampleTiming : std::uint8_t { kPeriodMean, kInstant };
  SampleTiming sample_timing = SampleTiming::kPeriodMean;
  // Nominal sample period of the odometry source. With kPeriodMean the first sample after a gap
  // covers only this much time (it measures the speed now, not the mean over the gap).
  std::int64_t period_ns = 10'000'000;
  // Samples further apart than this are a gap: the motion after the previous sample is known
  // (its speed holds) for gap_ns and unknown after that (below). Larger tolerates more
  // jitter of the source before the covariance grows; smaller notices a stall sooner.
  std::int64_t gap_ns = 50'000'000;
  // Unknown motion: the speed random-walks with this acceleration density (m/s^2 per sqrt(s))
  // and the yaw rate may change by gap_yaw_rate_change_sigma_radps at once (arcs start and end
  // within one sample) and random-walks with gap_yaw_accel_sigma_radps2. Half the vehicle's
  // acceleration limits keeps 3 sigma above braking at the full limit for gaps up to 3 s, and
  // 3 x 0.8 rad/s covers an arc of 2 rad/s (0.5 m radius at 1 m/s) starting or ending anywhere
  // in the gap, with 20 % to spare. Too small: fixes after a gap are gated although right; too
  // large: the pose goes lost after shorter gaps (heading sigma 0.8 rad/s x (gap - gap_ns)).
  // A gyro that covers the gap replaces the yaw-rate terms.
  double gap_accel_sigma_mps2 = 0.5;
  double gap_yaw_accel_sigma_radps2 = 1.0;
  double gap_yaw_rate_change_sigma_radps = 0.8;
};

// Gyro (docs/design/fusion.md, "Gyro"; inputs through add_gyro; aid_gyro.cpp).
struct GyroConfig {
  // Each gyro sample is the mean yaw rate over the interval since the previous sample (what a
  // gyro's digital low-pass and an integrating read-out give). Where the samples cover an
  // odometry period, the gyro carries the heading and the wheels only the speed.
  // White rate noise (angle random walk), rad/s per sqrt(Hz): the heading sigma grows by it times
  // sqrt(t). 0.01 deg/s/sqrt(Hz) is a typical industrial MEMS part (BMI088, ADIS16460 are
  // 0.004-0.014). Too small: fixes after long legs fail the gate; too large: sigma overstates.
  double noise_density_radps_per_sqrt_hz = deg_to_rad(0.01);
  // Prior sigma of the gyro bias left after imu.bias_degps (turn-on bias of a MEMS part: a few
  // tenths of a deg/s) and its random walk per sqrt(s) (bias instability and temperature drift).
  // The bias is learned from fixes and while standing still. Larger walk: follows a drifting
  // bias faster, sigma between landmarks grows faster.
  double init_bias_sigma_radps = deg_to_rad(0.5);
  double bias_sigma_radps_per_sqrt_s = deg_to_rad(0.002);
  // Prior sigma of the gyro scale error and its random walk per sqrt(s). Learned from the
  // heading change over turns between fixes.
  double init_scale_sigma = 0.01;
  double scale_sigma_per_sqrt_s = 1e-5;
  // Samples at or beyond this magnitude are saturated (the sensor's range clips them) and not
  // used; the periods they touch fall back to the wheels. Set just below the configured range.
  double saturation_radps = deg_to_rad(245.0);
  // Consecutive samples further apart than this leave a hole: periods across it use the wheels.
  std::int64_t gap_ns = 25'000'000;
  // Gyro samples kept (time-ordered ring) for re-propagation after delayed fixes. Must cover
  // the event history's span (core.history_capacity odometry periods) at the gyro rate: 1024 is
  // 5 s at 200 Hz. Memory 16 bytes a sample, allocated once.
  std::size_t capacity = 1024;
  // Standstill: wheels below these (|v|, |omega|) over a period mean the vehicle does not turn;
  // the gyro's reading is then its bias (zero-rate update, sigma standstill_omega_sigma_radps).
  double standstill_v_mps = 0.005;
  double standstill_omega_radps = deg_to_rad(0.5);
  double standstill_omega_sigma_radps = deg_to_rad(0.01);
};

// Wheel slip, with a gyro (wheels against gyro) and without (one wheel held); aid_wheel_slip.cpp.
struct SlipConfig {
  // Wheel slip: the wheels' yaw rate (after the wheel calibration) differs from the gyro's by
  // more than yaw_rate_radps + yaw_rate_fraction * |omega| in a period. The speed of
  // that period is then corrected by the slip's speed error (|difference| * wheel_track_mm / 2:
  // down while driving, a spinning wheel; up while braking, a locked one) and keeps half of it
  // as its sigma; flagged and counted. Smaller catches smaller slips and
  // misfires on an uncalibrated track width in turns (3 % scale = 0.06 rad/s at 2 rad/s).
  double yaw_rate_radps = deg_to_rad(3.0);
  double yaw_rate_fraction = 0.1;
  // The drive wheels' track, the slip's lever arm: key can.odometry.track_width_mm, the same value
  // the CAN decoding converts wheel speeds with.
  double wheel_track_mm = kDefaultTrackWidthMm;
  // A disagreement that lasts longer than this is no slip but a doubtful gyro (time stamps off,
  // a failing sensor): the heading then also takes the disagreement as uncertainty.
  std::int64_t max_duration_ns = 500'000'000;
  // Below the slip threshold: the wheels' yaw rate is a measurement of their calibration
  // (s_omega, b_omega, c_omega_v) given the gyro's rate, fused into those states only, with the
  // odometry yaw-rate noise. A difference within noise_sigmas of what that noise and the
  // calibration's uncertainty explain teaches the calibration; a larger one is a slip (one wheel
  // off by e: yaw rate e / track, speed e / 2): the speed is corrected by its speed equivalent,
  // spin or lock as the speed reading's step says, with the rest of the doubt as speed sigma,
  // correlated over a run of such periods (a slip's speed error adds up, it does not average
  // out). A 5 % slip of the outer wheel in a 2 rad/s arc (8.6 deg/s, under the 14.5 deg/s slip
  // threshold) is then corrected instead of gating the next fixes. Larger: fewer small slips are
  // corrected; smaller: sample noise is taken for slips more often (each costs a little sigma).
  double noise_sigmas = 3.0;
  // The vehicle's acceleration (and braking) limit: between two odometry samples the speed
  // changes by about this times the period. A speed reading that steps by more at the start of a
  // wheel/gyro disagreement tells a spinning wheel (up) from a locked one (down). Larger: the
  // sign of a slip is believed only for larger steps (more sigma, same mean for big slips).
  double max_accel_mps2 = 1.0;
  // Wheels only (no gyro): a slip shows as one wheel's speed reading stepping between two
  // periods by more than the vehicle can change a wheel's speed (max_accel_mps2 times the period)
  // plus wheel_step_min_mps, while the other wheel's reading stays within that. Such a step is not
  // the vehicle's motion (a spinning or locked wheel, a glitch): that wheel is held, flagged and
  // counted as a slip, until it steps back (over one or two periods) or for at most
  // max_duration_ns. While held it is read as the mean of "less the step" and "the other
  // wheel plus their difference at the onset"; half their difference is yaw-rate doubt that the
  // heading sigma adds up, with hold_sigma_fraction of the held step's yaw rate as a floor
  // (docs/design/fusion.md "Wheel slip without a gyro"). A turn into or out of an arc steps both
  // wheels, an acceleration moves both within the limit: neither starts a hold. Larger
  // wheel_step_min_mps: smaller slips go unheld (a 25 % slip at 1 m/s steps 0.25 m/s); smaller:
  // encoder quantisation starts holds (keep it above one encoder count per odometry period).
  double wheel_step_min_mps = 0.05;
  double hold_sigma_fraction = 0.1;
};

// Landmark fixes: effective covariance, gate, delays (aid_fix.cpp).
struct FixConfig {
  // The reported fix covariance is used as R = cov_scale * R_reported + diag(floor^2).
  // The floor models what the vision stage cannot know (landmark placement and map survey
  // error, camera mounting); scale > 1 distrusts an optimistic vision covariance.
  double cov_scale = 1.0;
  double floor_sigma_mm = 0.1;
  double floor_sigma_rad = deg_to_rad(0.01);
  // Probability of the chi-square(3) gate on the fix innovation. 0.999 gives 16.27; higher
  // accepts more true fixes after poor dead reckoning but lets larger misreads through.
  double gate_probability = 0.999;
  // Fixes whose exposure time is older than the newest event by more than this are rejected as
  // too old (counted). Also rejected: anything older than the oldest event kept.
  std::int64_t max_delay_ns = 500'000'000;
  // Fixes stamped further than this after the newest odometry are held (odometry is late or in
  // a gap) and fused when a newer odometry sample arrives; a held fix still more than this ahead
  // of that sample is rejected as invalid (the camera clock is ahead). held_capacity bounds
  // the hold; when full the oldest held fix is dropped (counted).
  std::int64_t max_lead_ns = 200'000'000;
  std::size_t held_capacity = 8;
  // Initial uncertainty of v and omega when initialising from a fix.
  double init_v_sigma_mps = 0.1;
  double init_omega_sigma_radps = 0.1;
};

// Recovery of a pose the fixes disagree with: kidnap, re-localisation, unseen slip
// (recovery.cpp).
struct RecoveryConfig {
  // Consecutive gate-rejected fixes that must agree with each other (given the odometry motion
  // between them) before the filter re-initialises ("kidnapped" vehicle). >= 2. Smaller recovers
  // faster after the vehicle was moved by hand; larger makes repeated misreads less likely to
  // hijack the pose.
  int kidnap_fixes = 3;
  // Agreeing fixes less than this far apart (mm, between the fix positions) count once towards
  // kidnap_fixes: they are most likely the same landmark seen in consecutive frames or while
  // standing on it, e.g. one misprinted landmark. A landmark is in view over ~40-120 mm of
  // travel; with landmarks 1 m apart, 300 mm means every counted fix is another landmark.
  // Larger protects better against a bad landmark; the vehicle has to move to recover.
  double kidnap_min_separation_mm = 300.0;
  // ... and the agreeing track must have lasted this long (first to last fix). A kidnap is a
  // lasting disagreement; a transient one (a camera clock glitch that stamps 2 s of frames
  // 300 ms off, which looks like a consistent 300 mm shift, or a burst of misreads) must not
  // move a healthy pose. Longer delays the recovery of a really carried vehicle (a lost one
  // re-localises from one map-verified fix without waiting).
  std::int64_t kidnap_min_duration_ns = 3'000'000'000;
  // Re-localisation from one fix: when the prior at the fix is lost (position or heading sigma
  // above the lost limits below), a single map-verified fix (its payload agreed with the map, so
  // a misprinted code cannot do it) whose own sigma is at most these re-initialises the pose
  // at once instead of waiting for kidnap_fixes separate landmarks. false: only the kidnap rule.
  bool relocalize_from_single_fix = true;
  double relocalize_max_fix_sigma_mm = 2.0;
  double relocalize_max_fix_sigma_rad = deg_to_rad(0.5);
  // Wheels only (no gyro sample since the last fix). A slip the wheels did not show (its onset
  // spread over periods, each step within the limits; a wheel on a wet patch): the heading turns by
  // some degrees the filter did not see, and the next landmark fails the gate. When a fix that
  // vouches for itself (its QR payload agreed with the map) fails the gate and its heading differs
  // from the prior's by more than 3 sigma and at most unseen_slip_max_rad, the filter tests whether
  // one heading change of that size at a point of the path driven since the last fused fix explains
  // the fix's position too (the path after it turned about it, plus the along-track error of one
  // wheel's extra distance), with a displacement the prior cannot explain (a turn right at the
  // landmark cannot be told from a heading misread of it). If one does, the heading change is added
  // to the covariance there (its own size as sigma) and the fix is fused: the pose recovers at the
  // first landmark instead of after kidnap_fixes. A misread or a wrong map entry rarely matches a
  // turn about a point of the driven path, and is refused as before. 0 turns the test off. Larger:
  // larger unseen turns are recovered; a map error of a landmark is more often taken for one.
  double unseen_slip_max_rad = deg_to_rad(20.0);
};

// Health of the estimate (health.cpp).
struct HealthConfig {
  // Localized while the last fused fix is at most this old; dead reckoning afterwards. With a
  // 1 m grid at 1 m/s a fix arrives every ~1 s (longer in turns).
  std::int64_t localized_timeout_ns = 2'000'000'000;
  // Lost when no odometry arrived for this long (odometry is expected at ~100 Hz).
  std::int64_t odom_timeout_ns = 100'000'000;
  // Lost when the position sigma (sqrt of the largest eigenvalue of the xy covariance) or the
  // heading sigma exceeds these.
  double lost_position_sigma_mm = 50.0;
  double lost_heading_sigma_rad = deg_to_rad(3.0);
};
// Range-bearing observations of landmarks seen at a distance (agv/fusion/range_bearing.hpp;
// aid_range_bearing.cpp). The observation's covariance R of (range, bearing) is used as
// R + diag(range_floor_sigma_mm^2, bearing_floor_sigma_rad^2): the floor models what the
// measurement cannot know (the landmark's survey error, the camera mount's calibration).
struct RangeBearingConfig {
  double range_floor_sigma_mm = 2.0;
  double bearing_floor_sigma_rad = deg_to_rad(0.1);
  // Probability of the chi-square(2) gate on the (range, bearing) innovation: 0.999 gives 13.8.
  // Higher accepts more true observations after poor dead reckoning, lets larger misreads and
  // map errors through.
  double gate_probability = 0.999;
  // Observations whose exposure is older than the newest event by more than this are rejected as
  // too old (as fixes: the history must still hold the state at the exposure).
  std::int64_t max_delay_ns = 500'000'000;
};

struct EkfConfig {
  CoreConfig core;
  OdometryConfig odometry;
  GyroConfig gyro;
  SlipConfig slip;
  FixConfig fix;
  RangeBearingConfig range_bearing;
  RecoveryConfig recovery;
  HealthConfig health;
  using OdomSampleTiming = OdometryConfig::SampleTiming;
};

// The plain 5-state filter: no calibration states, so the process noise has to cover the
// odometry's systematic errors itself (1 % scale error = 10 mm after 1 m = 2 sigma): along /
// across 5 / 2 mm per sqrt(m), heading 0.1 deg per sqrt(m) and 0.3 deg per sqrt(s).
inline void use_uncalibrated_noise(EkfConfig* c) {
  c->odometry.estimate_calibration = false;
  c->core.along_track_sigma_mm_per_sqrt_m = 5.0;
  c->core.cross_track_sigma_mm_per_sqrt_m = 2.0;
  c->core.heading_sigma_rad_per_sqrt_m = deg_to_rad(0.1);
  c->core.heading_drift_sigma_rad_per_sqrt_s = deg_to_rad(0.3);
}

// Empty string when the part (or the whole configuration) is usable, otherwise what is wrong.
std::string validate(const CoreConfig& c);
std::string validate(const OdometryConfig& c);
std::string validate(const GyroConfig& c);
std::string validate(const SlipConfig& c);
std::string validate(const FixConfig& c);
std::string validate(const RangeBearingConfig& c);
std::string validate(const RecoveryConfig& c);
std::string validate(const HealthConfig& c);
std::string validate(const EkfConfig& config);

}  // namespace agv::fusion
