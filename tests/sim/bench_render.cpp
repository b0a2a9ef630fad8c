// Rendering speed of the simulator (not a ctest; docs/design/simulator.md gives the command).
// Prints the median CPU time per frame for a few configurations and ratios against the floor-only
// frame measured in the same run.
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <ctime>
#include <vector>

#include "agv/sim/render.hpp"

using namespace agv;
using namespace agv::sim;

namespace {

double median_ms(const FrameRenderer& r, const Pose2& pose, const RenderOptions& o, int n) {
  std::mt19937_64 rng(1);
  std::vector<double> t;
  for (int i = 0; i < n; ++i) {
    // Process CPU time: the machine running this may be shared, wall time would mislead.
    const std::clock_t a = std::clock();
    const cv::Mat img = r.render(pose, o, rng);
    const std::clock_t b = std::clock();
    if (img.empty()) return -1.0;
    t.push_back(1000.0 * static_cast<double>(b - a) / CLOCKS_PER_SEC);
  }
  std::nth_element(t.begin(), t.begin() + n / 2, t.end());
  return t[static_cast<size_t>(n / 2)];
}

}  // namespace

int main(int argc, char** argv) {
  const int n = argc > 1 ? std::max(3, std::atoi(argv[1])) : 21;
  Scene scene;
  std::string err;
  if (!make_scene(default_landmark_grid(), LandmarkGeometry{}, PayloadMode::kFull, &scene, &err)) {
    std::fprintf(stderr, "%s\n", err.c_str());
    return 1;
  }
  for (const CameraModel& cam : {CameraModel::default_640x480(), CameraModel::default_1280x800()}) {
    const auto a = std::chrono::steady_clock::now();
    const FrameRenderer r(scene, cam);
    const double setup_ms =
        std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - a).count();
    const Pose2 away{500.0, 500.0, 0.3};   // no landmark in view
    const Pose2 over{1010.0, 995.0, 0.3};  // landmark 2 centred
    RenderOptions real = realistic_options();
    real.speed_mps = 0.5;
    const double base = median_ms(r, away, RenderOptions{}, n);
    const double lm = median_ms(r, over, RenderOptions{}, n);
    const double lm_real = median_ms(r, over, real, n);
    std::printf(
        "%dx%d: setup %.0f ms; median per frame over %d runs: floor only %.1f ms, "
        "with landmark %.1f ms (x%.2f), with landmark realistic %.1f ms (x%.2f)\n",
        cam.intrinsics.width_px, cam.intrinsics.height_px, setup_ms, n, base, lm, lm / base,
        lm_real, lm_real / base);
  }
  return 0;
}
