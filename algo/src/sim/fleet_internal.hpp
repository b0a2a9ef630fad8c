// Internals of the fleet simulator (algo/include/agv/sim/fleet.hpp), shared by its source files.
#pragma once

#include <cstdint>
#include <random>
#include <string>
#include <vector>

#include "agv/sim/fleet.hpp"

namespace agv::sim::fleet_internal {

// The reservation table: the site's bounding box cut into square cells, each free (-1) or held by
// one vehicle. A vehicle may hold a cell through several of its reserved points; count is how
// many, so the cell is released with the last of them.
class CellGrid {
 public:
  void init(double min_x_mm, double min_y_mm, double max_x_mm, double max_y_mm, double cell_mm);
  // Appends the cells whose square lies within r_mm of p (closed): a disc of radius r_mm at p
  // lies inside them.
  void cells_near(Vec2 p_mm, double r_mm, std::vector<int>* out) const;
  // The vehicle holding one of the cells other than `vehicle`, or -1.
  int blocker(int vehicle, const int* cells, std::size_t n) const;
  void acquire(int vehicle, const int* cells, std::size_t n);
  void release(int vehicle, const int* cells, std::size_t n);
  int owner(int cell) const { return owner_[static_cast<std::size_t>(cell)]; }
  std::size_t size() const { return owner_.size(); }
  double cell_mm() const { return cell_mm_; }

 private:
  double x0_ = 0.0, y0_ = 0.0, cell_mm_ = 250.0;
  int nx_ = 0, ny_ = 0;
  std::vector<int> owner_;
  std::vector<int> count_;
};

// One drive along a route: the trajectory and its reserved points (every sample of the
// trajectory at most path_step_mm apart along the path, with the cells each needs).
struct Leg {
  site::RouteTrajectory traj;
  std::vector<double> sample_s_mm;
  std::vector<float> sample_theta_rad;
  std::vector<std::uint32_t> cell_begin;  // sample k's cells: cells[cell_begin[k], cell_begin[k+1])
  std::vector<int> cells;
  int lo = 0, hi = -1;  // reserved samples [lo, hi]
  int plan_hi = -1;     // samples (hi, plan_hi] are on the plan layer
  double tau_s = 0.0;   // trajectory time reached
  double s_mm = 0.0;    // path length reached
  double alpha = 0.0;   // rate of trajectory time per simulated time (0 stopped .. 1 as planned)
  std::size_t samples() const { return sample_s_mm.size(); }
  const int* cells_of(int k) const {
    return cells.data() + cell_begin[static_cast<std::size_t>(k)];
  }
  std::size_t count_of(int k) const {
    const auto i = static_cast<std::size_t>(k);
    return cell_begin[i + 1] - cell_begin[i];
  }
};

enum class Phase : std::uint8_t { kParked, kTurn, kDrive, kDwell };
enum class Stage : std::uint8_t { kToPick, kToDrop, kDone };
enum class LegKind : std::uint8_t { kTask, kEvade };

// A yaw-rate gyro fed with the true mean rate of each step (the error model of simulate_gyro,
// imu_model.hpp, with the same streams).
class GyroStream {
 public:
  void init(const GyroParams& p, std::int64_t period_ns);
  ImuSample sample(std::int64_t t_ns, double true_rate_radps);

 private:
  GyroParams p_;
  std::mt19937_64 white_rng_, markov_rng_, walk_rng_;
  std::normal_distribution<double> n01_{0.0, 1.0};
  double white_sigma_ = 0.0, phi_ = 0.0, markov_step_ = 0.0, walk_step_ = 0.0;
  double markov_ = 0.0, walk_ = 0.0;
  bool first_ = true;
};

struct Vehicle {
  int index = 0;
  double radius_mm = 0.0;
  double reserve_mm = 0.0;  // radius + clearance / 2 + path_step / 2: what a reserved point covers
  Pose2 pose;
  double v_mps = 0.0, omega_radps = 0.0;
  double theta_unwrapped_rad = 0.0, s_total_mm = 0.0;  // for period-mean odometry and gyro
  double odom_theta_rad = 0.0, odom_s_mm = 0.0;        // at the previous odometry sample
  double gyro_theta_rad = 0.0;                         // at the previous step
  Phase phase = Phase::kParked;
  Stage stage = Stage::kDone;
  int task = 0;          // index into its queue
  int task_record = -1;  // index into FleetResult::tasks of the current task
  double dwell_end_s = 0.0;
  std::vector<int> base_cells;  // held while not on a leg
  bool has_leg = false;
  LegKind leg_kind = LegKind::kTask;
  Leg leg;
  double turn_target_rad = 0.0;
  // Traffic: blocked = the next reserved point is held by waits_on.
  bool blocked = false;
  int waits_on = -1;
  double stopped_s = 0.0;  // how long it has stood blocked
  bool reported = false;   // its current blockage has been reported
  double retry_s = 0.0;    // no new resolution attempt before this time
  // Blocked since (1e300 when not): the longer-blocked vehicle has the first claim on the cells
  // of its blocked run (requested), so that passing traffic cannot starve it.
  double wait_since_s = 1e300;
  std::vector<int> requested;
  std::vector<SlipEvent> slips;
  OdometryParams odom;
  GyroStream gyro;
};

class FleetSim {
 public:
  FleetSim(const site::Site& site, const site::RoutePlanner& planner,
           const std::vector<FleetVehicleSpec>& specs, const FleetParams& params, FleetResult* out);
  bool init(std::string* error);
  void run(const FleetStepObserver& observer);

 private:
  // fleet.cpp
  void step_vehicle(Vehicle& v);
  void advance_stage(Vehicle& v);
  void check_pairs(const FleetStepObserver& observer);
  void record_sensors(Vehicle& v, std::int64_t step);
  void event(FleetEventKind kind, std::vector<int> vehicles, std::string text);
  // fleet_traffic.cpp
  bool build_leg(const Vehicle& v, Vec2 goal_mm, Leg* leg, std::string* why,
                 double max_length_mm = 1e300) const;
  void start_task_leg(Vehicle& v);
  void release_holdings(Vehicle& v);
  void drive_step(Vehicle& v);
  void turn_step(Vehicle& v);
  void arrive(Vehicle& v);
  void extend_reservation(Vehicle& v);
  // The cells other vehicles will need later (their legs' points not yet reserved): a vehicle
  // stops nowhere on them, so it never stands in the way of a vehicle yet to come.
  void plan_change(const Vehicle& v, const Leg& leg, int k0, int k1, int delta);
  void extend_plan(const Vehicle& v, Leg& leg);
  bool on_others_plan(const Vehicle& v, const Leg& leg, int k) const;
  int run_blocker(const Vehicle& v, const Leg& leg, int k, int m) const;
  void place_requests(Vehicle& v, const Leg& leg, int k, int m);
  void clear_requests(Vehicle& v);
  // fleet_resolve.cpp
  void resolve_blockages();
  bool waiting(const Vehicle& v) const;
  bool idle(const Vehicle& v) const { return v.stage == Stage::kDone && v.phase == Phase::kParked; }
  // False when no member could drive aside.
  bool handle_blockage(const std::vector<int>& members, bool cycle);
  bool try_evade(Vehicle& y, const Vehicle* x);
  // Drives y to the nearest refuge (distance, point) whose cells are free and unmarked in mark_.
  bool evade_to_refuge(Vehicle& y, const std::vector<std::pair<double, Vec2>>& refuges);
  void remaining_cells(const Vehicle& x, std::vector<std::uint8_t>* mark) const;

  const site::Site& site_;
  const site::RoutePlanner& planner_;
  const std::vector<FleetVehicleSpec>& specs_;
  FleetParams p_;
  FleetResult* out_;
  CellGrid grid_;
  std::vector<Vehicle> vehicles_;
  std::vector<int> scratch_;
  std::vector<std::uint8_t> mark_;
  std::vector<std::uint16_t> plan_own_;   // per vehicle and cell
  std::vector<std::uint8_t> plan_dir_;    // per vehicle and cell: heading there, 256 steps a turn
  std::vector<std::int32_t> plan_total_;  // per cell
  std::vector<int> request_;              // per cell: the vehicle with the first claim, or -1
  std::vector<Pose2> poses_;
  double t_s_ = 0.0, dt_s_ = 0.0;
  std::int64_t step_ = 0;
  std::int64_t duration_ns_ = 0;
};

}  // namespace agv::sim::fleet_internal
