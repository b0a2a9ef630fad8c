// bench_overhead_latency: agvloc-overhead's exposure -> MQTT publish latency in its live loop
// (overhead/src/live.cpp) on paced cameras: every camera delivers a rendered frame of the test
// site at its frame rate on CLOCK_MONOTONIC (absolute deadlines, no drift), stamped at delivery
// minus --camera-latency-ms (the exposure to delivery time of a real camera: readout, transfer);
// the loop processes the frames and publishes every vehicle at output.rate_hz to an MQTT broker.
// Per frame processed: the time from its exposure stamp to the return of the first publish after
// it (every vehicle handed to the MQTT client). Hand-run, not a test; numbers in
// docs/design/overhead.md. Start a broker first, e.g. `mosquitto -p 18830`:
//   bench_overhead_latency --broker-port 18830 [--seconds 20] [--fps 30] [--rate-hz 30]
//                          [--camera-latency-ms 0] [--scale 1] [--max-decimation 4]
//                          [--sweep-max-pixels P] [--absent N]  (N more vehicles in the fleet, in
//                          no camera's view: the whole-image sweeps that look for them)
//                          [--vehicles N]  (N vehicles at rest in view, a grid of 5 columns;
//                          2: the test site's own two)
#include <time.h>

#include <algorithm>
#include <atomic>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <map>
#include <opencv2/imgproc.hpp>
#include <string>
#include <vector>

#include "../overhead/tag_test_scene.hpp"
#include "agv/hal/camera.hpp"
#include "agv/sim/site_render.hpp"
#include "core.hpp"
#include "inputs.hpp"
#include "live.hpp"

namespace {

using namespace agv;
using namespace agv::overhead_app;

// A camera that delivers one image at absolute multiples of its period from t0.
class PacedCamera : public hal::Camera {
 public:
  PacedCamera(cv::Mat image, std::int64_t t0_ns, std::int64_t period_ns, std::int64_t latency_ns,
              std::int64_t end_ns)
      : image_(std::move(image)),
        t0_(t0_ns),
        period_(period_ns),
        latency_(latency_ns),
        end_(end_ns) {}
  hal::CameraStatus start() override { return hal::CameraStatus::kOk; }
  void stop() override {}
  hal::CameraStatus next_frame(std::int64_t timeout_ns, hal::FrameView* f) override {
    const std::int64_t due = t0_ + (k_ + 1) * period_;
    if (due > end_) return hal::CameraStatus::kEndOfStream;
    const std::int64_t now = monotonic_ns();
    if (due - now > timeout_ns) {
      sleep_until(now + timeout_ns);
      return hal::CameraStatus::kTimeout;
    }
    sleep_until(due);
    ++k_;
    f->data = image_.data;
    f->width_px = image_.cols;
    f->height_px = image_.rows;
    f->stride_bytes = static_cast<int>(image_.step);
    f->t_exposure_ns = due - latency_;
    f->sequence = static_cast<std::uint64_t>(k_);
    f->slot = 0;
    return hal::CameraStatus::kOk;
  }
  void release(const hal::FrameView&) override {}
  hal::CameraStats stats() const override { return {}; }
  const char* last_error() const override { return ""; }

 private:
  static void sleep_until(std::int64_t t_ns) {
    timespec ts{static_cast<time_t>(t_ns / 1'000'000'000), static_cast<long>(t_ns % 1'000'000'000)};
    while (clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &ts, nullptr) == EINTR) {
    }
  }
  cv::Mat image_;
  std::int64_t t0_, period_, latency_, end_;
  std::int64_t k_ = 0;
};

double percentile_ms(std::vector<std::int64_t> v, double p) {
  if (v.empty()) return std::nan("");
  std::sort(v.begin(), v.end());
  const auto i = static_cast<std::size_t>(std::ceil(p * static_cast<double>(v.size()))) - 1;
  return 1e-6 * static_cast<double>(v[std::min(i, v.size() - 1)]);
}

}  // namespace

int main(int argc, char** argv) {
  std::map<std::string, double> o{
      {"--seconds", 20},          {"--fps", 30},        {"--rate-hz", 30},
      {"--camera-latency-ms", 0}, {"--broker-port", 0}, {"--scale", 1},
      {"--max-decimation", 4},    {"--absent", 0},      {"--sweep-max-pixels", 2.5e6},
      {"--vehicles", 2}};
  for (int i = 1; i + 1 < argc; i += 2) {
    if (!o.count(argv[i])) {
      std::fprintf(stderr, "bench_overhead_latency: unknown option %s\n", argv[i]);
      return 2;
    }
    o[argv[i]] = std::atof(argv[i + 1]);
  }
  if (o["--broker-port"] <= 0 || o["--fps"] <= 0 || o["--seconds"] <= 0 || o["--scale"] < 1 ||
      o["--vehicles"] < 1 || o["--vehicles"] > 40) {
    std::fprintf(stderr,
                 "usage: bench_overhead_latency --broker-port P [--seconds S] [--fps F] "
                 "[--rate-hz R] [--camera-latency-ms L] [--scale N] [--max-decimation D] "
                 "[--sweep-max-pixels P] [--absent N] [--vehicles N]\n");
    return 2;
  }
  site::Site s;
  std::vector<std::string> errors;
  if (!load_site_file(AGV_SOURCE_DIR "/tests/overhead/data/two_camera_site.yaml", &s, &errors)) {
    for (const std::string& e : errors) std::fprintf(stderr, "%s\n", e.c_str());
    return 2;
  }
  // --scale N: every camera N times larger in pixels (the same view), for heavier frames.
  const int scale = static_cast<int>(o["--scale"]);
  for (site::CeilingCamera& c : s.cameras) overhead::test::scale_camera(&c, scale);
  std::vector<sim::AgvState> agvs = {{{1350.0, 1250.0, 0.3}, 0.0, 0.0},
                                     {{3600.0, 1000.0, -1.0}, 0.0, 0.0}};
  const int vehicles = static_cast<int>(o["--vehicles"]);
  if (vehicles != 2) {
    // A grid of 5 columns 1 m apart and rows 0.6 m apart over the 5 x 2.4 m floor (trays 500 x
    // 400 mm: they do not touch), each vehicle turned its own way.
    agvs.clear();
    const site::FleetAgv first = s.fleet.front();
    s.fleet.clear();
    const int rows = (vehicles + 4) / 5;
    for (int i = 0; i < vehicles; ++i) {
      const double y = 2400.0 * (i / 5 + 0.5) / rows;
      agvs.push_back({{500.0 + 1000.0 * (i % 5), y, -3.0 + 0.29 * i}, 0.0, 0.0});
      site::FleetAgv a = first;
      a.id = "agv-" + std::to_string(i + 1);
      a.tag_id = static_cast<std::uint32_t>(30 + i);
      s.fleet.push_back(a);
    }
  }
  OverheadConfig cfg;
  cfg.output_rate_hz = o["--rate-hz"];
  cfg.search.max_decimation = static_cast<int>(o["--max-decimation"]);
  cfg.search.sweep_max_pixels = static_cast<int>(o["--sweep-max-pixels"]);
  cfg.mqtt.enabled = true;
  cfg.mqtt.broker_host = "127.0.0.1";
  cfg.mqtt.port = static_cast<int>(o["--broker-port"]);
  std::vector<cv::Mat> images;
  for (std::size_t c = 0; c < s.cameras.size(); ++c) {
    sim::SiteScene scene;
    scene.site = s;
    scene.agvs = agvs;
    const sim::SiteFrameRenderer r(s.cameras[c].intrinsics);
    images.push_back(r.render(scene, sim::RenderCamera::from_ceiling(s.cameras[c]),
                              sim::realistic_site_params(), 1)
                         .image.clone());
  }
  // After rendering: the renderer draws every vehicle of the fleet.
  for (int i = 0; i < static_cast<int>(o["--absent"]); ++i) {
    site::FleetAgv a = s.fleet.front();
    a.id = "absent-" + std::to_string(i + 1);
    a.tag_id = static_cast<std::uint32_t>(100 + i);
    s.fleet.push_back(a);
  }
  TrackerCore core(cfg, s);
  std::string err;
  if (!core.open_outputs("", &err)) {
    std::fprintf(stderr, "bench_overhead_latency: %s\n", err.c_str());
    return 1;
  }
  // The first exposure after the rendering and the broker's connection (large frames take
  // seconds to render): frames due before the loop starts would arrive as one burst.
  const std::int64_t period = std::llround(1e9 / o["--fps"]);
  const std::int64_t t0 = monotonic_ns() + 500'000'000;
  const std::int64_t end = t0 + std::llround(o["--seconds"] * 1e9);
  std::vector<LiveCamera> cams;
  for (std::size_t c = 0; c < s.cameras.size(); ++c) {
    // Cameras free running, their exposures staggered over the period.
    const std::int64_t offset =
        period * static_cast<std::int64_t>(c) / static_cast<std::int64_t>(s.cameras.size());
    cams.push_back(
        {s.cameras[c].id, c,
         std::make_unique<PacedCamera>(images[c], t0 + offset, period,
                                       std::llround(o["--camera-latency-ms"] * 1e6), end)});
  }
  std::vector<std::int64_t> lat;
  LiveDiag d;
  d.exposure_to_publish_ns = &lat;
  const std::atomic<bool> stop{false};
  const LiveCounters n = run_live(&cams, &core, stop, 0, d);
  core.finish("bench_overhead_latency", cams.size(), &err);
  // The first second: tracks starting.
  const std::size_t skip = std::min(lat.size(), static_cast<std::size_t>(o["--fps"] * 2));
  const std::vector<std::int64_t> steady(lat.begin() + static_cast<std::ptrdiff_t>(skip),
                                         lat.end());
  std::printf(
      "bench_overhead_latency: %zu vehicles, %zu cameras %dx%d at %.0f fps, publishing at %.0f Hz "
      "to 127.0.0.1:%d, camera latency %.1f ms, %.0f s: %zu frames measured (%llu dropped "
      "behind, %llu ticks, %llu skipped)\n"
      "exposure -> publish: p50 %.2f ms, p90 %.2f ms, p99 %.2f ms, max %.2f ms\n",
      agvs.size(), cams.size(), s.cameras[0].intrinsics.width_px, s.cameras[0].intrinsics.height_px,
      o["--fps"], o["--rate-hz"], cfg.mqtt.port, o["--camera-latency-ms"], o["--seconds"],
      steady.size(), static_cast<unsigned long long>(n.frames_dropped),
      static_cast<unsigned long long>(n.ticks), static_cast<unsigned long long>(n.ticks_skipped),
      percentile_ms(steady, 0.5), percentile_ms(steady, 0.9), percentile_ms(steady, 0.99),
      percentile_ms(steady, 1.0));
  return 0;
}
