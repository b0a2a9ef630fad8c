// The fleet simulator's traffic rules: the cell reservation table, legs (a route, its trajectory
// and the cells each point of it needs), driving with reservation ahead and release behind
// (docs/design/fleet_sim.md "Traffic").
#include <algorithm>
#include <cmath>

#include "fleet_internal.hpp"

namespace agv::sim::fleet_internal {

void CellGrid::init(double min_x_mm, double min_y_mm, double max_x_mm, double max_y_mm,
                    double cell_mm) {
  cell_mm_ = cell_mm;
  x0_ = min_x_mm;
  y0_ = min_y_mm;
  nx_ = std::max(1, static_cast<int>(std::ceil((max_x_mm - min_x_mm) / cell_mm)));
  ny_ = std::max(1, static_cast<int>(std::ceil((max_y_mm - min_y_mm) / cell_mm)));
  const auto n = static_cast<std::size_t>(nx_) * static_cast<std::size_t>(ny_);
  owner_.assign(n, -1);
  count_.assign(n, 0);
}

void CellGrid::cells_near(Vec2 p, double r, std::vector<int>* out) const {
  auto clamp_index = [](double v, int n) {
    if (!(v > 0.0)) return 0;  // also NaN
    return std::min(n - 1, static_cast<int>(v));
  };
  const int ix0 = clamp_index(std::floor((p.x - r - x0_) / cell_mm_), nx_);
  const int ix1 = clamp_index(std::floor((p.x + r - x0_) / cell_mm_), nx_);
  const int iy0 = clamp_index(std::floor((p.y - r - y0_) / cell_mm_), ny_);
  const int iy1 = clamp_index(std::floor((p.y + r - y0_) / cell_mm_), ny_);
  const double r2 = r * r;
  for (int iy = iy0; iy <= iy1; ++iy) {
    const double cy0 = y0_ + iy * cell_mm_;
    const double dy = std::max({cy0 - p.y, 0.0, p.y - (cy0 + cell_mm_)});
    for (int ix = ix0; ix <= ix1; ++ix) {
      const double cx0 = x0_ + ix * cell_mm_;
      const double dx = std::max({cx0 - p.x, 0.0, p.x - (cx0 + cell_mm_)});
      if (dx * dx + dy * dy <= r2) out->push_back(iy * nx_ + ix);
    }
  }
}

int CellGrid::blocker(int vehicle, const int* cells, std::size_t n) const {
  for (std::size_t i = 0; i < n; ++i) {
    const int o = owner_[static_cast<std::size_t>(cells[i])];
    if (o >= 0 && o != vehicle) return o;
  }
  return -1;
}

void CellGrid::acquire(int vehicle, const int* cells, std::size_t n) {
  for (std::size_t i = 0; i < n; ++i) {
    const auto c = static_cast<std::size_t>(cells[i]);
    owner_[c] = vehicle;
    ++count_[c];
  }
}

void CellGrid::release(int vehicle, const int* cells, std::size_t n) {
  for (std::size_t i = 0; i < n; ++i) {
    const auto c = static_cast<std::size_t>(cells[i]);
    if (owner_[c] != vehicle || count_[c] <= 0) continue;  // not ours: nothing to give back
    if (--count_[c] == 0) owner_[c] = -1;
  }
}

bool FleetSim::build_leg(const Vehicle& v, Vec2 goal_mm, Leg* leg, std::string* why,
                         double max_length_mm) const {
  const site::Route route = planner_.plan({v.pose.x_mm, v.pose.y_mm}, goal_mm);
  if (route.status != site::PlanStatus::kOk) {
    *why = std::string("no route (") + site::to_string(route.status) + "): " + route.error;
    return false;
  }
  if (route.length_mm > max_length_mm) {
    *why = "route longer than " + std::to_string(max_length_mm) + " mm";
    return false;
  }
  // A corner the limits cannot blend: retry with tighter blends before giving up on the leg.
  site::DriveLimits lim = p_.drive;
  std::string err;
  bool made = false;
  for (int attempt = 0; attempt < 4 && !made; ++attempt) {
    made = site::RouteTrajectory::make(route, lim, &leg->traj, &err);
    lim.max_curvature_per_mm *= 2.0;
    lim.clothoid_length_mm *= 0.5;
  }
  if (!made) {
    *why = "no trajectory: " + err;
    return false;
  }
  const site::RouteTrajectory& tr = leg->traj;
  const double d_s = tr.duration_s();
  const double step = p_.path_step_mm;
  leg->sample_s_mm.clear();
  leg->sample_theta_rad.clear();
  leg->cell_begin.assign(1, 0);
  leg->cells.clear();
  auto add = [&](const site::TrajectorySample& smp) {
    leg->sample_s_mm.push_back(smp.s_mm);
    leg->sample_theta_rad.push_back(static_cast<float>(smp.pose.theta_rad));
    grid_.cells_near({smp.pose.x_mm, smp.pose.y_mm}, v.reserve_mm, &leg->cells);
    leg->cell_begin.push_back(static_cast<std::uint32_t>(leg->cells.size()));
  };
  // Points at most `step` apart along the path, so every position lies within step / 2 of one:
  // time steps in which the vehicle cannot cover more, subdivided where it does.
  const double dt = step / (1000.0 * std::max(p_.drive.speed_mps, 1e-3));
  site::TrajectorySample last = tr.at(0.0);
  add(last);
  double t_last = 0.0;
  while (t_last < d_s) {
    const double t = std::min(d_s, t_last + dt);
    site::TrajectorySample smp = tr.at(t);
    const double ds = smp.s_mm - last.s_mm;
    if (ds > step) {
      const int parts = static_cast<int>(std::ceil(ds / step)) + 1;
      for (int i = 1; i < parts; ++i) add(tr.at(t_last + (t - t_last) * i / parts));
    }
    if (ds > 1e-6 || t >= d_s) add(smp);
    if (ds > 1e-6) last = smp;
    t_last = t;
  }
  leg->lo = 0;
  leg->hi = -1;
  leg->tau_s = 0.0;
  leg->s_mm = leg->sample_s_mm.front();
  leg->alpha = 0.0;
  return true;
}

void FleetSim::start_task_leg(Vehicle& v) {
  const FleetTask& task =
      specs_[static_cast<std::size_t>(v.index)].tasks[static_cast<std::size_t>(v.task)];
  FleetTaskRecord& rec = out_->tasks[static_cast<std::size_t>(v.task_record)];
  if (rec.start_s < 0.0) rec.start_s = t_s_;
  const Vec2 goal = v.stage == Stage::kToPick ? task.pick_mm : task.drop_mm;
  if (std::hypot(goal.x - v.pose.x_mm, goal.y - v.pose.y_mm) < 1.0) {
    v.phase = Phase::kDwell;
    v.dwell_end_s = t_s_ + p_.dwell_s;
    return;
  }
  std::string why;
  if (!build_leg(v, goal, &v.leg, &why)) {
    rec.error = why;
    event(FleetEventKind::kTaskDropped, {v.index},
          "vehicle " + std::to_string(v.index) + " task " + std::to_string(v.task) + ": " + why);
    v.stage = Stage::kToDrop;
    advance_stage(v);
    return;
  }
  v.has_leg = true;
  extend_plan(v, v.leg);
  v.leg_kind = LegKind::kTask;
  v.phase = Phase::kTurn;
  v.turn_target_rad = v.leg.traj.at(0.0).pose.theta_rad;
}

void FleetSim::release_holdings(Vehicle& v) {
  if (v.has_leg) {
    plan_change(v, v.leg, v.leg.hi + 1, v.leg.plan_hi, -1);
    v.leg.plan_hi = -1;
    for (int k = v.leg.lo; k <= v.leg.hi; ++k)
      grid_.release(v.index, v.leg.cells_of(k), v.leg.count_of(k));
    v.leg.lo = 0;
    v.leg.hi = -1;
  }
  grid_.release(v.index, v.base_cells.data(), v.base_cells.size());
  v.base_cells.clear();
  clear_requests(v);
  v.wait_since_s = 1e300;
}

namespace {

std::uint8_t fleet_heading_code(double theta_rad) {
  return static_cast<std::uint8_t>(static_cast<int>(std::lround(theta_rad * (128.0 / kPi))) & 0xFF);
}

}  // namespace

void FleetSim::plan_change(const Vehicle& v, const Leg& leg, int k0, int k1, int delta) {
  const std::size_t base = static_cast<std::size_t>(v.index) * grid_.size();
  for (int k = std::max(0, k0); k <= k1; ++k) {
    const int* c = leg.cells_of(k);
    const std::uint8_t dir = fleet_heading_code(leg.sample_theta_rad[static_cast<std::size_t>(k)]);
    for (std::size_t i = 0; i < leg.count_of(k); ++i) {
      const auto ci = static_cast<std::size_t>(c[i]);
      if (delta > 0 && plan_own_[base + ci] == 0) plan_dir_[base + ci] = dir;
      plan_own_[base + ci] = static_cast<std::uint16_t>(plan_own_[base + ci] + delta);
      plan_total_[ci] += delta;
    }
  }
}

void FleetSim::extend_plan(const Vehicle& v, Leg& leg) {
  const int n = static_cast<int>(leg.samples());
  const double s_hi = leg.sample_s_mm[static_cast<std::size_t>(std::max(0, leg.hi))];
  const int from = std::max(leg.plan_hi, leg.hi) + 1;
  int k = from;
  while (k < n && leg.sample_s_mm[static_cast<std::size_t>(k)] <= s_hi + p_.plan_horizon_mm) ++k;
  plan_change(v, leg, from, k - 1, +1);
  leg.plan_hi = std::max(leg.plan_hi, k - 1);
}

bool FleetSim::on_others_plan(const Vehicle& v, const Leg& leg, int k) const {
  const std::size_t cells = grid_.size();
  const std::uint16_t* own = plan_own_.data() + static_cast<std::size_t>(v.index) * cells;
  const int mine = fleet_heading_code(leg.sample_theta_rad[static_cast<std::size_t>(k)]);
  const int* c = leg.cells_of(k);
  for (std::size_t i = 0; i < leg.count_of(k); ++i) {
    const auto ci = static_cast<std::size_t>(c[i]);
    if (plan_total_[ci] <= own[ci]) continue;
    // Someone else will pass here. Stopping in the way of a vehicle going the same way only
    // makes it queue behind; crossing or oncoming, it can make a cycle.
    for (std::size_t w = 0; w < vehicles_.size(); ++w) {
      if (static_cast<int>(w) == v.index || plan_own_[w * cells + ci] == 0) continue;
      const int d = std::abs(
          static_cast<std::int8_t>(static_cast<std::uint8_t>(plan_dir_[w * cells + ci] - mine)));
      if (d > 32) return true;  // more than 45 degrees apart
    }
  }
  return false;
}

int FleetSim::run_blocker(const Vehicle& v, const Leg& leg, int k, int m) const {
  for (int q = k; q <= m; ++q) {
    const int* c = leg.cells_of(q);
    for (std::size_t i = 0; i < leg.count_of(q); ++i) {
      const int o = grid_.owner(c[i]);
      if (o >= 0 && o != v.index) return o;
      const int r = request_[static_cast<std::size_t>(c[i])];
      if (r >= 0 && r != v.index &&
          vehicles_[static_cast<std::size_t>(r)].wait_since_s < v.wait_since_s) {
        return r;
      }
    }
  }
  return -1;
}

void FleetSim::clear_requests(Vehicle& v) {
  for (int c : v.requested) {
    if (request_[static_cast<std::size_t>(c)] == v.index)
      request_[static_cast<std::size_t>(c)] = -1;
  }
  v.requested.clear();
}

void FleetSim::place_requests(Vehicle& v, const Leg& leg, int k, int m) {
  clear_requests(v);
  for (int q = k; q <= m; ++q) {
    const int* c = leg.cells_of(q);
    for (std::size_t i = 0; i < leg.count_of(q); ++i) {
      int& r = request_[static_cast<std::size_t>(c[i])];
      if (r < 0 || vehicles_[static_cast<std::size_t>(r)].wait_since_s > v.wait_since_s) {
        r = v.index;
        v.requested.push_back(c[i]);
      }
    }
  }
}

void FleetSim::extend_reservation(Vehicle& v) {
  Leg& leg = v.leg;
  const double vmax_mmps = p_.drive.speed_mps * 1000.0;
  const double reach = leg.s_mm + vmax_mmps * p_.drive.speed_mps / (2.0 * p_.drive.accel_mps2) +
                       vmax_mmps * dt_s_ + p_.lookahead_mm;
  v.blocked = false;
  const int n = static_cast<int>(leg.samples());
  while (leg.hi + 1 < n &&
         (leg.hi < 0 || leg.sample_s_mm[static_cast<std::size_t>(leg.hi + 1)] <= reach)) {
    // Reserve through to the first point off every other vehicle's way, all or nothing: a
    // vehicle that has to stop then stands where nobody else needs to pass.
    const int k = leg.hi + 1;
    int m = k;
    while (m + 1 < n && on_others_plan(v, leg, m)) ++m;
    const int b = run_blocker(v, leg, k, m);
    if (b >= 0) {
      v.blocked = true;
      v.waits_on = b;
      v.wait_since_s = std::min(v.wait_since_s, t_s_);
      place_requests(v, leg, k, m);
      return;
    }
    plan_change(v, leg, k, std::min(m, leg.plan_hi), -1);
    for (int q = k; q <= m; ++q) grid_.acquire(v.index, leg.cells_of(q), leg.count_of(q));
    leg.hi = m;
    leg.plan_hi = std::max(leg.plan_hi, m);
    if (!v.base_cells.empty()) {
      // The leg's first point covers where it stands: the parking cells are no longer needed.
      grid_.release(v.index, v.base_cells.data(), v.base_cells.size());
      v.base_cells.clear();
    }
  }
  extend_plan(v, leg);
  v.wait_since_s = 1e300;
  if (!v.requested.empty()) clear_requests(v);
}

void FleetSim::turn_step(Vehicle& v) {
  v.v_mps = 0.0;
  const double d = wrap_angle_rad(v.turn_target_rad - v.pose.theta_rad);
  const double max_step = p_.turn_rate_radps * dt_s_;
  if (std::abs(d) <= max_step) {
    v.pose.theta_rad = v.turn_target_rad;
    v.omega_radps = d / dt_s_;
    v.phase = Phase::kDrive;
    return;
  }
  const double step = d > 0.0 ? max_step : -max_step;
  v.pose.theta_rad = wrap_angle_rad(v.pose.theta_rad + step);
  v.omega_radps = step / dt_s_;
}

void FleetSim::drive_step(Vehicle& v) {
  Leg& leg = v.leg;
  // A standing, blocked vehicle looks again every 10 steps (50 ms): its run can be long.
  if (v.blocked && leg.alpha == 0.0 && leg.hi >= 0 && (step_ + v.index) % 10 != 0) {
    v.v_mps = v.omega_radps = 0.0;
    return;
  }
  extend_reservation(v);
  if (leg.hi < 0) {
    v.v_mps = v.omega_radps = leg.alpha = 0.0;
    return;
  }
  const double d_s = leg.traj.duration_s();
  const double vmax_mmps = p_.drive.speed_mps * 1000.0;
  // Trajectory time runs at alpha times simulated time; alpha changes by at most beta per
  // second, so from alpha the vehicle stops within vmax * alpha^2 / (2 beta).
  const double beta = p_.drive.accel_mps2 / p_.drive.speed_mps;
  const bool end_held = leg.hi + 1 == static_cast<int>(leg.samples());
  const double s_hi = leg.sample_s_mm[static_cast<std::size_t>(leg.hi)];
  const double a = leg.alpha;
  const double options[3] = {std::min(1.0, a + beta * dt_s_), a, std::max(0.0, a - beta * dt_s_)};
  double alpha = options[2];
  for (double c : options) {
    if (end_held ||
        leg.s_mm + vmax_mmps * c * dt_s_ + vmax_mmps * c * c / (2.0 * beta) <= s_hi + 1e-6) {
      alpha = c;
      break;
    }
  }
  // Rounding leaves a residue that would creep forward for ever instead of standing.
  if (alpha < 0.5 * beta * dt_s_) alpha = 0.0;
  double tau = std::min(d_s, leg.tau_s + alpha * dt_s_);
  site::TrajectorySample smp = leg.traj.at(tau);
  if (!end_held && smp.s_mm > s_hi + 1e-6) {
    // Cannot happen while the braking bound holds; never drive onto cells not held.
    alpha = 0.0;
    tau = leg.tau_s;
    smp = leg.traj.at(tau);
  }
  v.s_total_mm += std::max(0.0, smp.s_mm - leg.s_mm);
  v.pose = smp.pose;
  v.v_mps = alpha * smp.v_mps;
  v.omega_radps = alpha * smp.omega_radps;
  leg.tau_s = tau;
  leg.alpha = alpha;
  leg.s_mm = smp.s_mm;
  // A position between points k+1 and k+2 is within step / 2 of one of them: k is not needed.
  while (leg.lo < leg.hi && leg.sample_s_mm[static_cast<std::size_t>(leg.lo + 1)] <= leg.s_mm) {
    grid_.release(v.index, leg.cells_of(leg.lo), leg.count_of(leg.lo));
    ++leg.lo;
  }
  if (tau >= d_s && end_held) arrive(v);
}

void FleetSim::arrive(Vehicle& v) {
  Leg& leg = v.leg;
  const int last = static_cast<int>(leg.samples()) - 1;
  v.base_cells.assign(leg.cells_of(last), leg.cells_of(last) + leg.count_of(last));
  grid_.acquire(v.index, v.base_cells.data(), v.base_cells.size());
  for (int k = leg.lo; k <= leg.hi; ++k) grid_.release(v.index, leg.cells_of(k), leg.count_of(k));
  v.has_leg = false;
  v.leg = Leg{};
  v.v_mps = v.omega_radps = 0.0;
  v.blocked = false;
  if (v.leg_kind == LegKind::kTask) {
    v.phase = Phase::kDwell;
    v.dwell_end_s = t_s_ + p_.dwell_s;
  } else {
    v.phase = Phase::kParked;
  }
}

}  // namespace agv::sim::fleet_internal
