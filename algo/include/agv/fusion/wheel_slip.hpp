// State of the fusion EKF's wheel-slip detectors (aid_wheel_slip.cpp), kept with every event of
// the filter's history so that a replay after a delayed input re-runs them from where they were:
//  - with a gyro: a run of periods whose wheel/gyro yaw-rate difference is a slip under the flag
//    threshold (SlipRun), and whether the period slipped beyond it;
//  - wheels only: the slipping wheel held at its reading before the step (WheelHold).
#pragma once

#include <cstdint>
#include <limits>

namespace agv::fusion {

// No time: no odometry kept, no slip run going.
inline constexpr std::int64_t kNoTimeNs = std::numeric_limits<std::int64_t>::min();

// A run of odometry periods whose wheel/gyro yaw-rate difference is a slip under the flag
// threshold (SlipConfig::noise_sigmas): what it may have integrated and which way it went.
struct SlipRun {
  double sigma_m = 0.0;  // speed-error sigma integrated since the run began or the last fix
  double llr = 0.0;      // log likelihood ratio spin : lock from the speed reading's steps
  double u_mps = 0.0;    // speed equivalent of the difference in the run's newest period
};

// Wheels only: a wheel whose reading stepped beyond the vehicle's limits (a slip), read less
// the step until it steps back (SlipConfig::wheel_step_min_mps).
struct WheelHold {
  int wheel = -1;           // -1 none, 0 left, 1 right
  double offset_mps = 0.0;  // the step, taken off the wheel's readings while held
  std::int64_t since_ns = kNoTimeNs;
  double sigma_rad = 0.0;  // heading sigma the hold has added so far
  // Held wheel less the step, minus the other wheel, at the onset; and its change since
  // (what the slip's size or the yaw rate changed by while held: which, the wheels cannot say).
  double diff0_mps = 0.0;
  double drift_mps = 0.0;
  // After a hold ended by the wheel stepping back: that period's time, wheel and step. A slip
  // that ends inside a period steps back over two; the second step is not a new slip.
  std::int64_t released_ns = kNoTimeNs;
  int released_wheel = -1;
  double released_step_mps = 0.0;
  // Both wheels' steps in this period (a slip that began inside the previous period showed
  // part of itself there, under the limit).
  double step_mps[2] = {0.0, 0.0};
};

// The detectors' state after one event of the history.
struct SlipState {
  bool slipping = false;              // the wheels slipped in the period ending here
  std::int64_t since_ns = kNoTimeNs;  // start of the current run of slip periods
  // The current run of wheel/gyro differences beyond SlipConfig::noise_sigmas (kept over a fix).
  SlipRun run;
  // Newest raw odometry speed at or before this event (NaN: none since the initialisation).
  double v_read_mps = std::numeric_limits<double>::quiet_NaN();
  double omega_read_radps = std::numeric_limits<double>::quiet_NaN();  // the same, yaw rate
  WheelHold hold;  // wheels only: the slipping wheel held at this event

  // What a measurement event (a fix, a range-bearing observation) takes over from the event
  // before it: a measurement saw what a slip run had integrated so far; the slip itself (its
  // sign, its last speed equivalent, a held wheel) and the newest readings go on to the next
  // period.
  static SlipState after_measurement(const SlipState& prev) {
    SlipState s;
    s.run = prev.run;
    s.run.sigma_m = 0.0;
    s.v_read_mps = prev.v_read_mps;
    s.omega_read_radps = prev.omega_read_radps;
    s.hold = prev.hold;
    return s;
  }
};

}  // namespace agv::fusion
