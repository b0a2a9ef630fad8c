// Fusion EKF: wheel odometry (v, omega), a gyro, landmark fixes (world pose of the vehicle) and
// range-bearing observations of landmarks into a pose at any requested time, with delayed inputs,
// chi-square gating, kidnap recovery and health. Model: Yang et al. eq. 14-19 (state x, y, theta,
// v, omega); details and measured accuracy in docs/design/fusion.md. Conventions:
// docs/design/frames.md (mm, rad wrapped to (-pi, pi], ns).
//
// The implementation is split by aid source: the core (ekf_core.cpp: prediction, the generic
// update, the event history and its replay), aid_odometry.cpp, aid_gyro.cpp, aid_wheel_slip.cpp,
// aid_fix.cpp, aid_range_bearing.cpp, recovery.cpp (kidnap, re-localisation, unseen slip) and
// health.cpp; each part has its configuration struct in ekf_config.hpp.
//
// Real-time use: construct once (all memory is allocated in the constructor); afterwards
// add_odometry, add_gyro, add_fix, add_range_bearing, estimate_at and take_flags never allocate.
// Not thread-safe: call from one thread (the fusion/output loop) or guard externally.
#pragma once

#include <Eigen/Core>
#include <array>
#include <cstddef>
#include <cstdint>
#include <limits>
#include <string>
#include <vector>

#include "agv/common/geometry.hpp"
#include "agv/fusion/ekf_config.hpp"
#include "agv/fusion/motion_model.hpp"
#include "agv/fusion/range_bearing.hpp"
#include "agv/fusion/wheel_slip.hpp"

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
  // Estimated odometry calibration (0 when OdometryConfig::estimate_calibration is false).
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
  // flags for non-finite values, samples at or beyond GyroConfig::saturation_radps or
  // non-increasing time.
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
  // Becomes other's estimate entirely (state, covariance, history, calibration, recovery state),
  // keeping its own counters, and counts a re-initialisation: a filter whose aids were found
  // wrong takes over from a twin that never fused them (localizer's floor_check).
  void adopt_estimate(const Ekf& other);

  // Range and bearing to a surveyed landmark from a sensor on the vehicle, at exposure time
  // t_exposure_ns (aid_range_bearing.cpp): gated (chi-square, 2 dof) against the prior at that
  // time and fused there; an exposure older than the newest event is fused through the history
  // replay as a delayed fix is. Never initialises, re-localises or counts towards a kidnap:
  // kRejectedNotTracking while the filter is uninitialised. kRejectedInvalid for non-finite
  // values, a range not > 0, R not symmetric positive definite, or a landmark predicted at the
  // sensor itself; kRejectedTooOld beyond RangeBearingConfig::max_delay_ns or older than the
  // initialisation or the history.
  FixOutcome add_range_bearing(std::int64_t t_exposure_ns, const RangeBearingObs& obs);
  // What estimate_at adds to the reported covariance (x, y, heading) at t_ns, position p_mm, for
  // an unseen heading change one gated range-bearing observation fits but no second landmark has
  // confirmed yet (aid_range_bearing.cpp); zero when there is none. Never in the filter's own P.
  Eigen::Matrix3d unconfirmed_slip_cov(std::int64_t t_ns, const Eigen::Vector2d& p_mm) const;
  // What a position covariance P_xy lacks of the one the repeated shares of the range-bearing
  // observations fused since the last floor fix or (re)initialisation leave
  // (RangeBearingObs::R_systematic): frames fused as independent shrink the filter's own P below
  // it. Added to the reported covariance (estimate_at: its sigma and health too) and to a floor
  // fix's prior (its gate and gain), never to the filter's own P, so the frames' noise still
  // averages.
  Eigen::Matrix2d repeated_share_excess(const Eigen::Matrix2d& P_xy) const;

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
    std::uint64_t odom_gaps = 0;           // samples that ended a gap (OdometryConfig::gap_ns)
    std::uint64_t fixes_held = 0;          // ahead of the odometry when they came
    std::uint64_t fixes_held_dropped = 0;  // pushed out of the full hold
    std::uint64_t relocalisations = 0;     // of reinitialisations: from a single fix when lost
    std::uint64_t fixes_rejected_not_tracking = 0;  // map-guided while uninitialised or lost
    std::uint64_t gyro_accepted = 0;
    std::uint64_t gyro_rejected_invalid = 0;    // non-finite
    std::uint64_t gyro_rejected_saturated = 0;  // at or beyond GyroConfig::saturation_radps
    std::uint64_t gyro_rejected_time = 0;       // not after the previous sample
    std::uint64_t slip_periods = 0;        // odometry periods the wheels disagreed with the gyro
    std::uint64_t slip_events = 0;         // of them: the first of a run
    std::uint64_t standstill_updates = 0;  // zero-rate updates of the gyro bias
    std::uint64_t unseen_slips = 0;  // gate-rejected fixes explained by an unseen heading change
    std::uint64_t range_bearing_fused = 0;
    std::uint64_t range_bearing_delayed = 0;  // of them: fused behind newer events
    std::uint64_t range_bearing_rejected_gate = 0;
    std::uint64_t range_bearing_rejected_not_initialised = 0;
    std::uint64_t range_bearing_rejected_too_old = 0;
    std::uint64_t range_bearing_rejected_invalid = 0;
    // Of range_bearing_fused: gated, fused with an unseen heading change's uncertainty added
    // (the second of consecutive gated observations that the same change explains).
    std::uint64_t range_bearing_unseen_slips = 0;
  };
  const Counters& counters() const { return counters_; }

  // Event flags accumulated since the previous call; clears them.
  std::uint16_t take_flags();

  bool initialised() const { return initialised_; }
  // Gate threshold computed from FixConfig::gate_probability (chi-square, 3 dof).
  double gate_threshold() const { return gate_threshold_; }
  // Mahalanobis distance^2 of the most recent fix against its prior (NaN before any gated fix).
  double last_fix_mahalanobis_sq() const { return last_fix_d2_; }
  const EkfConfig& config() const { return config_; }

 private:
  static constexpr std::int64_t kNoOdom = kNoTimeNs;
  enum class EventKind : std::uint8_t { kOdom, kFix, kInit, kRangeBearing };
  struct Event {
    std::int64_t t_ns = 0;
    EventKind kind = EventKind::kOdom;
    double v_mps = 0.0, omega_radps = 0.0;            // odometry input
    Eigen::Vector3d z = Eigen::Vector3d::Zero();      // fix (x_mm, y_mm, theta_rad)
    Eigen::Matrix3d R = Eigen::Matrix3d::Identity();  // effective fix covariance
    RangeBearingObs rb;  // range-bearing observation, with its effective covariance
    bool valid = false;  // state below is meaningful (filter initialised at this time)
    bool gyro = false;   // the period ending here took its heading from the gyro
    SlipState slip;      // the slip detectors after this event
    // Newest odometry sample at or before this event (kNoOdom: none kept): where the known
    // motion ends (OdometryConfig::gap_ns after it).
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
  // A fix after its checks: where it goes in the history and its prior there.
  struct FixPrior {
    std::size_t base = 0;  // index of the last event at or before the exposure
    FilterVec x = FilterVec::Zero();
    FilterCov P = FilterCov::Zero();
    double position_sigma_mm = 0.0;
    bool lost = false;
  };
  // One wheel's readings in a period against the previous one (wheels-only slip).
  struct WheelSteps {
    double now[2] = {0.0, 0.0};   // left, right wheel speed now
    double step[2] = {0.0, 0.0};  // and its change since the previous period
    double limit = 0.0;           // the largest step the vehicle's own motion explains
    double track_m = 0.0;
  };
  // The speed of a period whose yaw the gyro covers, after the wheel/gyro comparison.
  struct GyroSlip {
    bool slip = false;     // beyond the flag threshold
    double d_radps = 0.0;  // wheels' yaw rate minus the gyro's
    double v_mps = 0.0;    // the speed reading, corrected for the slip
    double v_var = 0.0;    // extra variance of that speed
  };

  // ---- Core (ekf_core.cpp): history, replay, prediction, generic update ----
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
  // Inserts a fused measurement event (its posterior set) and re-propagates the newer events;
  // returns its index. *delayed: newer events existed.
  std::size_t insert_measurement(const Event& ev, bool* delayed);
  // The measurement update of a fix or range-bearing event (replay and first fusion alike).
  void update_measurement(const Event& ev, FilterVec* x, FilterCov* P) const;
  // Re-initialises the history at t_ns with state x, P.
  void initialise_at(std::int64_t t_ns, const FilterVec& x, const FilterCov& P);
  // x, P over dt_s with the motion model (eq. 15-16); velocity_noise adds the random walk of v
  // and omega over dt_s (off when an odometry sample for the period is fused just before).
  // gyro_heading: the yaw rate came from the gyro, whose noise and calibration states carry the
  // heading uncertainty (no wheel heading noise).
  void predict(FilterVec* x, FilterCov* P, double dt_s, bool velocity_noise = true,
               bool gyro_heading = false) const;
  void add_velocity_noise(FilterCov* P, double dt_s) const;
  // Newest event time and newest odometry time together: the time the input streams reached.
  bool newest_time(std::int64_t* t_ns) const;

  // ---- Odometry (aid_odometry.cpp) ----
  void update_odometry(FilterVec* x, FilterCov* P, double v_mps, double omega_radps) const;
  // Speed-only odometry update (the gyro has the yaw rate); extra_v_var for a slip.
  void update_speed(FilterVec* x, FilterCov* P, double v_mps, double extra_v_var) const;
  // Odometry step (period-mean sample): fuse the sample, then predict over the period it covers.
  void propagate_odometry(FilterVec* x, FilterCov* P, double dt_s, double v_mps,
                          double omega_radps) const;
  // Prediction over [t0, t1] inside a known odometry period: the gyro's rate where it covers
  // the span, the period's yaw rate otherwise.
  void predict_known(FilterVec* x, FilterCov* P, std::int64_t t0_ns, std::int64_t t1_ns) const;
  // Prediction from t0_ns to t1_ns when the newest odometry is at odom_t_ns: the known motion
  // (predict()) up to odom_t_ns + gap_ns, the unknown-motion model after it.
  void predict_span(FilterVec* x, FilterCov* P, std::int64_t t0_ns, std::int64_t t1_ns,
                    std::int64_t odom_t_ns) const;
  // The unknown-motion part of predict_span, from known_end_ns to t1_ns.
  void predict_unknown(FilterVec* x, FilterCov* P, std::int64_t t0_ns, std::int64_t known_end_ns,
                       std::int64_t t1_ns, std::int64_t odom_t_ns) const;
  // Applies an odometry sample at t_ns to the posterior of the previous event at t_prev_ns.
  // prev: the event before (its slip state), out: gyro use and slip of this period (optional).
  void apply_odometry(FilterVec* x, FilterCov* P, std::int64_t t_prev_ns, std::int64_t odom_t_ns,
                      std::int64_t t_ns, double v_mps, double omega_radps,
                      const Event* prev = nullptr, Event* out = nullptr) const;
  // The same for a period of known motion without a gyro (wheels only, held wheel applied).
  void apply_wheel_period(FilterVec* x, FilterCov* P, std::int64_t t_prev_ns, std::int64_t t_ns,
                          double v_mps, double omega_radps, const Event* prev, Event* out) const;
  bool is_gap(std::int64_t odom_t_ns, std::int64_t t_ns) const {
    return odom_t_ns == kNoOdom || t_ns - odom_t_ns > config_.odometry.gap_ns;
  }
  static std::int64_t odom_time_after(const Event& ev) {
    return ev.kind == EventKind::kOdom ? ev.t_ns : ev.odom_t_ns;
  }
  // Newest odometry time at or before history index i (exclusive of i itself).
  std::int64_t odom_time_before(std::size_t i) const {
    return i == 0 ? kNoOdom : odom_time_after(at(i - 1));
  }

  // ---- Gyro (aid_gyro.cpp) ----
  // The period (t_prev_ns, t_ns] of an odometry sample whose yaw the gyro covers (mean g).
  void apply_gyro_period(FilterVec* x, FilterCov* P, std::int64_t t_prev_ns, std::int64_t t_ns,
                         double v_mps, double omega_radps, double g, const Event* prev,
                         Event* out) const;
  // The odometry step of a period whose yaw the gyro covers; returns whether wheels slipped.
  // v_read_prev_mps: the previous raw speed reading (NaN: none); run: the sub-threshold slip run
  // so far, updated for this period.
  bool gyro_period(FilterVec* x, FilterCov* P, double dt_s, double v_mps, double omega_radps,
                   double gyro_radps, bool distrust_gyro, double v_read_prev_mps,
                   SlipRun* run) const;
  // Mean gyro rate over (t0_ns, t1_ns] when the kept samples cover it completely.
  bool gyro_mean(std::int64_t t0_ns, std::int64_t t1_ns, double* mean_radps) const;
  // The same, holding the newest sample's rate up to gap_ns past it (output ticks between
  // samples during an odometry gap).
  bool gyro_mean_hold(std::int64_t t0_ns, std::int64_t t1_ns, double* mean_radps) const;
  // Sets omega from a gyro mean over dt_s (the gyro calibration states, the rate noise).
  void set_gyro_rate(FilterVec* x, FilterCov* P, double gyro_radps, double dt_s) const;
  // Zero-rate pseudo-measurement omega = 0 (standing still): teaches the gyro bias.
  void update_zero_rate(FilterVec* x, FilterCov* P) const;
  // Index of the first kept gyro sample with t >= t_ns (gyro_size_ when none).
  std::size_t gyro_lower_bound(std::int64_t t_ns) const;

  // ---- Wheel slip (aid_wheel_slip.cpp) ----
  // With a gyro: the wheels' yaw rate against the gyro's (x holds the gyro's rate); a slip
  // corrects the speed, a smaller difference teaches the wheel calibration or, beyond the
  // noise, is a sub-threshold slip (run).
  GyroSlip wheels_against_gyro(FilterVec* x, FilterCov* P, double dt_s, double v_mps,
                               double omega_radps, bool still, double v_read_prev_mps,
                               SlipRun* run) const;
  // A difference under the flag threshold: the speed, corrected for what the sample noise and
  // the calibration do not explain.
  void small_slip(FilterVec* x, FilterCov* P, double dt_s, double v_mps, double omega_radps,
                  bool still, double v_read_prev_mps, double away, SlipRun* run,
                  GyroSlip* out) const;
  // Fuses the wheels' yaw rate into their calibration states only (the gyro keeps the heading);
  // returns the wheels' yaw rate minus the gyro's, rad/s, and its sigma from the sample noise
  // and the calibration's uncertainty.
  double learn_wheel_yaw(FilterVec* x, FilterCov* P, double v_mps, double omega_radps, bool learn,
                         double* sigma_radps) const;
  // Wheels only: the hold after this period's readings (SlipConfig::wheel_step_min_mps); sets
  // the readings to use and the heading variance the hold adds in this period.
  WheelHold hold_wheel(const Event& prev, std::int64_t t_ns, double dt_s, double v_mps,
                       double omega_radps, double* v_use_mps, double* omega_use_radps,
                       double* add_theta_var) const;
  // A hold going on: false when it ends in this period (*h is then the hold to keep).
  bool continue_hold(WheelHold* h, const WheelSteps& s, std::int64_t t_ns,
                     double* add_theta_var) const;
  // No hold yet: true when one of the wheels starts one in this period (*h set).
  bool start_hold(const Event& prev, const WheelSteps& s, double dt_s, WheelHold* h,
                  double* add_theta_var) const;
  // The held wheel's reading to use, and the heading doubt the hold adds.
  void read_held(WheelHold* h, const WheelSteps& s, double dt_s, double* v_use_mps,
                 double* omega_use_radps, double* add_theta_var) const;
  // Counts slip periods and runs once per period however often the period is replayed.
  void count_slip(const Event& prev, bool was_slip, bool was_start, const Event& ev) const;

  // ---- Landmark fix (aid_fix.cpp) ----
  FixOutcome fuse_fix(std::int64_t t_ns, const Pose2& z_world, const Eigen::Matrix3d& R_in,
                      bool map_verified, bool map_guided, bool from_hold);
  // Fix R scaled and floored (FixConfig::cov_scale, floor sigmas).
  Eigen::Matrix3d effective_fix_cov(const Eigen::Matrix3d& R_in) const;
  FixOutcome initialise_from_fix(long k, std::int64_t t_ns, const Eigen::Vector3d& z,
                                 const Eigen::Matrix3d& R);
  // The gate and the recovery rules for a fix against its prior; kFused when it is to be fused
  // (prior->P may then carry an unseen slip's uncertainty).
  FixOutcome gate_fix(std::int64_t t_ns, const Eigen::Vector3d& z, const Eigen::Matrix3d& R,
                      const Eigen::Matrix3d& R_in, bool map_verified, bool map_guided,
                      FixPrior* prior);
  FixOutcome reject_fix_gate(std::int64_t t_ns, const Eigen::Vector3d& z, const Eigen::Matrix3d& R,
                             const FixPrior& prior, bool map_guided, bool worthless_prior);
  FixOutcome reject_fix_invalid();
  FixOutcome reject_fix_too_old();
  FixOutcome reject_fix_not_tracking();
  // Fuses a gated fix at its exposure time and re-propagates newer events.
  FixOutcome fuse_gated_fix(std::int64_t t_ns, const Eigen::Vector3d& z, const Eigen::Matrix3d& R,
                            FixPrior* prior);
  void hold_fix(std::int64_t t_ns, const Pose2& z_world, const Eigen::Matrix3d& R_in,
                bool map_verified, bool map_guided);
  // Fuses held fixes older than t_ns (before the odometry sample at t_ns is inserted).
  void release_held_before(std::int64_t t_ns);
  // After odometry at t_ns: fuses held fixes within max_lead_ns, rejects those still ahead.
  void settle_held_after(std::int64_t t_ns);
  void update_fix(FilterVec* x, FilterCov* P, const Eigen::Vector3d& z,
                  const Eigen::Matrix3d& R) const;
  // Innovation (angle wrapped) and its Mahalanobis distance^2.
  double mahalanobis_sq(const FilterVec& x, const FilterCov& P, const Eigen::Vector3d& z,
                        const Eigen::Matrix3d& R) const;
  // Mahalanobis distance^2 of the fix position alone against the prior position.
  double position_mahalanobis_sq(const FilterVec& x, const FilterCov& P, const Eigen::Vector3d& z,
                                 const Eigen::Matrix3d& R) const;

  // ---- Range-bearing (aid_range_bearing.cpp) ----
  void update_range_bearing(FilterVec* x, FilterCov* P, const RangeBearingObs& obs) const;
  FixOutcome reject_range_bearing_invalid();
  FixOutcome reject_range_bearing_too_old();

  // ---- Recovery (recovery.cpp): kidnap, re-localisation, unseen slip ----
  // Kidnap candidate handling for a gate-rejected fix; true when it re-initialised the filter.
  // prior_worthless (position sigma beyond 4x lost_position_sigma_mm): two separate agreeing
  // fixes suffice, without kidnap_min_duration_ns.
  bool kidnap_candidate(std::int64_t t_ns, const Eigen::Vector3d& z, const Eigen::Matrix3d& R,
                        const FilterVec& prior_x, const FilterCov& prior_P, bool prior_worthless);
  // Carries the candidate track to t_ns and fuses the fix into it when it passes the gate.
  bool extend_hypothesis(std::int64_t t_ns, const Eigen::Vector3d& z, const Eigen::Matrix3d& R);
  void start_hypothesis(std::int64_t t_ns, const Eigen::Vector3d& z, const Eigen::Matrix3d& R,
                        const FilterVec& prior_x, const FilterCov& prior_P);
  // Raises the calibration variances (odometry when estimated, gyro bias and scale) to at least
  // their initial values: for a kidnap track, which must not inherit a rejected filter's trust.
  void widen_calibration(FilterCov* P) const;
  // Re-initialises the pose from one fix, keeping speed and calibration of the prior.
  void relocalize(std::int64_t t_ns, const Eigen::Vector3d& z, const Eigen::Matrix3d& R,
                  const FilterVec& prior_x, const FilterCov& prior_P);
  // The path driven since the last fused fix (unseen_slip_max_rad), thinned as it fills.
  void track_odometry();
  void track_restart(std::size_t fix_index);
  // True when one heading change on that path explains the fix's innovation (z against x, P at
  // t_ns); then adds it to *P (heading, and position through the lever arm to the fix).
  bool explain_unseen_slip(std::int64_t t_ns, const Eigen::Vector3d& z, const Eigen::Matrix3d& R,
                           const FilterVec& x, FilterCov* P) const;
  // The same for a gated range-bearing observation (obs: its effective R): the heading change
  // and turn point that best explain it; true when one within unseen_slip_max_rad and beyond the
  // prior's 3 sigma does, and the observation passes the gate with it added to *P. *dth_rad: the
  // change.
  bool explain_unseen_slip(std::int64_t t_ns, const RangeBearingObs& obs, const FilterVec& x,
                           FilterCov* P, double* dth_rad) const;
  // Wheels only since the last fused fix and the rule on: a heading change may be unseen.
  bool unseen_slip_possible() const;
  // A turn by dth_rad about a point of the path, seen at position p: its displacement q there,
  // the direction u of the path at the point, the along-track and spread slack (mm).
  struct UnseenTurn {
    Eigen::Vector2d q = Eigen::Vector2d::Zero(), u = Eigen::Vector2d::Zero();
    double along_mm = 0.0, smear_mm = 0.0;
  };
  struct TrackPoint;
  UnseenTurn unseen_turn(const TrackPoint& tp, const Eigen::Vector2d& p, double dth_rad) const;
  // Adds the turn's uncertainty to *P: heading by its own size, position along the chord it
  // moved, the along-track and spread terms.
  void add_unseen_turn(const UnseenTurn& turn, double dth_rad, FilterCov* P) const;
  // Gated range-bearing observation: true when it is the second of consecutive gated ones, of
  // two landmarks, explained by the same unseen heading change; then *P carries that change.
  bool range_bearing_unseen_slip(std::int64_t t_ns, const RangeBearingObs& obs, const FilterVec& x,
                                 FilterCov* P);

  // ---- Health (health.cpp) ----
  // Position or heading sigma of P beyond the lost limits; reports both sigmas when asked.
  bool prior_lost(const FilterCov& P, double* position_sigma_mm = nullptr,
                  double* heading_sigma_rad = nullptr) const;

  EkfConfig config_;
  double gate_threshold_ = 0.0;
  double gate_threshold_2d_ = 0.0;        // same probability, position only
  double range_bearing_threshold_ = 0.0;  // chi-square, 2 dof, RangeBearingConfig
  std::vector<Event> history_;            // sized in the constructor, never resized
  struct TrackPoint {
    std::int64_t t_ns = 0;
    double x_mm = 0.0, y_mm = 0.0, theta_rad = 0.0, v_mps = 0.0;
  };
  static constexpr std::size_t kTrackPoints = 128;
  std::array<TrackPoint, kTrackPoints> track_{};
  std::size_t track_size_ = 0;
  std::int64_t track_spacing_ns_ = 50'000'000;  // doubles each time the track is thinned
  // Newest fused range-bearing exposure since the track started (heading confirmed there).
  std::int64_t track_rb_fused_t_ns_ = std::numeric_limits<std::int64_t>::min();
  // The last gated range-bearing observation an unseen heading change explained (count 0: none
  // since the last fused observation or fix).
  struct RbSlipCandidate {
    int count = 0;
    std::int64_t t_ns = 0;
    double dth_rad = 0.0, tol_rad = 0.0;
    Eigen::Vector2d landmark_xy_mm = Eigen::Vector2d::Zero();
    // The turn's uncertainty at the exposure (x, y, heading) and the position there: reported,
    // never fused, until a second landmark confirms the change or an update refutes it.
    Eigen::Matrix3d turn_cov = Eigen::Matrix3d::Zero();
    Eigen::Vector2d p_mm = Eigen::Vector2d::Zero();
  };
  RbSlipCandidate rb_slip_;
  // The envelope of the repeated shares' position covariances (repeated_share_excess).
  Eigen::Matrix2d rb_repeated_floor_ = Eigen::Matrix2d::Zero();
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
};

}  // namespace agv::fusion
