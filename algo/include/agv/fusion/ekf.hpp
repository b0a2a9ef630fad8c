// Fusion EKF: wheel odometry (v, omega) and landmark fixes (world pose of the vehicle) into a
// pose at any requested time, with delayed fixes, chi-square gating, kidnap recovery and health.
// Model: paper 000 eq. 14-19 (state x, y, theta, v, omega); details and measured accuracy in
// docs/design/fusion.md. Conventions: docs/design/frames.md (mm, rad wrapped to (-pi, pi], ns).
//
// Real-time use: construct once (all memory is allocated in the constructor); afterwards
// add_odometry, add_fix, estimate_at and take_flags never allocate. Not thread-safe: call from
// one thread (the fusion/output loop) or guard externally.
#pragma once

#include <Eigen/Core>
#include <array>
#include <cstddef>
#include <cstdint>
#include <limits>
#include <string>
#include <vector>

#include "agv/common/geometry.hpp"
#include "agv/common/track_width.hpp"
#include "agv/fusion/motion_model.hpp"

namespace agv::fusion {

// The filter state is the paper's (x, y, theta, v, omega) followed by four odometry
// calibration states (docs/design/fusion.md, "Odometry calibration"):
//   odometry v     = (1 + s_v) v
//   odometry omega = (1 + s_omega) omega + b_omega + c_omega_v v
// s_v: speed scale error (mean wheel radius); s_omega: yaw-rate scale error (track width);
// b_omega: yaw-rate bias (gyro); c_omega_v: yaw rate per speed (left/right wheel radius
// mismatch makes a straight run curve), rad/m.
inline constexpr int kIsv = 5;
inline constexpr int kIsomega = 6;
inline constexpr int kIbomega = 7;
inline constexpr int kIcomegav = 8;
// Gyro calibration (docs/design/fusion.md, "Gyro"): gyro = (1 + s_g) omega + b_g.
inline constexpr int kIbg = 9;
inline constexpr int kIsg = 10;
inline constexpr int kFilterDim = 11;
using FilterVec = Eigen::Matrix<double, kFilterDim, 1>;
using FilterCov = Eigen::Matrix<double, kFilterDim, kFilterDim>;

struct EkfConfig {
  // ---- Process noise (added per prediction step; all are white-noise densities) ----
  // Random walk of the speed (m/s^2 per sqrt(s)) when predicting past the newest odometry
  // sample, within odom_gap_ns of it (each sample replaces v and omega with their covariance;
  // beyond odom_gap_ns the gap model below applies): 0.11 m/s after 50 ms. Larger: the pose
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

  // ---- Odometry calibration ----
  // Estimate s_v, s_omega, b_omega and c_omega_v from the fixes. A 1 % scale error alone is 5 mm at
  // the midpoint of a 1 m landmark spacing and a 0.5 deg/s yaw-rate bias another ~1-3 mm; learning
  // them (a few landmarks suffice) removes most of that. false: the plain 5-state filter of
  // paper 000 (the calibration states stay exactly 0); set it with use_uncalibrated_noise(),
  // whose process noise covers the uncalibrated errors.
  bool estimate_odometry_calibration = true;
  // Prior sigmas of the calibration (what a new or re-tyred vehicle may be off by).
  double init_v_scale_sigma = 0.03;
  double init_omega_scale_sigma = 0.03;
  double init_omega_bias_sigma_radps = deg_to_rad(1.5);
  double init_omega_per_v_sigma_radpm = deg_to_rad(1.5);  // 1.5 deg per metre
  // Random walk of the calibration (tyre wear, load, temperature), per sqrt(s). Larger tracks
  // changes faster but lets the calibration absorb noise of individual fixes and widens the
  // heading gate. The wheels' yaw-rate bias walks slowly (wheel wear, load); a drifting gyro has
  // its own bias state (gyro_bias_sigma_radps_per_sqrt_s).
  double v_scale_sigma_per_sqrt_s = 1e-4;
  double omega_scale_sigma_per_sqrt_s = 1e-4;
  double omega_bias_sigma_radps_per_sqrt_s = deg_to_rad(0.004);
  double omega_per_v_sigma_radpm_per_sqrt_s = deg_to_rad(0.005);

  // ---- Odometry sample noise (the samples drive the motion; docs/design/fusion.md, "Model") ----
  // Noise of one sample: the pose sigma grows by it per period (0.005 m/s over 10 ms = 0.05 mm,
  // a random walk). A real encoder's tick quantisation is about 0.0015 m/s per 10 ms; the
  // simulator's noise is 0.002 m/s. Larger: sigma overstates the error between landmarks.
  double odom_v_sigma_mps = 0.005;
  double odom_omega_sigma_radps = deg_to_rad(0.2);
  // Plausibility limits: samples beyond them are rejected as invalid input.
  double max_abs_v_mps = 5.0;
  double max_abs_omega_radps = 10.0;

  // ---- Odometry timing and gaps (docs/design/fusion.md, "Odometry gaps") ----
  // What one odometry sample means. kPeriodMean: the mean speed over the odom_period_ns ending at
  // its stamp (encoder ticks per period, what most motor controllers send); kInstant: the speed
  // at its stamp (a controller that reports its speed loop's current value). A filter set for the
  // wrong one turns every yaw-rate step into a heading error of up to omega * period.
  enum class OdomSampleTiming : std::uint8_t { kPeriodMean, kInstant };
  OdomSampleTiming odom_sample_timing = OdomSampleTiming::kPeriodMean;
  // Nominal sample period of the odometry source. With kPeriodMean the first sample after a gap
  // covers only this much time (it measures the speed now, not the mean over the gap).
  std::int64_t odom_period_ns = 10'000'000;
  // Samples further apart than this are a gap: the motion after the previous sample is known
  // (its speed holds) for odom_gap_ns and unknown after that (below). Larger tolerates more
  // jitter of the source before the covariance grows; smaller notices a stall sooner.
  std::int64_t odom_gap_ns = 50'000'000;
  // Unknown motion: the speed random-walks with this acceleration density (m/s^2 per sqrt(s))
  // and the yaw rate may change by gap_yaw_rate_change_sigma_radps at once (arcs start and end
  // within one sample) and random-walks with gap_yaw_accel_sigma_radps2. Half the vehicle's
  // acceleration limits keeps 3 sigma above braking at the full limit for gaps up to 3 s, and
  // 3 x 0.8 rad/s covers an arc of 2 rad/s (0.5 m radius at 1 m/s) starting or ending anywhere
  // in the gap, with 20 % to spare. Too small: fixes after a gap are gated although right; too
  // large: the pose goes lost after shorter gaps (heading sigma 0.8 rad/s x (gap - odom_gap_ns)).
  // A gyro that covers the gap replaces the yaw-rate terms.
  double gap_accel_sigma_mps2 = 0.5;
  double gap_yaw_accel_sigma_radps2 = 1.0;
  double gap_yaw_rate_change_sigma_radps = 0.8;

  // ---- Fixes ----
  // The reported fix covariance is used as R = fix_cov_scale * R_reported + diag(floor^2).
  // The floor models what the vision stage cannot know (landmark placement and map survey
  // error, camera mounting); scale > 1 distrusts an optimistic vision covariance.
  double fix_cov_scale = 1.0;
  double fix_floor_sigma_mm = 0.1;
  double fix_floor_sigma_rad = deg_to_rad(0.01);
  // Probability of the chi-square(3) gate on the fix innovation. 0.999 gives 16.27; higher
  // accepts more true fixes after poor dead reckoning but lets larger misreads through.
  double gate_probability = 0.999;
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
  // Initial uncertainty of v and omega when initialising from a fix.
  double init_v_sigma_mps = 0.1;
  double init_omega_sigma_radps = 0.1;

  // ---- Delayed fixes ----
  // Events (odometry samples, fused fixes) kept for re-propagation. Must exceed the odometry rate
  // times max_fix_delay_ns plus the fixes in that time: 256 covers 1.5 s at 100 Hz odometry and
  // 30 Hz fixes. Memory: ~0.85 kB per event, allocated once.
  std::size_t history_capacity = 256;
  // Fixes whose exposure time is older than the newest event by more than this are rejected as
  // too old (counted). Also rejected: anything older than the oldest event kept.
  std::int64_t max_fix_delay_ns = 500'000'000;
  // Fixes stamped further than this after the newest odometry are held (odometry is late or in
  // a gap) and fused when a newer odometry sample arrives; a held fix still more than this ahead
  // of that sample is rejected as invalid (the camera clock is ahead). held_fix_capacity bounds
  // the hold; when full the oldest held fix is dropped (counted).
  std::int64_t max_fix_lead_ns = 200'000'000;
  std::size_t held_fix_capacity = 8;

  // ---- Gyro (docs/design/fusion.md, "Gyro"; inputs through add_gyro) ----
  // Each gyro sample is the mean yaw rate over the interval since the previous sample (what a
  // gyro's digital low-pass and an integrating read-out give). Where the samples cover an
  // odometry period, the gyro carries the heading and the wheels only the speed.
  // White rate noise (angle random walk), rad/s per sqrt(Hz): the heading sigma grows by it times
  // sqrt(t). 0.01 deg/s/sqrt(Hz) is a typical industrial MEMS part (BMI088, ADIS16460 are
  // 0.004-0.014). Too small: fixes after long legs fail the gate; too large: sigma overstates.
  double gyro_noise_density_radps_per_sqrt_hz = deg_to_rad(0.01);
  // Prior sigma of the gyro bias left after imu.bias_degps (turn-on bias of a MEMS part: a few
  // tenths of a deg/s) and its random walk per sqrt(s) (bias instability and temperature drift).
  // The bias is learned from fixes and while standing still. Larger walk: follows a drifting
  // bias faster, sigma between landmarks grows faster.
  double init_gyro_bias_sigma_radps = deg_to_rad(0.5);
  double gyro_bias_sigma_radps_per_sqrt_s = deg_to_rad(0.002);
  // Prior sigma of the gyro scale error and its random walk per sqrt(s). Learned from the
  // heading change over turns between fixes.
  double init_gyro_scale_sigma = 0.01;
  double gyro_scale_sigma_per_sqrt_s = 1e-5;
  // Samples at or beyond this magnitude are saturated (the sensor's range clips them) and not
  // used; the periods they touch fall back to the wheels. Set just below the configured range.
  double gyro_saturation_radps = deg_to_rad(245.0);
  // Consecutive samples further apart than this leave a hole: periods across it use the wheels.
  std::int64_t gyro_gap_ns = 25'000'000;
  // Gyro samples kept (time-ordered ring) for re-propagation after delayed fixes. Must cover
  // the event history's span (history_capacity odometry periods) at the gyro rate: 1024 is 5 s
  // at 200 Hz. Memory 16 bytes a sample, allocated once.
  std::size_t gyro_capacity = 1024;
  // Wheel slip: the wheels' yaw rate (after the wheel calibration) differs from the gyro's by
  // more than slip_yaw_rate_radps + slip_yaw_rate_fraction * |omega| in a period. The speed of
  // that period is then corrected by the slip's speed error (|difference| * wheel_track_mm / 2:
  // down while driving, a spinning wheel; up while braking, a locked one) and keeps half of it
  // as its sigma; flagged and counted. Smaller catches smaller slips and
  // misfires on an uncalibrated track width in turns (3 % scale = 0.06 rad/s at 2 rad/s).
  double slip_yaw_rate_radps = deg_to_rad(3.0);
  double slip_yaw_rate_fraction = 0.1;
  // The drive wheels' track, the slip's lever arm: key can.odometry.track_width_mm, the same value
  // the CAN decoding converts wheel speeds with.
  double wheel_track_mm = kDefaultTrackWidthMm;
  // A disagreement that lasts longer than this is no slip but a doubtful gyro (time stamps off,
  // a failing sensor): the heading then also takes the disagreement as uncertainty.
  std::int64_t slip_max_duration_ns = 500'000'000;
  // Below the slip threshold: the wheels' yaw rate is a measurement of their calibration
  // (s_omega, b_omega, c_omega_v) given the gyro's rate, fused into those states only, with the
  // odometry yaw-rate noise. A difference within slip_noise_sigmas of what that noise and the
  // calibration's uncertainty explain teaches the calibration; a larger one is a slip (one wheel
  // off by e: yaw rate e / track, speed e / 2): the speed is corrected by its speed equivalent,
  // spin or lock as the speed reading's step says, with the rest of the doubt as speed sigma,
  // correlated over a run of such periods (a slip's speed error adds up, it does not average
  // out). A 5 % slip of the outer wheel in a 2 rad/s arc (8.6 deg/s, under the 14.5 deg/s slip
  // threshold) is then corrected instead of gating the next fixes. Larger: fewer small slips are
  // corrected; smaller: sample noise is taken for slips more often (each costs a little sigma).
  double slip_noise_sigmas = 3.0;
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
  // slip_max_duration_ns. While held it is read as the mean of "less the step" and "the other
  // wheel plus their difference at the onset"; half their difference is yaw-rate doubt that the
  // heading sigma adds up, with slip_hold_sigma_fraction of the held step's yaw rate as a floor
  // (docs/design/fusion.md "Wheel slip without a gyro"). A turn into or out of an arc steps both
  // wheels, an acceleration moves both within the limit: neither starts a hold. Larger
  // wheel_step_min_mps: smaller slips go unheld (a 25 % slip at 1 m/s steps 0.25 m/s); smaller:
  // encoder quantisation starts holds (keep it above one encoder count per odometry period).
  double wheel_step_min_mps = 0.05;
  double slip_hold_sigma_fraction = 0.1;
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
  // Standstill: wheels below these (|v|, |omega|) over a period mean the vehicle does not turn;
  // the gyro's reading is then its bias (zero-rate update, sigma standstill_omega_sigma_radps).
  double standstill_v_mps = 0.005;
  double standstill_omega_radps = deg_to_rad(0.5);
  double standstill_omega_sigma_radps = deg_to_rad(0.01);

  // ---- Health ----
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

// The plain 5-state filter: no calibration states, so the process noise has to cover the
// odometry's systematic errors itself (1 % scale error = 10 mm after 1 m = 2 sigma): along /
// across 5 / 2 mm per sqrt(m), heading 0.1 deg per sqrt(m) and 0.3 deg per sqrt(s).
inline void use_uncalibrated_noise(EkfConfig* c) {
  c->estimate_odometry_calibration = false;
  c->along_track_sigma_mm_per_sqrt_m = 5.0;
  c->cross_track_sigma_mm_per_sqrt_m = 2.0;
  c->heading_sigma_rad_per_sqrt_m = deg_to_rad(0.1);
  c->heading_drift_sigma_rad_per_sqrt_s = deg_to_rad(0.3);
}

// Empty string when the configuration is usable, otherwise what is wrong.
std::string validate(const EkfConfig& config);

enum class HealthState : std::uint8_t {
  kUninitialized = 0,
  kLocalized = 1,
  kDeadReckoning = 2,
  kLost = 3
};
const char* to_string(HealthState h);

// Bit flags for the CAN status frame.
namespace flags {
inline constexpr std::uint16_t kFusedOdom = 1u << 0;
inline constexpr std::uint16_t kFusedFix = 1u << 1;
inline constexpr std::uint16_t kRejectedGate = 1u << 2;
inline constexpr std::uint16_t kRejectedTooOld = 1u << 3;
inline constexpr std::uint16_t kReinitialised = 1u << 4;
inline constexpr std::uint16_t kOdomTimeout = 1u << 5;      // status at the queried time
inline constexpr std::uint16_t kCovarianceLimit = 1u << 6;  // status at the queried time
inline constexpr std::uint16_t kInvalidInput = 1u << 7;     // odometry or fix rejected as bad
inline constexpr std::uint16_t kInitialised = 1u << 8;      // first fix initialised the filter
inline constexpr std::uint16_t kDelayedFix = 1u << 9;       // a fix was fused behind newer data
inline constexpr std::uint16_t kOdomGap = 1u
                                          << 10;  // odometry resumed after a gap (unknown motion)
inline constexpr std::uint16_t kWheelSlip = 1u << 11;    // slip: wheels vs gyro, or one wheel held
inline constexpr std::uint16_t kGyroInvalid = 1u << 12;  // a gyro sample was rejected
}  // namespace flags

struct PoseEstimate {
  bool valid = false;  // false until the first fix initialised the filter
  std::int64_t t_ns = 0;
  Pose2 pose;
  double v_mps = 0.0;
  double omega_radps = 0.0;
  StateCov cov = StateCov::Zero();  // order x_mm, y_mm, theta_rad, v_mps, omega_radps
  HealthState health = HealthState::kUninitialized;
  std::int64_t time_since_fix_ns = -1;  // -1 when no fix has been fused
  std::uint16_t flags = 0;         // pending event flags (see take_flags) | status flags at t_ns
  double position_sigma_mm = 0.0;  // sqrt(largest eigenvalue of the xy covariance)
  double heading_sigma_rad = 0.0;
  // Estimated odometry calibration (0 when EkfConfig::estimate_odometry_calibration is false).
  double odom_v_scale_error = 0.0;
  double odom_omega_scale_error = 0.0;
  double odom_omega_bias_radps = 0.0;
  double odom_omega_per_v_radpm = 0.0;
  // Estimated gyro calibration and whether the gyro carried the heading of the newest period.
  double gyro_bias_radps = 0.0;
  double gyro_scale_error = 0.0;
  bool gyro_heading = false;
};

enum class FixOutcome {
  kFused,
  kInitialised,
  kRejectedGate,
  kRejectedTooOld,
  kRejectedInvalid,
  kReinitialised,
  kHeld,  // ahead of the newest odometry: kept and fused when odometry catches up
  // A map-guided fix (its identity came from the prediction itself) while the filter is
  // uninitialised or lost: it cannot confirm the pose that chose it (docs/design/map_identity.md).
  kRejectedNotTracking,
};
const char* to_string(FixOutcome o);

class Ekf {
 public:
  // Throws std::invalid_argument when validate(config) is not empty.
  explicit Ekf(const EkfConfig& config);

  // Odometry sample stamped t_ns (strictly increasing): the mean forward speed and yaw rate
  // over the period ending at t_ns (as encoder tick counts give them). Fuses (v, omega) and
  // predicts from the previous event to t_ns with them. Before initialisation the sample is only
  // stored (it is replayed after a fix initialises the filter at an earlier time). Returns false,
  // counts and flags, and leaves the state untouched for non-finite or implausible values and
  // non-increasing time.
  bool add_odometry(std::int64_t t_ns, double v_mps, double omega_radps);

  // Gyro yaw-rate sample (rad/s, counter-clockwise positive) stamped t_ns on the odometry's clock
  // (strictly increasing). The gyro then carries the heading over every odometry period it
  // covers (docs/design/fusion.md, "Gyro"); the wheels keep the speed. Returns false, counts and
  // flags for non-finite values, samples at or beyond gyro_saturation_radps, non-increasing time,
  // or a stamp more than max_gyro_lead_ns ahead of the newest odometry.
  bool add_gyro(std::int64_t t_ns, double gyro_z_radps);

  // Landmark fix: world pose of the vehicle at exposure time t_exposure_ns with covariance R of
  // (x_mm, y_mm, theta_rad). May be older than the newest odometry (delayed): it is fused at
  // its own time and later events are re-propagated.
  // map_verified: the landmark's pose was checked against (or taken from) the survey map, so a
  // misprinted code cannot be the source; only such fixes may re-localise a lost filter alone.
  // map_guided: the landmark was identified from this filter's own prediction (QR unreadable):
  // fused only through the normal gate of an initialised, not lost filter; never initialises,
  // re-localises or counts towards a kidnap (else kRejectedNotTracking / kRejectedGate).
  FixOutcome add_fix(std::int64_t t_exposure_ns, const Pose2& z_world, const Eigen::Matrix3d& R,
                     bool map_verified = false, bool map_guided = false);
  // An external pose (the VDA 5050 initPosition action, docs/guide/vda5050.md): re-initialises the
  // filter at t_ns to z_world with position/heading covariance R, keeping speed and calibration;
  // uninitialised, it initialises as from a first fix. No gate: the operator overrides the
  // filter. False (state untouched) for a non-finite pose or R not positive definite.
  bool set_pose(std::int64_t t_ns, const Pose2& z_world, const Eigen::Matrix3d& R);

  // Estimate predicted (or, inside the history, interpolated by prediction from the last event
  // at or before t_ns) to t_ns; does not change the filter. valid only once initialised and when
  // t_ns is not older than the oldest state kept.
  PoseEstimate estimate_at(std::int64_t t_ns) const;

  struct Counters {
    std::uint64_t odom_fused = 0;
    std::uint64_t odom_stored_uninitialised = 0;  // accepted before the first fix
    std::uint64_t odom_rejected_invalid = 0;      // NaN/inf or beyond the plausibility limits
    std::uint64_t odom_rejected_time = 0;         // time not after the previous sample
    std::uint64_t fixes_fused = 0;
    std::uint64_t fixes_delayed = 0;  // of fixes_fused: fused behind newer events
    std::uint64_t fixes_initialised = 0;
    std::uint64_t fixes_rejected_gate = 0;
    std::uint64_t fixes_rejected_too_old = 0;
    std::uint64_t fixes_rejected_invalid = 0;
    std::uint64_t reinitialisations = 0;
    std::uint64_t events_replayed = 0;     // re-propagation steps done for delayed data
    std::uint64_t history_overwrites = 0;  // oldest events dropped because the buffer was full
    std::uint64_t odom_gaps = 0;           // samples that ended a gap (odom_gap_ns)
    std::uint64_t fixes_held = 0;          // ahead of the odometry when they came
    std::uint64_t fixes_held_dropped = 0;  // pushed out of the full hold
    std::uint64_t relocalisations = 0;     // of reinitialisations: from a single fix when lost
    std::uint64_t fixes_rejected_not_tracking = 0;  // map-guided while uninitialised or lost
    std::uint64_t gyro_accepted = 0;
    std::uint64_t gyro_rejected_invalid = 0;    // non-finite
    std::uint64_t gyro_rejected_saturated = 0;  // at or beyond gyro_saturation_radps
    std::uint64_t gyro_rejected_time = 0;       // not after the previous sample
    std::uint64_t slip_periods = 0;        // odometry periods the wheels disagreed with the gyro
    std::uint64_t slip_events = 0;         // of them: the first of a run
    std::uint64_t standstill_updates = 0;  // zero-rate updates of the gyro bias
    std::uint64_t unseen_slips = 0;  // gate-rejected fixes explained by an unseen heading change
  };
  const Counters& counters() const { return counters_; }

  // Event flags accumulated since the previous call; clears them.
  std::uint16_t take_flags();

  bool initialised() const { return initialised_; }
  // Gate threshold computed from gate_probability (chi-square, 3 dof).
  double gate_threshold() const { return gate_threshold_; }
  // Mahalanobis distance^2 of the most recent fix against its prior (NaN before any gated fix).
  double last_fix_mahalanobis_sq() const { return last_fix_d2_; }
  const EkfConfig& config() const { return config_; }

 private:
  static constexpr std::int64_t kNoOdom = INT64_MIN;
  enum class EventKind : std::uint8_t { kOdom, kFix, kInit };
  // A run of odometry periods whose wheel/gyro yaw-rate difference is a slip under the flag
  // threshold (slip_noise_sigmas): what it may have integrated and which way it went.
  struct SlipRun {
    double sigma_m = 0.0;  // speed-error sigma integrated since the run began or the last fix
    double llr = 0.0;      // log likelihood ratio spin : lock from the speed reading's steps
    double u_mps = 0.0;    // speed equivalent of the difference in the run's newest period
  };
  // Wheels only: a wheel whose reading stepped beyond the vehicle's limits (a slip), read less
  // the step until it steps back (EkfConfig::wheel_step_min_mps).
  struct WheelHold {
    int wheel = -1;           // -1 none, 0 left, 1 right
    double offset_mps = 0.0;  // the step, taken off the wheel's readings while held
    std::int64_t since_ns = INT64_MIN;
    double sigma_rad = 0.0;  // heading sigma the hold has added so far
    // Held wheel less the step, minus the other wheel, at the onset; and its change since
    // (what the slip's size or the yaw rate changed by while held: which, the wheels cannot say).
    double diff0_mps = 0.0;
    double drift_mps = 0.0;
    // After a hold ended by the wheel stepping back: that period's time, wheel and step. A slip
    // that ends inside a period steps back over two; the second step is not a new slip.
    std::int64_t released_ns = INT64_MIN;
    int released_wheel = -1;
    double released_step_mps = 0.0;
    // Both wheels' steps in this period (a slip that began inside the previous period showed
    // part of itself there, under the limit).
    double step_mps[2] = {0.0, 0.0};
  };
  struct Event {
    std::int64_t t_ns = 0;
    EventKind kind = EventKind::kOdom;
    double v_mps = 0.0, omega_radps = 0.0;            // odometry input
    Eigen::Vector3d z = Eigen::Vector3d::Zero();      // fix (x_mm, y_mm, theta_rad)
    Eigen::Matrix3d R = Eigen::Matrix3d::Identity();  // effective fix covariance
    bool valid = false;  // state below is meaningful (filter initialised at this time)
    bool gyro = false;   // the period ending here took its heading from the gyro
    bool slip = false;   // the wheels disagreed with the gyro in that period
    std::int64_t slip_since_ns = kNoOdom;  // start of the current run of slip periods
    // The current run of wheel/gyro differences beyond slip_noise_sigmas (kept over a fix).
    SlipRun slip_run;
    // Newest raw odometry speed at or before this event (NaN: none since the initialisation).
    double v_read_mps = std::numeric_limits<double>::quiet_NaN();
    double omega_read_radps = std::numeric_limits<double>::quiet_NaN();  // the same, yaw rate
    WheelHold hold;  // wheels only: the slipping wheel held at this event
    // Newest odometry sample at or before this event (kNoOdom: none kept): where the known
    // motion ends (odom_gap_ns after it).
    std::int64_t odom_t_ns = kNoOdom;
    FilterVec x = FilterVec::Zero();  // posterior after this event
    FilterCov P = FilterCov::Zero();
  };
  // Candidate track of consecutive gate-rejected fixes (kidnap detection).
  struct Hypothesis {
    int count = 0;
    std::int64_t t_first_ns = 0;  // time of the fix that started the candidate
    std::int64_t t_ns = 0;        // time of the newest fix fused into the candidate
    double x_count_mm = 0.0;      // position of the newest fix that incremented count
    double y_count_mm = 0.0;
    FilterVec x = FilterVec::Zero();
    FilterCov P = FilterCov::Zero();
  };

  struct HeldFix {
    std::int64_t t_ns = 0;
    Pose2 z;
    Eigen::Matrix3d R = Eigen::Matrix3d::Identity();  // as given (before scale and floor)
    bool map_verified = false;
    bool map_guided = false;
  };

  // What a fix event takes over from the event before it (slip state, newest readings).
  static void carry_over_fix(const Event& prev, Event* fix);
  // Ring buffer access in time order: 0 = oldest.
  Event& at(std::size_t i) { return history_[(head_ + i) % history_.size()]; }
  const Event& at(std::size_t i) const { return history_[(head_ + i) % history_.size()]; }
  // Index of the last event with t <= t_ns, or -1.
  long find_last_at_or_before(std::int64_t t_ns) const;
  // Appends then moves the event back to its time-ordered place; returns its index.
  std::size_t insert_event(const Event& ev);
  // Recomputes the posteriors of events from index `from` to the newest.
  void replay_from(std::size_t from);
  void process_event(const Event& prev, Event* ev) const;

  // x, P over dt_s with the motion model (eq. 15-16); velocity_noise adds the random walk of v
  // and omega over dt_s (off when an odometry sample for the period is fused just before).
  // gyro_heading: the yaw rate came from the gyro, whose noise and calibration states carry the
  // heading uncertainty (no wheel heading noise).
  void predict(FilterVec* x, FilterCov* P, double dt_s, bool velocity_noise = true,
               bool gyro_heading = false) const;
  void add_velocity_noise(FilterCov* P, double dt_s) const;
  void update_odometry(FilterVec* x, FilterCov* P, double v_mps, double omega_radps) const;
  // Odometry step (period-mean sample): fuse the sample, then predict over the period it covers.
  void propagate_odometry(FilterVec* x, FilterCov* P, double dt_s, double v_mps,
                          double omega_radps) const;
  // Prediction over [t0, t1] inside a known odometry period: the gyro's rate where it covers
  // the span, the period's yaw rate otherwise.
  void predict_known(FilterVec* x, FilterCov* P, std::int64_t t0_ns, std::int64_t t1_ns) const;
  // Prediction from t0_ns to t1_ns when the newest odometry is at odom_t_ns: the known motion
  // (predict()) up to odom_t_ns + odom_gap_ns, the unknown-motion model after it.
  void predict_span(FilterVec* x, FilterCov* P, std::int64_t t0_ns, std::int64_t t1_ns,
                    std::int64_t odom_t_ns) const;
  // Applies an odometry sample at t_ns to the posterior of the previous event at t_prev_ns.
  // prev: the event before (its slip run), out: gyro use and slip of this period (optional).
  void apply_odometry(FilterVec* x, FilterCov* P, std::int64_t t_prev_ns, std::int64_t odom_t_ns,
                      std::int64_t t_ns, double v_mps, double omega_radps,
                      const Event* prev = nullptr, Event* out = nullptr) const;
  // Wheels only: the hold after this period's readings (EkfConfig::wheel_step_min_mps); sets the
  // readings to use and the heading variance the hold adds in this period.
  WheelHold hold_wheel(const Event& prev, std::int64_t t_ns, double dt_s, double v_mps,
                       double omega_radps, double* v_use_mps, double* omega_use_radps,
                       double* add_theta_var) const;
  // Mean gyro rate over (t0_ns, t1_ns] when the kept samples cover it completely.
  bool gyro_mean(std::int64_t t0_ns, std::int64_t t1_ns, double* mean_radps) const;
  // The same, holding the newest sample's rate up to gyro_gap_ns past it (output ticks between
  // samples during an odometry gap).
  bool gyro_mean_hold(std::int64_t t0_ns, std::int64_t t1_ns, double* mean_radps) const;
  // Sets omega from a gyro mean over dt_s (the gyro calibration states, the rate noise).
  void set_gyro_rate(FilterVec* x, FilterCov* P, double gyro_radps, double dt_s) const;
  // Speed-only odometry update (the gyro has the yaw rate); extra_v_var for a slip.
  void update_speed(FilterVec* x, FilterCov* P, double v_mps, double extra_v_var) const;
  // Zero-rate pseudo-measurement omega = 0 (standing still): teaches the gyro bias.
  void update_zero_rate(FilterVec* x, FilterCov* P) const;
  // The odometry step of a period whose yaw the gyro covers; returns whether wheels slipped.
  // v_read_prev_mps: the previous raw speed reading (NaN: none); run: the sub-threshold slip run
  // so far, updated for this period.
  bool gyro_period(FilterVec* x, FilterCov* P, double dt_s, double v_mps, double omega_radps,
                   double gyro_radps, bool distrust_gyro, double v_read_prev_mps,
                   SlipRun* run) const;
  // Fuses the wheels' yaw rate into their calibration states only (the gyro keeps the heading);
  // returns the wheels' yaw rate minus the gyro's, rad/s, and its sigma from the sample noise
  // and the calibration's uncertainty.
  double learn_wheel_yaw(FilterVec* x, FilterCov* P, double v_mps, double omega_radps, bool learn,
                         double* sigma_radps) const;
  bool is_gap(std::int64_t odom_t_ns, std::int64_t t_ns) const {
    return odom_t_ns == kNoOdom || t_ns - odom_t_ns > config_.odom_gap_ns;
  }
  static std::int64_t odom_time_after(const Event& ev) {
    return ev.kind == EventKind::kOdom ? ev.t_ns : ev.odom_t_ns;
  }
  // Newest odometry time at or before history index i (exclusive of i itself).
  std::int64_t odom_time_before(std::size_t i) const {
    return i == 0 ? kNoOdom : odom_time_after(at(i - 1));
  }
  FixOutcome fuse_fix(std::int64_t t_ns, const Pose2& z_world, const Eigen::Matrix3d& R_in,
                      bool map_verified, bool map_guided, bool from_hold);
  void hold_fix(std::int64_t t_ns, const Pose2& z_world, const Eigen::Matrix3d& R_in,
                bool map_verified, bool map_guided);
  // Fuses held fixes older than t_ns (before the odometry sample at t_ns is inserted).
  void release_held_before(std::int64_t t_ns);
  // After odometry at t_ns: fuses held fixes within max_fix_lead_ns, rejects those still ahead.
  void settle_held_after(std::int64_t t_ns);
  // Position or heading sigma of P beyond the lost limits; reports both sigmas when asked.
  bool prior_lost(const FilterCov& P, double* position_sigma_mm = nullptr,
                  double* heading_sigma_rad = nullptr) const;
  // Re-initialises the pose from one fix, keeping speed and calibration of the prior.
  // Raises the calibration variances (odometry when estimated, gyro bias and scale) to at least
  // their initial values: for a kidnap track, which must not inherit a rejected filter's trust.
  void widen_calibration(FilterCov* P) const;
  void relocalize(std::int64_t t_ns, const Eigen::Vector3d& z, const Eigen::Matrix3d& R,
                  const FilterVec& prior_x, const FilterCov& prior_P);
  void update_fix(FilterVec* x, FilterCov* P, const Eigen::Vector3d& z,
                  const Eigen::Matrix3d& R) const;
  // Innovation (angle wrapped) and its Mahalanobis distance^2.
  double mahalanobis_sq(const FilterVec& x, const FilterCov& P, const Eigen::Vector3d& z,
                        const Eigen::Matrix3d& R) const;
  // Kidnap candidate handling for a gate-rejected fix; true when it re-initialised the filter.
  // prior_worthless (position sigma beyond 4x lost_position_sigma_mm): two separate agreeing
  // fixes suffice, without kidnap_min_duration_ns.
  bool kidnap_candidate(std::int64_t t_ns, const Eigen::Vector3d& z, const Eigen::Matrix3d& R,
                        const FilterVec& prior_x, const FilterCov& prior_P, bool prior_worthless);
  // Mahalanobis distance^2 of the fix position alone against the prior position.
  double position_mahalanobis_sq(const FilterVec& x, const FilterCov& P, const Eigen::Vector3d& z,
                                 const Eigen::Matrix3d& R) const;
  void initialise_at(std::int64_t t_ns, const FilterVec& x, const FilterCov& P);
  // The path driven since the last fused fix (unseen_slip_max_rad), thinned as it fills.
  void track_odometry();
  void track_restart(std::size_t fix_index);
  // True when one heading change on that path explains the fix's innovation (z against x, P at
  // t_ns); then adds it to *P (heading, and position through the lever arm to the fix).
  bool explain_unseen_slip(std::int64_t t_ns, const Eigen::Vector3d& z, const Eigen::Matrix3d& R,
                           const FilterVec& x, FilterCov* P) const;

  EkfConfig config_;
  double gate_threshold_ = 0.0;
  double gate_threshold_2d_ = 0.0;  // same probability, position only
  std::vector<Event> history_;      // sized in the constructor, never resized
  struct TrackPoint {
    std::int64_t t_ns = 0;
    double x_mm = 0.0, y_mm = 0.0, theta_rad = 0.0, v_mps = 0.0;
  };
  static constexpr std::size_t kTrackPoints = 128;
  std::array<TrackPoint, kTrackPoints> track_{};
  std::size_t track_size_ = 0;
  std::int64_t track_spacing_ns_ = 50'000'000;  // doubles each time the track is thinned
  std::size_t head_ = 0;
  std::size_t size_ = 0;

  bool initialised_ = false;
  std::int64_t t_init_ns_ = 0;  // time of the latest (re)initialisation
  bool have_odom_ = false;
  std::int64_t last_odom_t_ns_ = 0;
  bool have_fix_ = false;
  std::int64_t last_fix_t_ns_ = 0;  // exposure time of the newest fused fix
  double last_fix_d2_;
  Hypothesis hyp_;
  std::vector<HeldFix> held_;  // time order, held_count_ used; sized in the constructor
  std::size_t held_count_ = 0;
  std::uint16_t pending_flags_ = 0;
  mutable Counters counters_;  // slip counts are taken while replaying (const steps)
  struct GyroSample {
    std::int64_t t_ns = 0;
    double rate_radps = 0.0;
  };
  std::vector<GyroSample> gyro_;  // ring, sized in the constructor
  std::size_t gyro_head_ = 0;
  std::size_t gyro_size_ = 0;
  const GyroSample& gyro_at(std::size_t i) const { return gyro_[(gyro_head_ + i) % gyro_.size()]; }
  // Index of the first kept gyro sample with t >= t_ns (gyro_size_ when none).
  std::size_t gyro_lower_bound(std::int64_t t_ns) const;
};

}  // namespace agv::fusion
