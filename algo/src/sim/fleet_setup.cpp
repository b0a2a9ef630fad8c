// The fleet simulator's set-up helpers: the planner for a fleet, random fleets and tasks, and
// the per-vehicle gyro stream.
#include <algorithm>
#include <cmath>
#include <random>

#include "fleet_internal.hpp"

namespace agv::sim {

namespace fleet_internal {

void GyroStream::init(const GyroParams& p, std::int64_t period_ns) {
  p_ = p;
  p_.rate_hz = 1e9 / static_cast<double>(period_ns);
  const double period_s = static_cast<double>(period_ns) * 1e-9;
  // The seeding and the three streams of simulate_gyro, so the realisations match in kind.
  white_rng_.seed(p.seed * 0xD1B54A32D192ED03ULL + 101);
  markov_rng_.seed(p.seed * 0xD1B54A32D192ED03ULL + 202);
  walk_rng_.seed(p.seed * 0xD1B54A32D192ED03ULL + 303);
  white_sigma_ = p.noise_density_radps_rthz / std::sqrt(period_s);
  phi_ = std::exp(-period_s / p.bias_correlation_s);
  markov_step_ = p.bias_instability_radps * std::sqrt(1.0 - phi_ * phi_);
  walk_step_ = p.bias_random_walk_radps_rts * std::sqrt(period_s);
  markov_ = p.bias_instability_radps * n01_(markov_rng_);
  walk_ = 0.0;
  first_ = true;
}

ImuSample GyroStream::sample(std::int64_t t_ns, double true_rate_radps) {
  if (!first_) {
    markov_ = phi_ * markov_ + markov_step_ * n01_(markov_rng_);
    walk_ += walk_step_ * n01_(walk_rng_);
  }
  first_ = false;
  const double rate = (1.0 + p_.scale_error) * true_rate_radps + p_.bias_radps + markov_ + walk_ +
                      white_sigma_ * n01_(white_rng_);
  return {t_ns + p_.latency_ns, std::clamp(rate, -p_.range_radps, p_.range_radps)};
}

}  // namespace fleet_internal

bool route_planner_for_fleet(const site::Site& site, const std::vector<double>& radii_mm,
                             site::RoutePlanner* out, std::string* error) {
  std::string local;
  if (!error) error = &local;
  if (radii_mm.empty()) return (*error = "no vehicles", false);
  double r_max = 0.0;
  for (double r : radii_mm) {
    if (!(std::isfinite(r) && r > 0.0)) return (*error = "vehicle radius must be positive", false);
    r_max = std::max(r_max, r);
  }
  site::PlannerParams pp;
  pp.vehicle_radius_mm = r_max;
  pp.clearance_mm = std::max(0.0, site.clearance_mm);
  return site::RoutePlanner::build(site, pp, out, error);
}

namespace {

// A free point of the site reachable from `anchor` (when given), or false after many draws.
bool fleet_draw_point(const site::RoutePlanner& planner, const double box[4], std::mt19937_64& rng,
                      const Vec2* anchor, Vec2* out) {
  std::uniform_real_distribution<double> ux(box[0], box[2]), uy(box[1], box[3]);
  for (int i = 0; i < 2000; ++i) {
    const Vec2 q{ux(rng), uy(rng)};
    if (!planner.point_free(q)) continue;
    if (anchor && planner.plan(*anchor, q).status != site::PlanStatus::kOk) continue;
    *out = q;
    return true;
  }
  return false;
}

}  // namespace

bool make_random_fleet(const site::RoutePlanner& planner, const site::Site& site,
                       const std::vector<double>& radii_mm, int tasks_per_vehicle,
                       std::uint64_t seed, std::vector<FleetVehicleSpec>* out, std::string* error,
                       double min_leg_mm) {
  std::string local;
  if (!error) error = &local;
  if (!out) return (*error = "no output given", false);
  out->clear();
  if (radii_mm.empty()) return (*error = "no vehicles", false);
  if (tasks_per_vehicle < 0 || tasks_per_vehicle > 100000) {
    return (*error = "tasks per vehicle must be in [0, 100000]", false);
  }
  if (site.outline.vertices_mm.size() < 3) return (*error = "the site has no outline", false);
  double box[4] = {1e300, 1e300, -1e300, -1e300};
  for (const Vec2& q : site.outline.vertices_mm) {
    box[0] = std::min(box[0], q.x), box[1] = std::min(box[1], q.y);
    box[2] = std::max(box[2], q.x), box[3] = std::max(box[3], q.y);
  }
  std::mt19937_64 rng(seed * 0x9E3779B97F4A7C15ULL + 7);
  std::uniform_real_distribution<double> heading(-kPi, kPi);
  const double clearance = std::max(0.0, site.clearance_mm);
  Vec2 anchor{};
  for (std::size_t i = 0; i < radii_mm.size(); ++i) {
    FleetVehicleSpec v;
    v.id = i < site.fleet.size() && !site.fleet[i].id.empty() ? site.fleet[i].id
                                                              : "agv" + std::to_string(i);
    v.radius_mm = radii_mm[i];
    // Starts far enough apart that their reserved cells (fleet_sim.md) cannot overlap.
    bool placed = false;
    for (int attempt = 0; attempt < 500 && !placed; ++attempt) {
      Vec2 q;
      if (!fleet_draw_point(planner, box, rng, i == 0 ? nullptr : &anchor, &q)) break;
      placed = true;
      for (const FleetVehicleSpec& o : *out) {
        const double need = o.radius_mm + v.radius_mm + clearance + 800.0;
        if (std::hypot(q.x - o.start.x_mm, q.y - o.start.y_mm) < need) placed = false;
      }
      if (placed) v.start = {q.x, q.y, heading(rng)};
    }
    if (!placed) {
      return (*error = "no free room for vehicle " + std::to_string(i) + " of " +
                       std::to_string(radii_mm.size()) + " on the site",
              false);
    }
    if (i == 0) anchor = {v.start.x_mm, v.start.y_mm};
    out->push_back(v);
  }
  for (FleetVehicleSpec& v : *out) {
    for (int k = 0; k < tasks_per_vehicle; ++k) {
      FleetTask t;
      bool ok = false;
      for (int attempt = 0; attempt < 200 && !ok; ++attempt) {
        if (!fleet_draw_point(planner, box, rng, &anchor, &t.pick_mm) ||
            !fleet_draw_point(planner, box, rng, &anchor, &t.drop_mm)) {
          break;
        }
        ok = std::hypot(t.pick_mm.x - t.drop_mm.x, t.pick_mm.y - t.drop_mm.y) >= min_leg_mm;
      }
      if (!ok)
        return (*error = "no two free points " + std::to_string(min_leg_mm) +
                         " mm apart for a task on the site",
                false);
      v.tasks.push_back(t);
    }
  }
  return true;
}

}  // namespace agv::sim
