// Fleet simulator: N vehicles on one site, each working a queue of tasks (drive to a pick point,
// dwell, drive to a drop point, dwell), routed by the site's route planner and kept apart by a
// reservation table of floor cells (first come, first served). Pure: simulated time only, no
// clocks, no files. Every vehicle's truth, odometry and gyro come out as the single-vehicle
// simulator writes them, so each can be stored as a recording. Method, guarantees and what it
// does not solve: docs/design/fleet_sim.md.
#pragma once

#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include "agv/common/geometry.hpp"
#include "agv/sim/imu_model.hpp"
#include "agv/sim/trajectory.hpp"
#include "agv/site/planner.hpp"
#include "agv/site/site.hpp"

namespace agv::sim {

struct FleetTask {
  Vec2 pick_mm;
  Vec2 drop_mm;
};

struct FleetVehicleSpec {
  std::string id;
  double radius_mm = 400.0;      // bounds the footprint; the clearance is kept beyond it
  Pose2 start;                   // site <- vehicle at t = 0, at rest
  std::vector<FleetTask> tasks;  // worked in order
};

struct FleetParams {
  double duration_s = 60.0;
  // One simulation step; also the gyro's sample period (its rate_hz is set from it).
  std::int64_t step_ns = 5'000'000;
  int odom_every_steps = 2;  // odometry and truth every this many steps (10 ms by default)
  // Kept between two vehicles beyond r_i + r_j (centre to centre >= r_i + r_j + clearance);
  // negative: the site's clearance_mm.
  double clearance_mm = -1.0;
  double cell_mm = 250.0;       // reservation cell side
  double path_step_mm = 50.0;   // spacing of the reserved points along a route
  double lookahead_mm = 500.0;  // reserved beyond the stopping distance at full speed
  // How far beyond its reserved run a vehicle's way counts as needed (no other vehicle stops on
  // it): longer avoids more deadlocks, but makes vehicles reserve longer runs.
  double plan_horizon_mm = 6000.0;
  double dwell_s = 2.0;          // standing at a pick or drop point
  double turn_rate_radps = 0.8;  // turning on the spot before a route starts
  site::DriveLimits drive;
  // A vehicle stopped for longer than this on a wait that leads back to itself (a cycle) or to a
  // vehicle with nothing left to do is reported and the blockage resolved (fleet_sim.md).
  double deadlock_after_s = 3.0;
  OdometryParams odometry;  // seed replaced per vehicle; period_ns = step * odom_every_steps
  GyroParams gyro;          // seed replaced per vehicle; rate from step_ns
  bool gyro_enabled = true;
  std::uint64_t seed = 1;  // per-vehicle sensor seeds derive from it
  // Keep truth, odometry and gyro samples (off: counts and statistics only, for a benchmark).
  bool keep_samples = true;
};

struct FleetTruthSample {
  std::int64_t t_ns = 0;
  Pose2 pose;
  double v_mps = 0.0;
  double omega_radps = 0.0;
};

struct FleetOdomSample {
  std::int64_t t_ns = 0;
  double v_mps = 0.0;
  double omega_radps = 0.0;
};

struct FleetVehicleOutput {
  std::vector<FleetTruthSample> truth;  // every odometry period, t_ns from 0
  std::vector<FleetOdomSample> odom;    // same times
  std::vector<ImuSample> gyro;          // every step (stamp includes the gyro latency)
  std::size_t slip_events = 0;
  double distance_mm = 0.0;
  double wait_s = 0.0;  // stopped because a cell ahead was held by another vehicle
  int waits = 0;        // distinct stops of that kind
  int evasions = 0;     // times it drove aside to resolve a blockage
};

struct FleetTaskRecord {
  int vehicle = 0;
  int index = 0;  // position in the vehicle's queue
  FleetTask task;
  double start_s = -1.0;   // left for the pick point
  double picked_s = -1.0;  // pick dwell over
  double finish_s = -1.0;  // drop dwell over; -1: not finished
  std::string error;       // why it was dropped (no route, no trajectory); empty otherwise
};

enum class FleetEventKind : std::uint8_t {
  kDeadlock,       // vehicles waiting on each other in a cycle
  kBlockedByIdle,  // waiting on a vehicle that has nothing left to do
  kEvade,          // a vehicle drives aside to resolve one of the above
  kUnresolved,     // no vehicle of the blockage found a place to drive aside to
  kTaskDropped,    // a leg could not be routed or driven
};
const char* to_string(FleetEventKind k);

struct FleetEvent {
  double t_s = 0.0;
  FleetEventKind kind = FleetEventKind::kDeadlock;
  std::vector<int> vehicles;
  std::string text;
};

struct FleetResult {
  std::vector<FleetVehicleOutput> vehicles;
  std::vector<FleetTaskRecord> tasks;
  std::vector<FleetEvent> events;
  std::int64_t steps = 0;
  double simulated_s = 0.0;
  // Over every step and every pair: the smallest centre distance, and the smallest margin
  // distance - (r_i + r_j + clearance) (never negative when the reservation holds).
  double min_pair_distance_mm = 0.0;
  double min_pair_margin_mm = 0.0;
  double clearance_mm = 0.0;
  int tasks_finished = 0;
  int deadlocks = 0;
  int blocked_by_idle = 0;
  int unresolved = 0;
};

// Called after every step with the time and every vehicle's pose (tests check every pair).
using FleetStepObserver = std::function<void(std::int64_t t_ns, const std::vector<Pose2>& poses)>;

// Runs the fleet for params.duration_s. The planner must have been built for the fleet's largest
// radius (route_planner_for_fleet). False with *error for bad input: no vehicle, a non-positive
// radius, a start or task point that is not free for the planner, two starts whose reserved
// cells overlap, invalid parameters. Runtime trouble (a leg that cannot be routed, a deadlock)
// is not an error: it is in out->events and the task records.
bool simulate_fleet(const site::Site& site, const site::RoutePlanner& planner,
                    const std::vector<FleetVehicleSpec>& vehicles, const FleetParams& params,
                    FleetResult* out, std::string* error,
                    const FleetStepObserver& observer = nullptr);

// The planner for a fleet: the site's obstacles inflated by the largest radius plus the site's
// clearance. False with *error when the site cannot be inflated or radii are not positive.
bool route_planner_for_fleet(const site::Site& site, const std::vector<double>& radii_mm,
                             site::RoutePlanner* out, std::string* error);

// A random fleet on a site: vehicles with the given radii at free, reachable start points far
// enough apart, each with tasks_per_vehicle tasks between free points reachable from every
// start (pick and drop at least min_leg_mm apart). Deterministic for seed. False with *error
// when the site has too little free room to place them.
bool make_random_fleet(const site::RoutePlanner& planner, const site::Site& site,
                       const std::vector<double>& radii_mm, int tasks_per_vehicle,
                       std::uint64_t seed, std::vector<FleetVehicleSpec>* out, std::string* error,
                       double min_leg_mm = 3000.0);

}  // namespace agv::sim
