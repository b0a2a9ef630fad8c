// Route planner cost (docs/design/site_planner.md): the visibility graph of a 100 m x 60 m site
// with 400 racks (1 600 rack vertices) built, and one query with the start and goal inserted,
// single-threaded (Google Benchmark).
//   build/<preset>/tests/bench/bench_planner [--benchmark_repetitions=5]
#include <benchmark/benchmark.h>

#include <random>
#include <string>
#include <vector>

#include "agv/site/planner.hpp"

using namespace agv;
using namespace agv::site;

namespace {

// 20 columns x 20 rows of 3.6 m x 1.0 m racks: 1.2 m cross aisles, 1.9 m picking aisles, each
// rack shifted by up to 0.1 m (so that no two aisles line up exactly).
Site warehouse() {
  Site s;
  s.outline.vertices_mm = {{0, 0}, {100000, 0}, {100000, 60000}, {0, 60000}};
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> jitter(-100, 100);
  for (int c = 0; c < 20; ++c) {
    for (int r = 0; r < 20; ++r) {
      const double x0 = 2500 + c * 4800 + jitter(rng), y0 = 1500 + r * 2900 + jitter(rng);
      Obstacle o;
      o.id = "r" + std::to_string(c) + "_" + std::to_string(r);
      o.outline.vertices_mm = {{x0, y0}, {x0 + 3600, y0}, {x0 + 3600, y0 + 1000}, {x0, y0 + 1000}};
      s.obstacles.push_back(o);
    }
  }
  return s;
}

void BM_Build(benchmark::State& state) {
  const Site s = warehouse();
  RoutePlanner p;
  std::string error;
  for (auto _ : state) {
    RoutePlanner q;
    if (!RoutePlanner::build(s, {}, &q, &error)) state.SkipWithError(error.c_str());
    benchmark::DoNotOptimize(q.edge_count());
    p = std::move(q);
  }
  state.counters["nodes"] = static_cast<double>(p.vertex_count());
  state.counters["edges"] = static_cast<double>(p.edge_count());
}
BENCHMARK(BM_Build)->Unit(benchmark::kMillisecond);

void BM_Query(benchmark::State& state) {
  const Site s = warehouse();
  RoutePlanner p;
  std::string error;
  RoutePlanner::build(s, {}, &p, &error);
  // Free points in the picking aisles, far apart: the routes cross the site.
  std::mt19937 rng(11);
  std::vector<std::pair<Vec2, Vec2>> queries;
  std::uniform_real_distribution<double> ux(1000, 99000), uy(1000, 59000);
  while (queries.size() < 64) {
    const Vec2 a{ux(rng), uy(rng)}, b{ux(rng), uy(rng)};
    if (p.point_free(a) && p.point_free(b) && std::abs(a.x - b.x) > 40000)
      queries.push_back({a, b});
  }
  std::size_t i = 0, ok = 0;
  double length = 0.0;
  for (auto _ : state) {
    const auto& q = queries[i++ % queries.size()];
    const Route r = p.plan(q.first, q.second);
    ok += r.status == PlanStatus::kOk;
    length += r.length_mm;
  }
  state.counters["ok_fraction"] = static_cast<double>(ok) / static_cast<double>(i);
  state.counters["mean_length_m"] = length / static_cast<double>(i) / 1000.0;
}
BENCHMARK(BM_Query)->Unit(benchmark::kMicrosecond);

}  // namespace

BENCHMARK_MAIN();
