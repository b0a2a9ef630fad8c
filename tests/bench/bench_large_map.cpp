// Large maps (docs/design/large_maps.md): start-up and per-frame cost of the localizer
// with a 1 m grid of 1 000, 10 000 and 60 000 landmarks (Google Benchmark). The start-up is the map
// text parsed and the vision localizer built (what `agvloc` does before its first frame); the
// frame costs are a tracked landmark frame, a landmark frame without a trusted prediction and the
// identity gate, each with the map of that size. Flat frame costs across the sizes are the target.
//   build/<preset>/tests/bench/bench_large_map [--benchmark_repetitions=3]
#include <benchmark/benchmark.h>

#include <cstdio>
#include <random>
#include <string>

#include "../support/prediction.hpp"
#include "agv/common/landmark_index.hpp"
#include "agv/sim/render.hpp"
#include "agv/vision/landmark_localizer.hpp"
#include "agv/vision/map_identity.hpp"

using namespace agv;

namespace {

constexpr double kSpacingMm = 1000.0;

// The map's text: a square 1 m grid, ids row by row, headings cycling 0, 90, 180, -90 deg.
std::string grid_text(int n) {
  int side = 1;
  while (side * side < n) ++side;
  std::string t = "id,x_mm,y_mm,heading_deg\n";
  const char* heads[] = {"0.00", "90.00", "180.00", "-90.00"};
  char line[96];
  for (int i = 0; i < n; ++i) {
    std::snprintf(line, sizeof line, "%d,%.1f,%.1f,%s\n", i + 1, (i % side) * kSpacingMm,
                  (i / side) * kSpacingMm, heads[i % 4]);
    t += line;
  }
  return t;
}

LandmarkMap grid_map(int n) {
  LandmarkMap m;
  std::string err;
  if (!parse_landmark_map(grid_text(n), &m, &err)) std::fprintf(stderr, "map: %s\n", err.c_str());
  return m;
}

using testsupport::predict;

// A frame over landmark 1 (the origin): rendered from a map of that landmark alone, which images
// the same as the large map (its neighbours are a metre away, out of the camera's view).
struct Frame {
  cv::Mat img;
  Pose2 vehicle;
};
Frame frame_over_first(const LandmarkMap& map, const CameraModel& cam) {
  LandmarkMap one;
  one.entries[1] = map.entries.at(1);
  sim::Scene scene;
  std::string err;
  sim::make_scene(one, LandmarkGeometry{}, sim::PayloadMode::kFull, &scene, &err);
  const Pose2 lw = one.entries.at(1).pose;
  const Pose2 v = compose(lw, inverse(Pose2{cam.mount.offset_x_mm + 4.0,
                                            cam.mount.offset_y_mm - 6.0, deg_to_rad(12.0)}));
  std::mt19937_64 rng(3);
  return {sim::render_frame(scene, cam, v, sim::RenderOptions{}, rng), v};
}

void BM_MapLoad(benchmark::State& st) {
  const std::string text = grid_text(static_cast<int>(st.range(0)));
  const CameraModel cam = CameraModel::default_640x480();
  for (auto _ : st) {
    LandmarkMap map;
    std::string err;
    parse_landmark_map(text, &map, &err);
    vision::LandmarkLocalizer loc(vision::VisionConfig{}, cam, LandmarkGeometry{}, &map);
    benchmark::DoNotOptimize(&loc);
  }
  st.counters["landmarks"] = static_cast<double>(st.range(0));
}

void frame_bench(benchmark::State& st, double sigma_mm, double sigma_deg) {
  const LandmarkMap map = grid_map(static_cast<int>(st.range(0)));
  const CameraModel cam = CameraModel::default_640x480();
  const Frame f = frame_over_first(map, cam);
  vision::LandmarkLocalizer loc(vision::VisionConfig{}, cam, LandmarkGeometry{}, &map);
  const vision::Prediction pred = predict(f.vehicle, sigma_mm, sigma_deg);
  vision::LandmarkFix fix;
  for (auto _ : st) {
    loc.process(f.img, pred, &fix);
    benchmark::DoNotOptimize(fix);
  }
  if (fix.status != vision::FixStatus::kOk) st.SkipWithError("no fix");
}

// A trusted prediction (sigma 3 mm, 0.5 deg): tracked detection from the mapped landmark's window.
void BM_TrackedFrame(benchmark::State& st) { frame_bench(st, 3.0, 0.5); }
// A prediction too loose to trust (sigma 200 mm, 5 deg): the full-frame search, the QR read with
// the book of the landmarks nearest the prediction.
void BM_UntrustedFrame(benchmark::State& st) { frame_bench(st, 200.0, 5.0); }

// The map-identity gate for a measured landmark under the vehicle, prediction sigma 20 mm / 1 deg.
void BM_IdentityGate(benchmark::State& st) {
  const LandmarkMap map = grid_map(static_cast<int>(st.range(0)));
  const LandmarkIndex index(map);
  const Pose2 v{120.0, -80.0, 0.2};  // over landmark 1, at the origin
  const Pose2 l = compose(inverse(v), map.entries.begin()->second.pose);
  const vision::Prediction pred = predict(v, 20.0, 1.0);
  const Eigen::Matrix3d meas = Eigen::Vector3d(0.05, 0.05, 1e-4).asDiagonal();
  const std::array<bool, 4> turns{true, true, true, true};
  for (auto _ : st) {
    const auto d = vision::gate_identity({l.x_mm, l.y_mm}, l.theta_rad, meas, turns, pred, map,
                                         vision::MapIdentityConfig{}, &index);
    benchmark::DoNotOptimize(d);
  }
}

void sizes(benchmark::internal::Benchmark* b) { b->Arg(25)->Arg(1000)->Arg(10000)->Arg(60000); }

BENCHMARK(BM_MapLoad)->Apply(sizes)->Unit(benchmark::kMillisecond);
BENCHMARK(BM_TrackedFrame)->Apply(sizes)->Unit(benchmark::kMicrosecond);
BENCHMARK(BM_UntrustedFrame)->Apply(sizes)->Unit(benchmark::kMicrosecond);
BENCHMARK(BM_IdentityGate)->Apply(sizes)->Unit(benchmark::kMicrosecond);

}  // namespace

BENCHMARK_MAIN();
