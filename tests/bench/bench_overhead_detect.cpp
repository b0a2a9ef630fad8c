// Overhead tag detection speed (hand-run, not a ctest; docs/design/overhead.md gives the figures):
// one 3840x2160 frame of a ceiling camera 6 m up over 20 vehicles (160 mm tags, about 60 px),
// rendered with the realistic effects. Side by side in one run, on one core:
//  - TagDetector::detect on a 256 x 256 window around each visible tag (the tracker's window),
//    decimation 1 and 2;
//  - TagDetector::detect_predicted at each tag's corners moved 3 px (the predicted path);
//  - libapriltag (tag36h11, 2 bits, one thread) on the whole frame, decimation 1 and 2, with its
//    default min_white_black_diff (5) and with the detector's (40);
//  - tag_fix_on_tray on each visible tag's corners: level trays told nothing, with the default
//    tray sigma (0.5 degrees, 2 mm), and with that sigma and a surveyed tilt.
// Run with --benchmark_repetitions=5 --benchmark_report_aggregates_only=true for medians.
#include <apriltag/apriltag.h>
#include <apriltag/tag36h11.h>
#include <benchmark/benchmark.h>

#include <cstdio>

#include "agv/overhead/tag_detect.hpp"
#include "agv/overhead/tag_fix.hpp"
#include "agv/sim/site_render.hpp"

using namespace agv;

namespace {

struct Bench {
  site::CeilingCamera camera;
  sim::RenderResult frame;
  std::vector<cv::Rect> windows;
  std::vector<std::array<Vec2, 4>> predicted;
  std::vector<std::array<Vec2, 4>> corners;  // the fully visible tags' truth corners
  std::vector<std::uint32_t> ids;
};

sim::SiteScene scene() {
  sim::SiteScene s;
  s.site.outline.vertices_mm = {{-5000, -2800}, {5000, -2800}, {5000, 2800}, {-5000, 2800}};
  for (int i = 0; i < 20; ++i) {
    site::FleetAgv a;
    a.id = "agv" + std::to_string(i + 1);
    a.tag_id = static_cast<std::uint32_t>(i + 1);
    s.site.fleet.push_back(a);
  }
  const std::vector<Pose2> poses = sim::random_free_poses(s.site, 20, 330.0, 1);
  for (const Pose2& p : poses) s.agvs.push_back({p, 1.0, 0.2});
  s.site.fleet.resize(s.agvs.size());
  sim::add_random_clutter(&s, 3, 2, 1);
  return s;
}

const Bench& bench() {
  static const Bench b = [] {
    Bench out;
    const sim::SiteScene s = scene();
    site::CeilingCamera cc;
    cc.intrinsics.width_px = 3840;
    cc.intrinsics.height_px = 2160;
    cc.intrinsics.fx = cc.intrinsics.fy = 2100.0;  // 160 mm at 5.6 m: 60 px
    cc.intrinsics.cx = 1919.5;
    cc.intrinsics.cy = 1079.5;
    cc.intrinsics.k1 = -0.08;
    cc.intrinsics.k2 = 0.01;
    out.camera = cc;
    out.frame = sim::render_site_frame(s, sim::RenderCamera::from_ceiling(cc),
                                       sim::realistic_site_params(), 1);
    for (const sim::AgvTruth& t : out.frame.agvs) {
      out.ids.push_back(t.tag_id);
      if (t.tag_visible_fraction < 0.99) continue;
      Vec2 c{0, 0};
      std::array<Vec2, 4> pred{};
      for (std::size_t k = 0; k < 4; ++k) {
        c.x += 0.25 * t.tag_corners_px[k].x;
        c.y += 0.25 * t.tag_corners_px[k].y;
        pred[k] = {t.tag_corners_px[k].x + 3.0, t.tag_corners_px[k].y - 2.0};
      }
      out.windows.emplace_back(static_cast<int>(c.x) - 128, static_cast<int>(c.y) - 128, 256, 256);
      out.predicted.push_back(pred);
      out.corners.push_back(t.tag_corners_px);
    }
    std::printf("frame %dx%d, %zu of %zu tags fully visible\n", out.frame.image.cols,
                out.frame.image.rows, out.windows.size(), out.frame.agvs.size());
    return out;
  }();
  return b;
}

void BM_DetectWindow256(benchmark::State& state) {
  const Bench& b = bench();
  overhead::TagDetectParams p;
  p.quad_decimate = static_cast<double>(state.range(0));
  const overhead::TagDetector det(p);
  std::size_t i = 0, found = 0, calls = 0;
  for (auto _ : state) {
    const auto obs = det.detect(b.frame.image, b.windows[i]);
    found += obs.size();
    ++calls;
    i = (i + 1) % b.windows.size();
    benchmark::DoNotOptimize(obs.data());
  }
  state.counters["found_per_window"] = static_cast<double>(found) / static_cast<double>(calls);
}

void BM_DetectPredicted(benchmark::State& state) {
  const Bench& b = bench();
  const overhead::TagDetector det;
  std::size_t i = 0, ok = 0, calls = 0;
  for (auto _ : state) {
    overhead::TagObservation o;
    ok += det.detect_predicted(b.frame.image, b.predicted[i], b.ids, &o) ? 1 : 0;
    ++calls;
    i = (i + 1) % b.predicted.size();
    benchmark::DoNotOptimize(o);
  }
  state.counters["read_share"] = static_cast<double>(ok) / static_cast<double>(calls);
}

void BM_LibapriltagFullFrame(benchmark::State& state) {
  const Bench& b = bench();
  apriltag_family_t* f = tag36h11_create();
  apriltag_detector_t* td = apriltag_detector_create();
  apriltag_detector_add_family_bits(td, f, 2);
  td->quad_decimate = static_cast<float>(state.range(0));
  td->qtp.min_white_black_diff = static_cast<int>(state.range(1));
  td->nthreads = 1;
  const cv::Mat& img = b.frame.image;
  image_u8_t view{img.cols, img.rows, static_cast<std::int32_t>(img.step[0]),
                  const_cast<std::uint8_t*>(img.ptr<std::uint8_t>(0))};
  int found = 0;
  for (auto _ : state) {
    zarray_t* d = apriltag_detector_detect(td, &view);
    found = zarray_size(d);
    apriltag_detections_destroy(d);
  }
  state.counters["found"] = found;
  apriltag_detector_destroy(td);
  tag36h11_destroy(f);
}

void BM_TagFix(benchmark::State& state) {
  const Bench& b = bench();
  site::FleetAgv agv;
  overhead::TrayPlaneSigma sigma;
  if (state.range(0) >= 1) sigma = {0.0087, 2.0};
  if (state.range(0) == 2) agv.tray_roll_rad = 0.01, agv.tray_pitch_rad = -0.01;
  std::size_t i = 0, ok = 0, calls = 0;
  for (auto _ : state) {
    overhead::TagFix f;
    ok += overhead::tag_fix_on_tray(b.camera, b.corners[i], 0.1, agv, sigma, &f) ? 1 : 0;
    ++calls;
    i = (i + 1) % b.corners.size();
    benchmark::DoNotOptimize(f);
  }
  state.counters["fixed_share"] = static_cast<double>(ok) / static_cast<double>(calls);
}

}  // namespace

BENCHMARK(BM_DetectWindow256)->Arg(1)->Arg(2)->Unit(benchmark::kMillisecond);
BENCHMARK(BM_DetectPredicted)->Unit(benchmark::kMillisecond);
BENCHMARK(BM_TagFix)->Arg(0)->Arg(1)->Arg(2)->Unit(benchmark::kMicrosecond);
BENCHMARK(BM_LibapriltagFullFrame)
    ->Args({1, 5})
    ->Args({1, 40})
    ->Args({2, 5})
    ->Args({2, 40})
    ->Unit(benchmark::kMillisecond);
BENCHMARK_MAIN();
