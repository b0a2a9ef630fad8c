// The fleet simulator's driver: set-up, the step loop, task stages, the pair check and the
// sensors of every vehicle (docs/design/fleet_sim.md).
#include "agv/sim/fleet.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

#include "fleet_internal.hpp"

namespace agv::sim {

const char* to_string(FleetEventKind k) {
  switch (k) {
    case FleetEventKind::kDeadlock:
      return "deadlock";
    case FleetEventKind::kBlockedByIdle:
      return "blocked_by_idle";
    case FleetEventKind::kEvade:
      return "evade";
    case FleetEventKind::kUnresolved:
      return "unresolved";
    case FleetEventKind::kTaskDropped:
      return "task_dropped";
  }
  return "?";
}

namespace fleet_internal {

namespace {

std::uint64_t fleet_mix_seed(std::uint64_t seed, std::uint64_t stream) {
  std::uint64_t x = seed * 0x9E3779B97F4A7C15ULL + stream * 0xBF58476D1CE4E5B9ULL + 0x1234567ULL;
  x = (x ^ (x >> 30)) * 0xbf58476d1ce4e5b9ULL;
  x = (x ^ (x >> 27)) * 0x94d049bb133111ebULL;
  return x ^ (x >> 31);
}

bool fleet_positive(double x) { return std::isfinite(x) && x > 0.0; }

bool fleet_check_params(const FleetParams& p, std::string* error) {
  auto fail = [&](const char* why) {
    *error = why;
    return false;
  };
  if (!(fleet_positive(p.duration_s) && p.duration_s <= 86400.0)) {
    return fail("duration_s must be in (0, 86400]");
  }
  if (p.step_ns < 1'000'000 || p.step_ns > 100'000'000) {
    return fail("step_ns must be in [1 ms, 100 ms]");
  }
  if (p.odom_every_steps < 1 || p.odom_every_steps > 100) {
    return fail("odom_every_steps must be in [1, 100]");
  }
  if (!std::isfinite(p.clearance_mm)) return fail("clearance_mm must be finite");
  if (!(p.cell_mm >= 20.0 && p.cell_mm <= 5000.0)) return fail("cell_mm must be in [20, 5000]");
  if (!(p.path_step_mm >= 1.0 && p.path_step_mm <= p.cell_mm)) {
    return fail("path_step_mm must be in [1, cell_mm]");
  }
  if (!(p.lookahead_mm >= 0.0 && p.lookahead_mm <= 1e6)) return fail("lookahead_mm out of range");
  if (!(p.plan_horizon_mm >= 0.0 && p.plan_horizon_mm <= 1e7)) {
    return fail("plan_horizon_mm out of range");
  }
  if (!(p.dwell_s >= 0.0 && p.dwell_s <= 3600.0)) return fail("dwell_s must be in [0, 3600]");
  if (!(fleet_positive(p.turn_rate_radps) && p.turn_rate_radps <= 20.0)) {
    return fail("turn_rate_radps must be in (0, 20]");
  }
  if (!fleet_positive(p.drive.speed_mps) || !fleet_positive(p.drive.accel_mps2) ||
      !fleet_positive(p.drive.lateral_accel_mps2) ||
      !fleet_positive(p.drive.max_curvature_per_mm) || !(p.drive.clothoid_length_mm >= 0.0)) {
    return fail("drive limits must be positive and finite");
  }
  if (!fleet_positive(p.deadlock_after_s)) return fail("deadlock_after_s must be > 0");
  if (p.gyro_enabled && !check_gyro_params(p.gyro, error)) return false;
  return true;
}

}  // namespace

FleetSim::FleetSim(const site::Site& site, const site::RoutePlanner& planner,
                   const std::vector<FleetVehicleSpec>& specs, const FleetParams& params,
                   FleetResult* out)
    : site_(site), planner_(planner), specs_(specs), p_(params), out_(out) {}

bool FleetSim::init(std::string* error) {
  if (!fleet_check_params(p_, error)) return false;
  if (specs_.empty()) return (*error = "no vehicles", false);
  if (specs_.size() > 10000) return (*error = "more than 10000 vehicles", false);
  if (site_.outline.vertices_mm.size() < 3) return (*error = "the site has no outline", false);
  if (p_.clearance_mm < 0.0) p_.clearance_mm = std::max(0.0, site_.clearance_mm);
  dt_s_ = static_cast<double>(p_.step_ns) * 1e-9;
  duration_ns_ = static_cast<std::int64_t>(std::llround(p_.duration_s * 1e9));
  double max_reserve = 0.0;
  double lo_x = 1e300, lo_y = 1e300, hi_x = -1e300, hi_y = -1e300;
  for (const Vec2& q : site_.outline.vertices_mm) {
    lo_x = std::min(lo_x, q.x), lo_y = std::min(lo_y, q.y);
    hi_x = std::max(hi_x, q.x), hi_y = std::max(hi_y, q.y);
  }
  for (std::size_t i = 0; i < specs_.size(); ++i) {
    const FleetVehicleSpec& s = specs_[i];
    const std::string name =
        "vehicle " + std::to_string(i) + (s.id.empty() ? "" : " (" + s.id + ")");
    if (!(fleet_positive(s.radius_mm) && s.radius_mm < 1e5)) {
      return (*error = name + ": radius_mm must be positive", false);
    }
    const Vec2 start{s.start.x_mm, s.start.y_mm};
    if (!std::isfinite(s.start.theta_rad) || !planner_.point_free(start)) {
      return (*error = name + ": start (" + std::to_string(start.x) + ", " +
                       std::to_string(start.y) + ") mm is not free for the planner",
              false);
    }
    for (std::size_t k = 0; k < s.tasks.size(); ++k) {
      if (!planner_.point_free(s.tasks[k].pick_mm) || !planner_.point_free(s.tasks[k].drop_mm)) {
        return (*error = name + ": task " + std::to_string(k) +
                         ": a pick or drop point is not free for the planner",
                false);
      }
    }
    max_reserve = std::max(max_reserve, s.radius_mm + 0.5 * p_.clearance_mm + p_.path_step_mm);
  }
  const double m = max_reserve + 2.0 * p_.cell_mm;
  if ((hi_x - lo_x) / p_.cell_mm * (hi_y - lo_y) / p_.cell_mm > 5e7) {
    return (*error = "the site is too large for cells of " + std::to_string(p_.cell_mm) + " mm",
            false);
  }
  grid_.init(lo_x - m, lo_y - m, hi_x + m, hi_y + m, p_.cell_mm);
  if (static_cast<double>(grid_.size()) * static_cast<double>(specs_.size()) > 2e8) {
    return (*error = "too many vehicles for a site this large with cells of " +
                     std::to_string(p_.cell_mm) + " mm",
            false);
  }
  mark_.assign(grid_.size(), 0);
  plan_own_.assign(grid_.size() * specs_.size(), 0);
  plan_dir_.assign(grid_.size() * specs_.size(), 0);
  plan_total_.assign(grid_.size(), 0);
  request_.assign(grid_.size(), -1);

  *out_ = FleetResult{};
  out_->clearance_mm = p_.clearance_mm;
  out_->min_pair_distance_mm = std::numeric_limits<double>::infinity();
  out_->min_pair_margin_mm = std::numeric_limits<double>::infinity();
  out_->vehicles.resize(specs_.size());
  vehicles_.resize(specs_.size());
  const std::int64_t odom_period_ns = p_.step_ns * p_.odom_every_steps;
  for (std::size_t i = 0; i < specs_.size(); ++i) {
    const FleetVehicleSpec& s = specs_[i];
    Vehicle& v = vehicles_[i];
    v.index = static_cast<int>(i);
    v.radius_mm = s.radius_mm;
    v.reserve_mm = s.radius_mm + 0.5 * p_.clearance_mm + 0.5 * p_.path_step_mm;
    v.pose = {s.start.x_mm, s.start.y_mm, wrap_angle_rad(s.start.theta_rad)};
    v.theta_unwrapped_rad = v.odom_theta_rad = v.gyro_theta_rad = v.pose.theta_rad;
    grid_.cells_near({v.pose.x_mm, v.pose.y_mm}, v.reserve_mm, &v.base_cells);
    const int b = grid_.blocker(v.index, v.base_cells.data(), v.base_cells.size());
    if (b >= 0) {
      return (*error = "vehicles " + std::to_string(b) + " and " + std::to_string(i) +
                       " start too close together (their reserved cells overlap)",
              false);
    }
    grid_.acquire(v.index, v.base_cells.data(), v.base_cells.size());
    v.stage = s.tasks.empty() ? Stage::kDone : Stage::kToPick;
    v.odom = p_.odometry;
    v.odom.period_ns = odom_period_ns;
    v.odom.seed = fleet_mix_seed(p_.seed, 2 * i + 1);
    v.slips = make_slip_events(v.odom, duration_ns_ + odom_period_ns);
    out_->vehicles[i].slip_events = v.slips.size();
    GyroParams g = p_.gyro;
    g.seed = fleet_mix_seed(p_.seed, 2 * i + 2);
    v.gyro.init(g, p_.step_ns);
    for (std::size_t k = 0; k < s.tasks.size(); ++k) {
      FleetTaskRecord r;
      r.vehicle = static_cast<int>(i);
      r.index = static_cast<int>(k);
      r.task = s.tasks[k];
      if (k == 0) v.task_record = static_cast<int>(out_->tasks.size());
      out_->tasks.push_back(r);
    }
    if (p_.keep_samples) {
      const auto n = static_cast<std::size_t>(duration_ns_ / odom_period_ns) + 2;
      out_->vehicles[i].truth.reserve(n);
      out_->vehicles[i].odom.reserve(n);
      if (p_.gyro_enabled)
        out_->vehicles[i].gyro.reserve(n * static_cast<std::size_t>(p_.odom_every_steps));
    }
  }
  poses_.resize(vehicles_.size());
  return true;
}

void FleetSim::event(FleetEventKind kind, std::vector<int> vehicles, std::string text) {
  out_->events.push_back({t_s_, kind, std::move(vehicles), std::move(text)});
}

void FleetSim::advance_stage(Vehicle& v) {
  FleetTaskRecord& r = out_->tasks[static_cast<std::size_t>(v.task_record)];
  if (v.stage == Stage::kToPick) {
    r.picked_s = t_s_;
    v.stage = Stage::kToDrop;
    return;
  }
  if (v.stage == Stage::kToDrop && r.error.empty()) {
    r.finish_s = t_s_;
    ++out_->tasks_finished;
  }
  ++v.task;
  const auto& queue = specs_[static_cast<std::size_t>(v.index)].tasks;
  if (v.task < static_cast<int>(queue.size())) {
    ++v.task_record;
    v.stage = Stage::kToPick;
  } else {
    v.stage = Stage::kDone;
  }
}

void FleetSim::step_vehicle(Vehicle& v) {
  const double theta_before = v.pose.theta_rad;
  switch (v.phase) {
    case Phase::kParked:
      v.v_mps = v.omega_radps = 0.0;
      if (v.stage != Stage::kDone) start_task_leg(v);
      break;
    case Phase::kDwell:
      v.v_mps = v.omega_radps = 0.0;
      if (t_s_ + 1e-9 >= v.dwell_end_s) {
        advance_stage(v);
        v.phase = Phase::kParked;
      }
      break;
    case Phase::kTurn:
      turn_step(v);
      break;
    case Phase::kDrive:
      drive_step(v);
      break;
  }
  v.theta_unwrapped_rad += wrap_angle_rad(v.pose.theta_rad - theta_before);
  FleetVehicleOutput& o = out_->vehicles[static_cast<std::size_t>(v.index)];
  if (waiting(v)) {
    if (v.stopped_s == 0.0) ++o.waits;
    v.stopped_s += dt_s_;
    o.wait_s += dt_s_;
  } else {
    v.stopped_s = 0.0;
    v.reported = false;
  }
}

void FleetSim::check_pairs(const FleetStepObserver& observer) {
  const std::size_t n = vehicles_.size();
  for (std::size_t i = 0; i < n; ++i) poses_[i] = vehicles_[i].pose;
  for (std::size_t i = 0; i < n; ++i) {
    for (std::size_t j = i + 1; j < n; ++j) {
      const double d = std::hypot(poses_[i].x_mm - poses_[j].x_mm, poses_[i].y_mm - poses_[j].y_mm);
      out_->min_pair_distance_mm = std::min(out_->min_pair_distance_mm, d);
      const double need = vehicles_[i].radius_mm + vehicles_[j].radius_mm + p_.clearance_mm;
      out_->min_pair_margin_mm = std::min(out_->min_pair_margin_mm, d - need);
    }
  }
  if (observer) observer(static_cast<std::int64_t>(std::llround(t_s_ * 1e9)), poses_);
}

void FleetSim::record_sensors(Vehicle& v, std::int64_t step) {
  const std::int64_t t_ns = step * p_.step_ns;
  FleetVehicleOutput& o = out_->vehicles[static_cast<std::size_t>(v.index)];
  if (p_.gyro_enabled) {
    const double rate = (v.theta_unwrapped_rad - v.gyro_theta_rad) / dt_s_;
    v.gyro_theta_rad = v.theta_unwrapped_rad;
    const ImuSample g = v.gyro.sample(t_ns, step == 0 ? 0.0 : rate);
    if (p_.keep_samples) o.gyro.push_back(g);
  }
  if (step % p_.odom_every_steps != 0) return;
  OdometrySample truth{v.v_mps, v.omega_radps};
  if (v.odom.timing == OdomSampleTiming::kPeriodMean) {
    const double period_s = static_cast<double>(v.odom.period_ns) * 1e-9;
    truth = {(v.s_total_mm - v.odom_s_mm) * 1e-3 / period_s,
             (v.theta_unwrapped_rad - v.odom_theta_rad) / period_s};
  }
  v.odom_s_mm = v.s_total_mm;
  v.odom_theta_rad = v.theta_unwrapped_rad;
  if (!p_.keep_samples) return;
  const OdometrySample rep = odometry_sample(v.odom, v.slips, truth, t_ns);
  o.odom.push_back({t_ns, rep.v_mps, rep.omega_radps});
  o.truth.push_back({t_ns, v.pose, v.v_mps, v.omega_radps});
}

void FleetSim::run(const FleetStepObserver& observer) {
  const std::int64_t n_steps = duration_ns_ / p_.step_ns;
  t_s_ = 0.0;
  check_pairs(observer);
  for (Vehicle& v : vehicles_) record_sensors(v, 0);
  for (std::int64_t step = 1; step <= n_steps; ++step) {
    t_s_ = static_cast<double>(step) * dt_s_;
    step_ = step;
    for (Vehicle& v : vehicles_) step_vehicle(v);
    resolve_blockages();
    check_pairs(observer);
    for (Vehicle& v : vehicles_) record_sensors(v, step);
  }
  out_->steps = n_steps;
  out_->simulated_s = static_cast<double>(n_steps) * dt_s_;
  for (const Vehicle& v : vehicles_) {
    out_->vehicles[static_cast<std::size_t>(v.index)].distance_mm = v.s_total_mm;
  }
  if (vehicles_.size() < 2) out_->min_pair_distance_mm = out_->min_pair_margin_mm = 0.0;
}

}  // namespace fleet_internal

bool simulate_fleet(const site::Site& site, const site::RoutePlanner& planner,
                    const std::vector<FleetVehicleSpec>& vehicles, const FleetParams& params,
                    FleetResult* out, std::string* error, const FleetStepObserver& observer) {
  std::string local;
  if (!error) error = &local;
  if (!out) return (*error = "no result given", false);
  fleet_internal::FleetSim sim(site, planner, vehicles, params, out);
  if (!sim.init(error)) return false;
  sim.run(observer);
  return true;
}

}  // namespace agv::sim
