// The classical tray fit's cost per covered tray (hand-run, not a ctest; docs/design/overhead.md
// gives the figures): one 3840 x 2160 frame of a ceiling camera 6 m up (60 px tags) over four
// vehicles whose tags lie under parcels, rendered with the realistic effects; fit_tray on each
// from a prediction 5 mm / 0.5 deg off (a track kept by tray boxes) and 20 mm / 3 deg off (one
// that coasted a few frames), the prediction's sigma the same.
// Run with --benchmark_repetitions=5 --benchmark_report_aggregates_only=true for medians.
#include <benchmark/benchmark.h>

#include <array>
#include <cmath>
#include <vector>

#include "agv/overhead/tray_fit.hpp"
#include "agv/sim/site_render.hpp"
#include "tag_test_scene.hpp"

using namespace agv;

namespace {

struct Bench {
  site::CeilingCamera camera;
  sim::SiteScene scene;
  sim::RenderResult frame;
};

const Bench& bench() {
  static const Bench b = [] {
    Bench out;
    out.camera = overhead::test::ceiling_camera(20.0);
    overhead::test::scale_camera(&out.camera, 3);
    out.scene = overhead::test::covered_tag_scene(out.camera, 20.0, 4, 3);
    sim::add_random_clutter(&out.scene, 3, 2, 1);
    const sim::SiteFrameRenderer r(out.camera.intrinsics);
    out.frame = r.render(out.scene, sim::RenderCamera::from_ceiling(out.camera),
                         sim::realistic_site_params(), 5);
    return out;
  }();
  return b;
}

// args: prediction offset and sigma, mm and hundredths of a degree.
void BM_FitTray(benchmark::State& state) {
  const Bench& b = bench();
  const double off_mm = static_cast<double>(state.range(0));
  const double off_rad = static_cast<double>(state.range(1)) * 0.01 * kPi / 180.0;
  const std::array<double, 9> cov{off_mm * off_mm,  0, 0, 0, off_mm * off_mm, 0, 0, 0,
                                  off_rad * off_rad};
  int fitted = 0, tried = 0;
  for (auto _ : state) {
    for (const sim::AgvTruth& t : b.frame.agvs) {
      const Pose2 pred{t.pose.x_mm + off_mm, t.pose.y_mm - off_mm, t.pose.theta_rad + off_rad};
      overhead::TrayFix fix;
      fitted += overhead::fit_tray(b.frame.image, b.camera, b.scene.site.fleet[t.index], pred, cov,
                                   {}, &fix)
                    ? 1
                    : 0;
      ++tried;
      benchmark::DoNotOptimize(fix);
    }
  }
  state.counters["fitted_share"] = tried > 0 ? static_cast<double>(fitted) / tried : 0.0;
  state.counters["trays"] = static_cast<double>(b.frame.agvs.size());
}
BENCHMARK(BM_FitTray)->Args({5, 50})->Args({20, 300})->Unit(benchmark::kMillisecond);

}  // namespace

BENCHMARK_MAIN();
