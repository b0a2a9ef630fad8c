// Fleet simulator benchmark (docs/design/fleet_sim.md "Performance"): by default 20 vehicles
// for 10 simulated minutes on the 40 m x 25 m warehouse of tests/site/fleet_warehouse.hpp, every
// sample kept as for recordings. Prints the wall time and the simulated/real-time ratio; exits 1
// when two vehicles came closer than r_i + r_j + clearance, a task was not finished, or the ratio
// is below
// --min-ratio.
//   bench_fleet [--agvs N] [--duration-s T] [--tasks M] [--seed K] [--min-ratio R]
//               [--plan-horizon-mm H] [--cell-mm C] [--events 1]
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>

#include "../site/fleet_warehouse.hpp"
#include "agv/sim/fleet.hpp"

int main(int argc, char** argv) {
  int agvs = 20, tasks = 2;
  double duration_s = 600.0, min_ratio = 20.0, horizon_mm = -1.0, cell_mm = -1.0;
  unsigned long long seed = 1;
  bool events = false;
  for (int i = 1; i + 1 < argc; i += 2) {
    if (!std::strcmp(argv[i], "--agvs")) {
      agvs = std::atoi(argv[i + 1]);
    } else if (!std::strcmp(argv[i], "--duration-s")) {
      duration_s = std::atof(argv[i + 1]);
    } else if (!std::strcmp(argv[i], "--tasks")) {
      tasks = std::atoi(argv[i + 1]);
    } else if (!std::strcmp(argv[i], "--seed")) {
      seed = std::strtoull(argv[i + 1], nullptr, 10);
    } else if (!std::strcmp(argv[i], "--plan-horizon-mm")) {
      horizon_mm = std::atof(argv[i + 1]);
    } else if (!std::strcmp(argv[i], "--cell-mm")) {
      cell_mm = std::atof(argv[i + 1]);
    } else if (!std::strcmp(argv[i], "--events")) {
      events = std::atoi(argv[i + 1]) != 0;
    } else if (!std::strcmp(argv[i], "--min-ratio")) {
      min_ratio = std::atof(argv[i + 1]);
    } else {
      std::fprintf(stderr, "bench_fleet: unknown option %s\n", argv[i]);
      return 2;
    }
  }
  if (agvs < 1 || agvs > 200 || tasks < 0 || !(duration_s > 0.0)) {
    std::fprintf(stderr, "bench_fleet: --agvs 1..200, --tasks >= 0, --duration-s > 0\n");
    return 2;
  }
  const agv::site::Site site = agv::fleet_bench::warehouse();
  // Every fourth vehicle is a larger one (radius 550 mm).
  std::vector<double> radii;
  for (int i = 0; i < agvs; ++i) radii.push_back(i % 4 == 3 ? 550.0 : 400.0);
  std::string err;
  const auto t_build = std::chrono::steady_clock::now();
  agv::site::RoutePlanner planner;
  if (!agv::sim::route_planner_for_fleet(site, radii, &planner, &err)) {
    std::fprintf(stderr, "bench_fleet: %s\n", err.c_str());
    return 1;
  }
  std::vector<agv::sim::FleetVehicleSpec> specs;
  if (!agv::sim::make_random_fleet(planner, site, radii, tasks, seed, &specs, &err)) {
    std::fprintf(stderr, "bench_fleet: %s\n", err.c_str());
    return 1;
  }
  const double setup_s =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - t_build).count();
  agv::sim::FleetParams p;
  p.duration_s = duration_s;
  p.seed = seed;
  if (horizon_mm >= 0.0) p.plan_horizon_mm = horizon_mm;
  if (cell_mm > 0.0) p.cell_mm = cell_mm;
  agv::sim::FleetResult r;
  const auto t0 = std::chrono::steady_clock::now();
  if (!agv::sim::simulate_fleet(site, planner, specs, p, &r, &err)) {
    std::fprintf(stderr, "bench_fleet: %s\n", err.c_str());
    return 1;
  }
  const double wall_s =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  const double ratio = r.simulated_s / wall_s;
  if (events) {  // the blockages and how they were resolved
    for (const auto& e : r.events)
      std::printf("  %.1f %s: %s\n", e.t_s, agv::sim::to_string(e.kind), e.text.c_str());
  }
  int waits = 0;
  double wait_s = 0.0, km = 0.0;
  std::size_t samples = 0;
  for (const auto& v : r.vehicles) {
    waits += v.waits;
    wait_s += v.wait_s;
    km += v.distance_mm * 1e-6;
    samples += v.truth.size() + v.odom.size() + v.gyro.size();
  }
  std::printf(
      "bench_fleet: %d vehicles, %.0f s simulated, %zu tasks (%d finished), %.2f km "
      "driven\n",
      agvs, r.simulated_s, r.tasks.size(), r.tasks_finished, km);
  std::printf("  min pair distance %.0f mm, min margin over r_i + r_j + %.0f mm: %.1f mm\n",
              r.min_pair_distance_mm, r.clearance_mm, r.min_pair_margin_mm);
  std::printf("  waits %d (%.0f vehicle-s), deadlocks %d, blocked by idle %d, unresolved %d\n",
              waits, wait_s, r.deadlocks, r.blocked_by_idle, r.unresolved);
  std::printf("  set-up %.2f s; simulation %.2f s wall (%zu samples kept): %.0fx real time\n",
              setup_s, wall_s, samples, ratio);
  const bool ok = r.min_pair_margin_mm >= 0.0 &&
                  r.tasks_finished == static_cast<int>(r.tasks.size()) && ratio >= min_ratio;
  if (!ok)
    std::printf("bench_fleet: FAILED (clearance, unfinished tasks or below %.0fx)\n", min_ratio);
  return ok ? 0 : 1;
}
