// Simulated vehicle motion and odometry: pure functions of time (t_ns since the trajectory
// start). Models and defaults: docs/design/simulator.md.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "agv/common/geometry.hpp"

namespace agv::sim {

// A closed path made of straight segments and circular arcs, driven by a differential-drive
// vehicle at constant speed after a smooth start. Closed so any duration works (it loops).
enum class TrajectoryKind {
  kLine,       // back and forth along the first landmark row: stadium loop over rows 0 and 1
  kSquare,     // rounded square around the landmark grid (straights + 90 degree turns)
  kCircle,     // circle through grid landmarks
  kFigure8,    // two tangent circles; crosses the grid centre
  kLawnmower,  // boustrophedon over `rows` landmark rows, then back to the start
  // Vehicle calibration drive (agvloc-desk calibrate vehicle, docs/design/simulator.md): over the
  // first 2-4 landmarks of row 0, stop over each landmark; turn on the spot +360 deg at the first,
  // +-90 and back at the others, 180 at the last, drive back stopping over each, 180 at the
  // first, repeat. Trapezoid profiles (speed_mps, max(accel, 1.5 m/s^2); 0.8 rad/s, 3 rad/s^2)
  // and a 0.3 s pause after every move, so speed changes happen with a landmark in view.
  kCalibration,
};

// Parses "line", "square", "circle", "figure8", "lawnmower", "calibration". False for anything
// else.
bool parse_trajectory_kind(const std::string& name, TrajectoryKind* out);
const char* to_string(TrajectoryKind k);

struct TrajectoryParams {
  TrajectoryKind kind = TrajectoryKind::kLine;
  // Where the path lies: it is laid out over a landmark grid with this origin (world mm),
  // spacing and size (the default map tools/maps/default_grid.csv: 5x5 at 1 m from (0,0)).
  Vec2 grid_origin_mm{0.0, 0.0};
  double grid_spacing_mm = 1000.0;
  int grid_columns = 5;
  int grid_rows = 5;
  int lawnmower_rows = 4;   // even, so the return leg closes the loop on the start side
  double lead_mm = 500.0;   // straight run before the first / after the last landmark of a row
  double speed_mps = 0.5;   // cruise speed
  double accel_mps2 = 0.5;  // start from rest with this acceleration
  // Lateral offset of the whole path (mm, to the vehicle's left at the start) so the camera does
  // not pass exactly over every landmark centre.
  double lateral_offset_mm = 20.0;
};

struct Segment {
  double length_mm = 0.0;
  double curvature_per_mm = 0.0;  // 0 straight, +1/R left (counter-clockwise), -1/R right
};

// One move of a timed program (kCalibration): a straight drive or a turn on the spot with a
// trapezoid rate profile, then a pause.
struct Move {
  bool rotate = false;
  double amount = 0.0;  // mm (>= 0) or rad (signed)
  double peak = 0.0, accel = 0.0, ramp_s = 0.0, cruise_s = 0.0, pause_s = 0.0;
  double duration_s() const { return 2.0 * ramp_s + cruise_s + pause_s; }
};

struct Trajectory {
  TrajectoryParams params;
  // kCalibration: moves[0] is the lead-in, moves[1..] the block repeated for ever.
  std::vector<Move> moves;
  std::vector<double> move_start_t_s, move_start_s_mm;
  std::vector<Pose2> move_start_pose;
  double block_duration_s = 0.0, block_length_mm = 0.0;
  Pose2 start;  // world pose at s = 0
  std::vector<Segment> segments;
  std::vector<double> seg_start_s_mm;
  std::vector<Pose2> seg_start_pose;
  double length_mm = 0.0;         // one lap
  double closure_error_mm = 0.0;  // end pose vs start pose of one lap (0 for a closed path)
};

// False with *error for invalid parameters (non-positive speed, odd lawnmower rows, ...).
bool make_trajectory(const TrajectoryParams& p, Trajectory* out, std::string* error);

struct MotionState {
  Pose2 pose;                // world <- vehicle
  double v_mps = 0.0;        // true forward speed
  double omega_radps = 0.0;  // true yaw rate
  double s_mm = 0.0;         // distance travelled
};

// True state at t_ns >= 0 after the start (t < 0 = standing at the start pose).
MotionState trajectory_state(const Trajectory& tr, std::int64_t t_ns);

// What one odometry sample at t_ns stands for. Motor controllers count encoder ticks per period,
// so a sample is the mean speed over the period ending at t_ns (kPeriodMean, the default and what
// the fusion assumes); kInstant is the true speed at t_ns (a controller that differentiates a
// filtered position, or the simulator's first odometry model). They differ only where v or omega
// changes within a period: at the start ramp and at every arc entry/exit (an omega step).
enum class OdomSampleTiming { kPeriodMean, kInstant };

// Parses "period_mean", "instant". False for anything else.
bool parse_odom_sample_timing(const std::string& name, OdomSampleTiming* out);
const char* to_string(OdomSampleTiming t);

// Odometry as the motor controllers report it: wheel-speed based, with a constant scale error
// per wheel, white noise, and occasional slip (one wheel reports more than it moved).
struct OdometryParams {
  OdomSampleTiming timing = OdomSampleTiming::kPeriodMean;
  std::int64_t period_ns = 10'000'000;  // sample period (the mean is over [t - period, t])
  double wheelbase_mm = 500.0;          // track width used to convert wheel speeds to v and omega
  double scale_error = 0.01;            // both wheels report this much too much (1 %)
  double scale_asymmetry = 0.004;       // right minus left scale error (makes straight runs curve)
  double noise_mps = 0.003;             // white noise per wheel speed sample (sigma)
  double slip_rate_per_s = 0.02;        // mean slip events per second (Poisson)
  double slip_duration_s = 0.3;
  double slip_excess = 0.05;  // the slipping wheel reports this fraction more than it moved
  // Yaw-rate errors beyond the wheels' (a gyro-fused controller; vehicle calibration tests):
  // reported omega = (1 + yaw_rate_scale_error) * wheel omega + yaw_rate_bias_radps.
  double yaw_rate_scale_error = 0.0;
  double yaw_rate_bias_radps = 0.0;
  std::uint64_t seed = 1;
};

struct SlipEvent {
  std::int64_t t_start_ns = 0;
  std::int64_t t_end_ns = 0;
  bool right_wheel = false;
};

// Slip events over [0, duration_ns), deterministic for params.seed.
std::vector<SlipEvent> make_slip_events(const OdometryParams& p, std::int64_t duration_ns);

struct OdometrySample {
  double v_mps = 0.0;
  double omega_radps = 0.0;
};

// The true v and omega a sample at t_ns stands for (p.timing): the state's own speeds at t_ns
// (kInstant), or distance travelled and heading turned over [t_ns - p.period_ns, t_ns] divided by
// the period (kPeriodMean; exact, from trajectory_state at both ends). No errors.
OdometrySample true_odometry(const OdometryParams& p, const Trajectory& tr, std::int64_t t_ns);

// Reported odometry given the true speeds `truth` of the sample at t_ns: per-wheel scale errors,
// noise and slip applied to the wheel speeds. A pure function of (params, slips, truth, t_ns);
// the noise is a hash of (seed, t_ns), so the same time always gives the same sample.
OdometrySample odometry_sample(const OdometryParams& p, const std::vector<SlipEvent>& slips,
                               const OdometrySample& truth, std::int64_t t_ns);

// The sample the controllers send at t_ns: odometry_sample(true_odometry(p, tr, t_ns)).
OdometrySample odometry_sample(const OdometryParams& p, const std::vector<SlipEvent>& slips,
                               const Trajectory& tr, std::int64_t t_ns);

}  // namespace agv::sim
