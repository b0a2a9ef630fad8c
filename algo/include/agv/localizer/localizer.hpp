// The localizer core: odometry, gyro, CAN frames and vision results in; one transport-neutral
// record per output period out (TickRecord: pose with its validity, velocity, quality, status,
// heartbeat due, end-to-end exposure), which every output encodes for itself: CAN
// (localizer::CanOutput, can_output.hpp), VDA 5050 (vda5050::map_tick), the diagnostics page,
// poses.csv. Owns fusion (fusion::Ekf) and the output policy: pose validity, health, fault
// latching, rejection flags, heartbeat schedule. Pure: no bus, no clock, no threads; the caller
// passes the time (firmware/src/output_loop.*). After construction none of its methods allocates
// (tests/firmware/test_alloc.cpp proves it).
#pragma once

#include <array>
#include <cstdint>
#include <optional>
#include <span>

#include "agv/common/latency_histogram.hpp"
#include "agv/fusion/ekf.hpp"
#include "agv/hal/can_frame.hpp"
#include "agv/hal/can_types.hpp"
#include "agv/localizer/can_fault_monitor.hpp"
#include "agv/localizer/time_base.hpp"
#include "agv/protocol/codec.hpp"
#include "agv/ranging/fix.hpp"
#include "agv/vision/landmark_localizer.hpp"
#include "agv/vision/tracking.hpp"

namespace agv::localizer {

// Configured odometry correction (keys `odometry.*`, from `agvloc-desk calibrate vehicle`),
// applied to every odometry sample before fusion (scales, bias), the same equations as the
// calibration's model
// (tools/desk/src/calib_vehicle.hpp):
//   v' = speed_scale * v + yaw_per_metre_rad * track_width_m^2 / 4 * omega
//   (track_width_m: fusion.wheel_track_mm, the one track width),
//   omega' = yaw_rate_scale * omega + yaw_rate_bias_radps + yaw_per_metre_rad * v
//   (v and omega as read; the yaw_per_metre terms are unequal wheels, calib_vehicle.hpp),
// The stamps are the time base's (TimeBase): odometry defines the vehicle's clock.
// The EKF's own calibration states (fusion.estimate_odometry_calibration) start at 1 / 0 and
// then estimate only what is left after this correction. All defaults = no change at all.
struct OdometryCorrection {
  double speed_scale = 1.0;
  double yaw_rate_scale = 1.0;
  double yaw_rate_bias_radps = 0.0;
  double yaw_per_metre_rad = 0.0;  // unequal wheels: a straight run's curvature, rad/m
};

// Configured gyro correction (keys `imu.*`), applied to every gyro sample before fusion:
//   rate' = scale * rate + bias_radps (its stamp: TimeBase). The EKF estimates the gyro bias and
// scale left after this.
struct GyroCorrection {
  double scale = 1.0;
  double bias_radps = 0.0;
};

// Landmarks on racks seen by the second (forward or side) camera (Localizer::on_ranging,
// docs/design/ranging.md "In the localizer"). While the filter is uninitialised or lost, each
// frame's landmarks give a prior-free fix (ranging::fix_from_landmarks); init_fixes consecutive
// fixes that agree initialise (or re-localise) the filter, one landmark never does. While it
// tracks, each landmark is a range-bearing update of the EKF (gated there); init_fixes consecutive
// frames with every landmark gated, whose fixes agree with each other on a heading step the wheels
// did not show (fusion.recovery.unseen_slip_max_rad, wheels only), re-localise it.
inline ranging::FixOptions rack_fix_options() {
  ranging::FixOptions o;
  // One frame's fix, before stacking: two landmarks at 5-8 m give 30-100 mm sigma across the
  // baseline, which a second of frames brings to the initialisation's limit; wider fixes are
  // nearly as ambiguous as they are uncertain.
  o.max_position_sd_mm = 100.0;
  return o;
}
struct RangingAidConfig {
  ranging::FixOptions fix = rack_fix_options();
  // Consecutive agreeing fixes needed to initialise: 2, as two agreeing fixes are what lets tags
  // (whose map entry is their only truth) re-initialise a filter whose position is unknown.
  int init_fixes = 2;
  // The pose that initialises (or re-localises) has at most this position sigma along its worst
  // axis: the lost limit is 50 mm, and a pose above this would start the filter no better than
  // lost.
  double init_position_sd_mm = 20.0;
  // true: the consecutive agreeing fixes are stacked (their own shares of the covariance
  // averaged, the share every frame repeats, the calibration's, kept once: fix_systematic_cov)
  // and the stack initialises once init_fixes agree and it is within init_position_sd_mm, so a
  // vehicle at rest gains from every frame. false: each frame's fix alone must be within
  // init_position_sd_mm, and the newest of init_fixes agreeing ones initialises.
  bool stack_fixes = true;
  // Fixes further apart than this are not consecutive: the count restarts.
  std::int64_t init_max_gap_ns = 500'000'000;
  // The earlier fix is carried to the later one with the newest odometry (v, omega); the motion's
  // doubt, per axis, is this share of the distance (and of the turn).
  double motion_sigma_share = 0.05;
  // Chi-square (3 dof) gate on the two fixes' difference: 16.27 is probability 0.999.
  double agreement_gate = 16.27;
  // vehicle clock = second camera's clock + camera_offset_ns (as TimeBase::camera_offset_ns).
  std::int64_t camera_offset_ns = 0;
  // 1 sigma of an error every bearing of a frame shares (the camera's yaw as mounted against as
  // calibrated, the principal point's column): added to each prior-free fix's covariance
  // (ranging::add_mount_yaw_uncertainty), which the landmarks themselves cannot reveal.
  double common_bearing_sigma_rad = 0.0;
  // A floor-only twin of the filter (the same odometry, gyro, floor fixes and operator poses; no
  // rack landmarks) arbitrates a floor fix that fails the gate after rack updates were fused: a
  // wrong second camera (a mount turned since its calibration, a rack that moved) must not veto
  // the floor camera. When the twin fuses conflict_fixes such fixes in a row (no floor fix the
  // filter fused between them), the filter takes over the twin's estimate
  // (OutputStats::ranging_floor_conflicts); if the next rack frame disagrees with it too
  // (probation_ns), the rack aid is suspended for conflict_suspend_ns. Only fixes whose identity
  // is their own (not map-guided) arbitrate. Off: no twin (the firmware turns it on with
  // ranging_camera.enabled). Longer suspension: a miscalibrated camera costs less often; shorter:
  // a transient conflict (a pushed rack) gives the rack aid back sooner.
  bool floor_check = false;
  std::int64_t conflict_suspend_ns = 30'000'000'000;
  // After taking over the twin's estimate, the first rack frame within this time that has a
  // landmark fused or gated decides: fused, the rack aid agrees with the floor camera (the filter
  // had been overconfident, e.g. after a slip the wheels did not show) and goes on; all gated, it
  // is suspended for conflict_suspend_ns.
  std::int64_t probation_ns = 1'000'000'000;
  // Floor fixes in a row, each gated by the filter and fused by the twin, before the take-over
  // (>= 1). One wrong floor fix (a misread corner, glare; the twin, less sure between floor
  // landmarks, fuses it) is not enough to overrule the rack aid; a turned second camera keeps
  // the filter gating every floor fix, and costs one floor frame more per take-over.
  int conflict_fixes = 2;
};

// One landmark of one second-camera frame, both ways the localizer uses it: from the vehicle's
// reference point (the prior-free fix's input, ranging::fix_observations) and from the camera
// itself (the EKF aid's input, ranging::sensor_range_bearing).
struct RackObservation {
  ranging::Observation vehicle;
  fusion::RangeBearingObs sensor;
};

// What Localizer::on_ranging did with one frame.
enum class RangingResult : std::uint8_t {
  kEmpty,        // no landmark in the frame
  kFused,        // tracking: at least one landmark fused
  kRejected,     // tracking: every landmark rejected by the EKF (gate, too old, invalid)
  kFixRefused,   // not tracking: the fix was refused (stats().ranging_fix_refused says why)
  kFixPending,   // not tracking: an OK fix, not yet agreed by enough consecutive ones
  kInitialised,  // not tracking: the filter was initialised or re-localised from the fix
  // Tracking, every landmark gated: init_fixes consecutive such frames' fixes agreed on a heading
  // step the wheels did not show (ranging_aid.cpp); re-localised from the newest.
  kRelocalised,
  // Not used: the rack aid is suspended after it disagreed with a floor fix (floor_check).
  kSuspended,
};
const char* to_string(RangingResult r);

struct LocalizerConfig {
  // fusion.odom_timeout_ns is THE odometry timeout: no accepted sample (CAN or recording) for
  // this long makes the pose invalid, sets FaultOdomTimeout and the EKF's kOdomTimeout flag.
  // Trade-off: short stops a vehicle on bus jitter, long lets it drive on a stale prediction.
  fusion::EkfConfig fusion;
  protocol::ProtocolConfig protocol;
  OdometryCorrection odometry;
  GyroCorrection gyro;
  // Every sensor stamp onto the vehicle's clock, applied where it enters the core (on_odometry,
  // on_gyro, on_fix, prediction_at); the threaded loop's vision worker takes the same value
  // (time_base()) for its predictions.
  TimeBase time_base;
  // No accepted gyro sample for this long while gyro samples were seen before sets
  // FaultImuTimeout (the filter falls back to the wheels by itself; docs/design/fusion.md "Gyro").
  // With the CAN gyro enabled (protocol.gyro.enabled) also when none has arrived this long after
  // the first tick. Key can.gyro.timeout_ms.
  std::int64_t gyro_timeout_ns = 100'000'000;
  // A gyro source outside CAN is configured (imu.source iio): silence since the first tick is
  // FaultImuTimeout as with the CAN gyro enabled.
  bool gyro_expected = false;
  std::int64_t heartbeat_period_ns = 1'000'000'000;
  // No camera frame for this long (and the stream not at its end) -> FaultCameraStalled.
  std::int64_t camera_timeout_ns = 500'000'000;
  std::uint8_t sw_major = 0, sw_minor = 0, sw_patch = 0;  // sent in the heartbeat
  RangingAidConfig ranging;
};

struct OutputStats {
  std::uint64_t ticks = 0;
  std::uint64_t missed_periods = 0;  // wake-ups later than one full period
  std::uint64_t odom_samples = 0;
  std::uint64_t odom_rejected = 0;  // by the EKF (time or plausibility)
  std::uint64_t gyro_samples = 0;
  std::uint64_t gyro_rejected = 0;  // by the EKF (time, plausibility, saturation)
  // CAN gyro frames that passed the decoder but carried the sensor's Saturated bit: not fused
  // (not in gyro_samples).
  std::uint64_t gyro_saturated = 0;
  std::uint64_t fixes_received = 0;
  // The fix outcomes below are the EKF's counters (fusion::Ekf::Counters, the one count), read by
  // fix_outcome_counts(): a fix held ahead of the odometry is counted when it is fused or
  // rejected. Written by the Localizer after every input; a sender must not change them.
  // fixes_fused: fused, initialising or re-initialising the filter (kidnap, re-localisation).
  std::uint64_t fixes_fused = 0;
  std::uint64_t fixes_rejected_gate = 0;
  std::uint64_t fixes_rejected_too_old = 0;
  std::uint64_t fixes_rejected_invalid = 0;  // also those exposed after their arrival
  std::uint64_t reinitialisations = 0;       // from fixes (not from an operator-set pose)
  // Map-guided fixes (docs/design/map_identity.md): received (also counted in fixes_received),
  // fused, and refused because the filter was uninitialised or lost.
  std::uint64_t fixes_map_guided = 0;
  std::uint64_t fixes_map_guided_fused = 0;
  std::uint64_t fixes_rejected_not_tracking = 0;
  std::uint64_t fix_poses = 0;  // pose pairs sent at once after a fix (pose_on_fix)
  // Second camera (on_ranging): frames and landmarks received; while tracking, the EKF's
  // range-bearing outcomes (its counters); while not, the fixes computed, those refused (by
  // ranging::FixStatus), OK ones that disagreed with the previous, and the initialisations and
  // re-localisations they made (not in fixes_fused or reinitialisations, which are floor fixes').
  // Tracking frames whose landmarks were all gated compute the fix too (ranging_step).
  std::uint64_t ranging_frames = 0;
  std::uint64_t ranging_landmarks = 0;
  std::uint64_t ranging_fused = 0;
  std::uint64_t ranging_rejected_gate = 0;
  std::uint64_t ranging_rejected_other = 0;  // too old, invalid, not initialised
  std::uint64_t ranging_fixes = 0;
  std::array<std::uint64_t, 8> ranging_fix_refused{};  // by ranging::FixStatus (kOk unused)
  std::uint64_t ranging_fixes_disagreed = 0;
  std::uint64_t ranging_initialisations = 0;
  // Of ranging_initialisations: while tracking, after a heading step the wheels did not show
  // (every landmark gated, consecutive agreeing fixes; RangingResult::kRelocalised).
  std::uint64_t ranging_step_relocalisations = 0;
  // floor_check: floor fixes the filter gated but its floor-only twin fused after rack updates
  // (the filter took over the twin's estimate), the suspensions of the rack aid that followed
  // (the next rack frame disagreed with the floor camera's pose too), and the frames not used
  // while suspended.
  std::uint64_t ranging_floor_conflicts = 0;
  // Such floor fixes short of conflict_fixes in a row (not taken over; a floor fix the filter
  // fused came next, or none yet).
  std::uint64_t ranging_floor_disputes = 0;
  // Floor fixes the filter fused and the twin gated (it held an older floor fix, a misread it
  // fused): the twin took over the filter's estimate.
  std::uint64_t ranging_floor_twin_resyncs = 0;
  std::uint64_t ranging_suspensions = 0;
  std::uint64_t ranging_suspended_frames = 0;
  std::uint64_t can_tx_ok = 0;
  std::uint64_t can_tx_failed = 0;
  std::uint64_t can_rx_frames = 0;
  std::uint64_t can_rx_other = 0;     // frames of no enabled input message (ignored)
  LatencyHistogram fusion_ns;         // tick() and its CAN encoding, one period
  LatencyHistogram can_send_ns;       // all sends of one tick
  LatencyHistogram end_to_end_ns;     // first pose frame sent after a fix - that frame's exposure
  LatencyHistogram period_jitter_ns;  // |actual wake-up - scheduled wake-up|
};

// What one received CAN frame was (Localizer::on_can_frame, three-argument form).
enum class CanRx : std::uint8_t {
  kOdometry,       // odometry that passed the decoder's checks, handed to on_odometry
  kGyro,           // gyro sample that passed the decoder's checks, handed to on_gyro (which may
                   // still reject it: stats().gyro_rejected)
  kGyroSaturated,  // gyro frame that passed the checks with the Saturated bit: counted, not fused
  kRejected,       // an enabled input message that failed its decoder's checks (counted there)
  kOther,          // no enabled input message: counted in can_rx_other, ignored
};

// The pose pair's content (AGV_PoseXY, AGV_PoseHeading) at one instant, periodic or at once
// after a fix (Localizer::pose_now).
struct PoseOutput {
  protocol::PoseOut pose;
  // Exposure of the newest fused fix this pose is the first to carry; INT64_MIN if none. The
  // sender records end-to-end latency = (time the pose left) - this.
  std::int64_t e2e_exposure_ns = INT64_MIN;
};

// What one tick produced, transport-neutral: what the CAN frames carry as plain values, with the
// estimate behind them. Every output encodes this one value (CAN: CanOutput; VDA 5050; the
// diagnostics page; replay's poses.csv).
struct TickRecord {
  std::int64_t t_ns = 0;
  fusion::PoseEstimate estimate;
  PoseOutput pose;
  protocol::VelocityOut velocity;
  protocol::QualityOut quality;
  protocol::StatusOut status;
  // AGV_Heartbeat is due this period (LocalizerConfig::heartbeat_period_ns); heartbeat holds it.
  bool heartbeat_due = false;
  protocol::HeartbeatOut heartbeat;
  // PoseValid of the pose (protocol::pose_valid_on_can(pose.pose)). Not the same as
  // estimate.valid, which means only "the filter is initialised" (true while LOST too).
  bool pose_valid = false;
};

// The fix outcomes of OutputStats, from the EKF's counters. exposed_after_arrival: fixes the
// Localizer refused before the EKF saw them (counted as invalid); operator: what operator-set
// poses (set_pose) added to the EKF's initialisations and re-initialisations, which are not
// fixes.
struct OperatorPoseCounts {
  std::uint64_t initialisations = 0;
  std::uint64_t reinitialisations = 0;
};
void fix_outcome_counts(const fusion::Ekf::Counters& ekf, std::uint64_t exposed_after_arrival,
                        const OperatorPoseCounts& operator_poses, OutputStats* out);

// The 1-sigma uncertainty an operator-set pose (VDA 5050 initPosition) gets: half the configured
// lost limits (fusion.lost_position_sigma_mm, fusion.lost_heading_sigma_deg). The pose is then
// valid (not LOST) until its sigma has doubled while dead reckoning, and the next landmark fix
// narrows it; at the limits themselves it would turn LOST as soon as the vehicle moved.
struct InitPositionSigma {
  double position_mm = 0.0;
  double heading_rad = 0.0;
};
inline constexpr double kInitPositionSigmaOfLostLimit = 0.5;
InitPositionSigma init_position_sigma(const fusion::EkfConfig& fusion);

class Localizer {
 public:
  // Throws std::invalid_argument on an invalid fusion or protocol configuration.
  explicit Localizer(const LocalizerConfig& cfg);

  // Odometry from any source (recording, CAN), stamped t_ns on the odometry's clock (the
  // vehicle's: TimeBase).
  void on_odometry(std::int64_t t_ns, double v_mps, double omega_radps);
  // One yaw-rate sample of the gyro (vehicle z axis, counter-clockwise positive), stamped t_ns on
  // the gyro's clock (TimeBase maps it onto the vehicle clock). From any source (CAN, IIO,
  // recording). Returns false when the filter rejected it (non-finite, saturated, not after the
  // previous sample, too far ahead).
  bool on_gyro(std::int64_t t_ns, double gyro_z_radps);
  // True when gyro samples were seen and none was accepted within gyro_timeout_ns of now_ns.
  bool gyro_timed_out(std::int64_t now_ns) const;
  // One received CAN frame, dispatched by ID over the enabled input messages of the signal table
  // (protocol::rx_enabled): odometry is decoded, checked and handed to on_odometry, AGV_Gyro
  // (with protocol.gyro.enabled) decoded, checked and handed to on_gyro unless the sensor flagged
  // it saturated (then counted in stats().gyro_saturated); other frames are counted and ignored.
  // Returns true when the frame was odometry that passed the decoder's checks; *sample (if not
  // null) is then what was handed to on_odometry, so the caller can keep the run's input for a
  // replay of exactly what fusion saw (replay --odom-from-can writes odom_received.csv).
  bool on_can_frame(const hal::CanFrame& f, protocol::OdomSample* sample = nullptr);
  // The same, telling what the frame was: *odom (if not null) is filled for kOdometry, *gyro (if
  // not null) for kGyro and kGyroSaturated (the decoded sample, before GyroCorrection).
  CanRx on_can_frame(const hal::CanFrame& f, protocol::OdomSample* odom,
                     protocol::GyroSample* gyro);
  // The receive filters, one per enabled input message in signal-table order (the odometry
  // frame, then AGV_Gyro when enabled), so the kernel drops the rest. Writes at most max
  // filters to out and returns how many the configuration needs (more than max: truncated).
  int receive_filters(hal::CanFilter* out, int max) const;
  // One odometry message (wheels or twist) + AGV_Gyro; the localizer test checks it against
  // every configuration of the signal table.
  static constexpr int kMaxReceiveFilters = 2;
  // A vision result for a frame exposed at t_exposure_ns (the camera's clock: TimeBase moves it
  // onto the vehicle's), ready at t_arrival_ns.
  // Failed fixes only set status flags. An exposure after the arrival can only come from a
  // camera clock that jumped ahead: rejected as invalid, never fused at a time it was not taken.
  void on_fix(const vision::LandmarkMeasurement& fix, std::int64_t t_exposure_ns,
              std::int64_t t_arrival_ns = INT64_MAX);
  // An external pose (VDA 5050 initPosition, docs/guide/vda5050.md) at now_ns, in mm / rad with its
  // 1-sigma position and heading uncertainty. False when the filter refused it (non-finite).
  bool set_pose(std::int64_t now_ns, const Pose2& pose, double sigma_mm, double sigma_rad);
  // The landmarks on racks of one second-camera frame exposed at t_exposure_ns (that camera's
  // clock; LocalizerConfig::ranging.camera_offset_ns moves it onto the vehicle's). Tracking: each
  // landmark -> Ekf::add_range_bearing; all of them gated: the fix may witness a heading step the
  // wheels did not show (re-localised after init_fixes agreeing frames). Uninitialised or lost: the
  // prior-free fix, initialising by RangingAidConfig's rules (ranging_aid.cpp). At most
  // kMaxRackLandmarks are used. The fix path allocates (ranging::fix_from_landmarks); the tracking
  // path does not.
  RangingResult on_ranging(std::int64_t t_exposure_ns, std::span<const RackObservation> obs);
  static constexpr std::size_t kMaxRackLandmarks = 16;
  // VDA 5050 initPosition: set_pose with init_position_sigma(config().fusion).
  bool init_position(std::int64_t now_ns, const Pose2& pose);
  // Camera health: receive time of the newest frame, the stream ended (replay), driver error.
  void set_camera_state(std::int64_t last_frame_ns, bool end_of_stream, bool error) {
    last_frame_ns_ = last_frame_ns;
    camera_eos_ = end_of_stream;
    camera_error_ = error;
  }
  // Bus health for the status frame's CAN faults; not called = no bus (no CAN faults).
  void set_can_state(hal::CanBusState state, const hal::CanStats& stats) {
    can_state_ = state;
    can_stats_ = stats;
    have_can_state_ = true;
  }
  void note_missed_period() {
    ++stats_.missed_periods;
    overrun_ = true;
  }

  // The periodic output at now_ns: pose, velocity, quality, status, heartbeat when due.
  TickRecord tick(std::int64_t now_ns);
  // The pose alone, estimated at now_ns, outside the periodic schedule (loop.pose_on_fix: a
  // fused fix reaches the bus without waiting up to one period).
  PoseOutput pose_now(std::int64_t now_ns);

  // The fused pose predicted to a camera frame's exposure (the camera's clock), for its search
  // windows
  // (docs/design/tracking.md) and map-guided identity (docs/design/map_identity.md). Valid when
  // initialised and odometry not timed out at t_exposure_ns, also while lost: its users decide by
  // the covariance. `replay --fast` asks this directly (vision runs inline).
  vision::Prediction prediction_at(std::int64_t t_exposure_ns) const;
  // The same at t_ns on the vehicle's clock with the velocities, for a thread that must not call
  // the core: the threaded loop's vision worker extrapolates it to each exposure, moved onto the
  // vehicle's clock by time_base().
  vision::MotionSnapshot snapshot_at(std::int64_t t_ns) const;
  const TimeBase& time_base() const { return cfg_.time_base; }
  const LocalizerConfig& config() const { return cfg_; }

  const OutputStats& stats() const { return stats_; }
  // The sender records transmit results and latencies here (not the fix outcomes: the EKF's).
  OutputStats& mutable_stats() { return stats_; }
  const fusion::Ekf& ekf() const { return ekf_; }
  const protocol::OdometryDecoder& odometry_decoder() const { return odom_; }
  const protocol::GyroDecoder& gyro_decoder() const { return gyro_; }
  bool odometry_timed_out(std::int64_t now_ns) const;

 private:
  // Pose output for an estimate: invalid when uninitialised, lost or without odometry.
  protocol::PoseOut pose_out(const fusion::PoseEstimate& est, std::int64_t now_ns,
                             bool* odom_timeout) const;
  PoseOutput take_pose(const protocol::PoseOut& pose);
  protocol::StatusOut status_at(std::int64_t now_ns, const fusion::PoseEstimate& est,
                                bool odom_timeout);
  protocol::QualityOut quality_of(const fusion::PoseEstimate& est);
  bool heartbeat_due(std::int64_t now_ns, protocol::HeartbeatOut* hb);
  // OutputStats' fix outcomes from the EKF's counters, after every call that may change them.
  // Initialisations from rack fixes are set poses to the EKF, counted apart like operator poses.
  void refresh_fix_counts() {
    const OperatorPoseCounts set_poses{
        operator_poses_.initialisations + rack_poses_.initialisations,
        operator_poses_.reinitialisations + rack_poses_.reinitialisations};
    fix_outcome_counts(ekf_.counters(), fixes_exposed_after_arrival_, set_poses, &stats_);
  }
  // on_ranging's two paths (ranging_aid.cpp).
  RangingResult ranging_track(std::int64_t t_ns, std::span<const RackObservation> obs,
                              const fusion::PoseEstimate& prior);
  RangingResult ranging_fix(std::int64_t t_ns, std::span<const RackObservation> obs);
  // Tracking, every landmark of the frame gated: the frame's fix as the witness of a heading step
  // the wheels did not show; init_fixes consecutive agreeing ones re-localise.
  RangingResult ranging_step(std::int64_t t_ns, std::span<const RackObservation> obs,
                             const fusion::PoseEstimate& prior);
  bool rack_heading_step(const ranging::FixResult& fix, const fusion::PoseEstimate& prior) const;
  // floor_check: a floor fix's outcome in the filter against the floor-only twin's; the outcome
  // to act on (kReinitialised when the twin overruled the rack aid).
  fusion::FixOutcome floor_arbitration(std::int64_t t_ns, fusion::FixOutcome outcome,
                                       fusion::FixOutcome twin_outcome, bool guided);
  // The frame's prior-free fix, counted (refusals by status), and the share of its covariance
  // that other frames of the same landmarks repeat; true when OK.
  bool rack_fix(std::span<const RackObservation> obs, ranging::FixResult* fix,
                Eigen::Matrix3d* systematic_cov);
  // The OK fix into the run of consecutive agreeing ones; true when the run may initialise:
  // init_fixes long and within init_position_sd_mm (rack_candidate_.fix is the pose).
  bool count_rack_fix(std::int64_t t_ns, const ranging::FixResult& fix,
                      const Eigen::Matrix3d& systematic_cov);
  // The run's pose carried to t_ns by the newest odometry, and the motion's doubt.
  void carry_rack_candidate(std::int64_t t_ns, Eigen::Vector3d* pose, Eigen::Matrix3d* Q) const;
  // The fix agrees with the run's pose carried to t_ns.
  bool rack_fix_agrees(std::int64_t t_ns, const ranging::FixResult& fix) const;
  // The fix stacked onto the run (stack_fixes).
  void stack_rack_fix(std::int64_t t_ns, const ranging::FixResult& fix,
                      const Eigen::Matrix3d& systematic_cov);

  LocalizerConfig cfg_;
  fusion::Ekf ekf_;
  std::optional<fusion::Ekf> floor_twin_;  // RangingAidConfig::floor_check
  bool rack_since_floor_fix_ = false;  // rack updates or a rack initialisation since a floor fix
  int floor_conflict_streak_ = 0;      // floor fixes in a row gated here, fused by the twin
  std::int64_t rack_suspended_until_ns_ = INT64_MIN;
  std::int64_t rack_probation_until_ns_ = INT64_MIN;  // a floor fix overruled the rack aid
  protocol::OdometryDecoder odom_;
  protocol::GyroDecoder gyro_;
  std::int64_t last_odom_ns_ = INT64_MIN;
  std::int64_t last_gyro_ns_ = INT64_MIN;
  std::uint64_t odom_rejected_seen_ = 0;
  std::uint64_t gyro_rejected_seen_ = 0;  // gyro decoder rejections up to the last status frame
  std::int64_t next_heartbeat_ns_ = INT64_MIN;
  std::int64_t first_tick_ns_ = INT64_MIN;
  std::int64_t last_frame_ns_ = INT64_MIN;
  std::uint16_t last_landmark_id_ = 0;
  bool last_landmark_valid_ = false;  // a fix accepted since start: id 0 is a tag, not "none"
  std::uint8_t rejections_ = 0;       // reject::* since the last status frame
  bool map_guided_fused_ = false;     // since the last quality frame
  bool camera_eos_ = false;
  bool camera_error_ = false;
  bool overrun_ = false;
  bool have_can_state_ = false;
  hal::CanBusState can_state_ = hal::CanBusState::kErrorActive;
  hal::CanStats can_stats_;
  std::int64_t pending_e2e_exposure_ns_ = INT64_MIN;  // newest fused fix not yet sent
  CanFaultMonitor can_faults_;  // latches bus-off / passive / drops between status frames
  std::uint64_t fixes_exposed_after_arrival_ = 0;  // refused before the EKF
  OperatorPoseCounts operator_poses_;
  OperatorPoseCounts rack_poses_;  // EKF initialisations made from rack fixes
  // The consecutive agreeing OK rack fixes while not tracking (or tracking with every landmark
  // gated and a heading step): how many, stacked into fix (the newest alone without
  // stack_fixes), whose covariance is own_cov (the frames' own shares, averaged) plus
  // systematic_cov (the newest frame's repeated share).
  struct RackCandidate {
    int count = 0;
    std::int64_t t_ns = 0;
    ranging::FixResult fix;
    Eigen::Matrix3d own_cov = Eigen::Matrix3d::Zero();
    Eigen::Matrix3d systematic_cov = Eigen::Matrix3d::Zero();
  };
  RackCandidate rack_candidate_;
  double last_v_mps_ = 0.0;  // newest accepted odometry, corrected (carries rack fixes)
  double last_omega_radps_ = 0.0;
  OutputStats stats_;
};

// The receive filters a configuration needs (Localizer::receive_filters; `agvloc record` sets
// the same ones without a localizer): one per enabled input message of the signal table.
int receive_filters(const protocol::ProtocolConfig& cfg, hal::CanFilter* out, int max);

}  // namespace agv::localizer
