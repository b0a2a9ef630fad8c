// LandmarkObserver cost per frame (hand-run, not a ctest; figures in docs/design/ranging.md), on
// RENDERED frames (not camera images): the forward camera of eval_ranging_frames (1280x800,
// f = 1000 px, lens distortion, defocus, noise, uneven light) at random poses in an area lined
// with racks carrying tag36h11 landmarks of 150 mm (2-8 m and beyond). Side by side on the same
// frames, one thread:
//  - FullSweepOld: the whole frame, and the whole frame again mirrored (MirrorCheck::kFullFrame,
//    the way observe() read every frame before predicted windows);
//  - FullSweep: the whole frame, each read re-read mirrored in its own window (kOwnWindow);
//  - FullSweepDecimate2: the same with libapriltag's quad decimation 2;
//  - Windows: the windows predicted from a pose prior (the true pose moved by a draw from its
//    covariance: 30 mm per axis, 0.3 deg), no periodic sweep (the interval's cost is one full
//    sweep per interval), the site's racks given to the observer (NoObstacles: not);
//  - IntervalLocalized / IntervalLocalizedFullSweep: the interval's frame with the localized prior,
//    the windows plus the whole frame at quad decimation 2, or a full sweep in their place.
// Counters: median, p90 and mean CPU per frame (thread CPU time, ms), landmarks seen per frame.
// `bench_ranging_observe --profile` first prints libapriltag's own stage times on the frames and
// the windowed reads against the full sweep's (ids, largest corner difference). `--diag` prints,
// for each frame with the localized prior, every predicted landmark and how it was read.
#include <apriltag/apriltag.h>
#include <apriltag/common/timeprofile.h>
#include <apriltag/tag36h11.h>
#include <benchmark/benchmark.h>

#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <ctime>
#include <map>
#include <random>
#include <string>

#include "agv/overhead/tag_detect.hpp"
#include "agv/ranging/observe.hpp"
#include "agv/sim/ranging_camera.hpp"
#include "ranging_scene.hpp"

using namespace agv;
using namespace agv::ranging;

namespace {

// Benchmark rows iterate over the first kFrames (4 kFrames: each 4 times) rendered frames;
// `--frames N` renders N for the --profile figures (the design note's agreement rows use 120).
constexpr int kFrames = 24;
int g_frames = kFrames;

struct Frames {
  sim::SiteScene scene;
  CameraIntrinsics k;
  RangingMount mount;
  std::vector<cv::Mat> images;
  std::vector<PosePrior> priors;                                  // 30 mm per axis, 0.3 deg
  std::vector<PosePrior> tight_priors;                            // 10 mm per axis, 0.1 deg
  std::vector<PosePrior> localized_priors;                        // 3 mm per axis, 0.03 deg
  std::vector<std::vector<overhead::TagObservation>> detections;  // the full sweep's
  std::vector<std::vector<sim::WallLandmarkTruth>> truths;        // the renderer's
};

PosePrior draw_prior(const Pose2& truth, double sd_mm, double sd_deg, std::mt19937_64& rng) {
  std::normal_distribution<double> n(0.0, 1.0);
  PosePrior prior;
  prior.cov =
      Eigen::Vector3d(sd_mm * sd_mm, sd_mm * sd_mm, std::pow(deg_to_rad(sd_deg), 2)).asDiagonal();
  prior.pose = {truth.x_mm + sd_mm * n(rng), truth.y_mm + sd_mm * n(rng),
                truth.theta_rad + deg_to_rad(sd_deg) * n(rng)};
  return prior;
}

const Frames& frames() {
  static const Frames f = [] {
    Frames out;
    out.scene = ranging_eval::warehouse(1);
    out.k = ranging_eval::true_camera();
    out.mount.x_mm = 300.0;
    out.mount.z_mm = 1000.0;
    const sim::SiteFrameRenderer renderer(out.k);
    const std::vector<Pose2> poses = ranging_eval::trial_poses(out.scene, g_frames, 1);
    std::mt19937_64 rng(5);
    overhead::TagDetectParams dp;
    dp.quad_min_white_black_diff = ObserveOptions{}.quad_min_white_black_diff;
    const overhead::TagDetector detector(dp);
    for (std::size_t i = 0; i < poses.size(); ++i) {
      std::mt19937_64 frame_rng(7919 + i);
      const sim::SiteRenderParams p = ranging_eval::degraded(frame_rng);
      sim::RenderResult frame =
          renderer.render(out.scene, sim::ranging_camera(out.k, poses[i], out.mount), p, 131 + i);
      out.images.push_back(frame.image);
      out.truths.push_back(std::move(frame.wall_landmarks));
      out.priors.push_back(draw_prior(poses[i], 30.0, 0.3, rng));
      out.tight_priors.push_back(draw_prior(poses[i], 10.0, 0.1, rng));
      out.localized_priors.push_back(draw_prior(poses[i], 3.0, 0.03, rng));
      const cv::Mat& g = out.images.back();
      out.detections.push_back(detector.detect(g, cv::Rect(0, 0, g.cols, g.rows)));
    }
    return out;
  }();
  return f;
}

double thread_cpu_ms() {
  timespec t{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &t);
  return static_cast<double>(t.tv_sec) * 1e3 + static_cast<double>(t.tv_nsec) * 1e-6;
}

double quantile(std::vector<double> v, double q) {
  std::sort(v.begin(), v.end());
  return v[std::min(v.size() - 1,
                    static_cast<std::size_t>(q * static_cast<double>(v.size() - 1) + 0.5))];
}

// The priors: 1 the 30 mm / 0.3 deg ones, 2 the 10 mm / 0.1 deg ones, 3 the 3 mm / 0.03 deg ones.
const PosePrior& prior_of(const Frames& f, int kind, std::size_t i) {
  return kind == 1 ? f.priors[i] : kind == 2 ? f.tight_priors[i] : f.localized_priors[i];
}

PosePrior turned(PosePrior p, double deg) {
  p.pose.theta_rad += deg_to_rad(deg);
  return p;
}

struct Mode {
  int windows = 0;              // 0 full sweep, else the priors of prior_of
  bool predicted_first = true;  // WindowOptions::predicted_first
  bool interval = false;        // every frame is the sweep interval's
  bool obstacles = true;        // the site's racks given to the observer (set_obstacles)
  double turn_deg = 0.0;        // the prior turned by this much (a prior wrong beyond its sigma)
};

void run(benchmark::State& state, const ObserveOptions& opt, const Mode& mode) {
  const Frames& f = frames();
  LandmarkObserver obs(f.k, f.mount, f.scene.site.wall_landmarks, opt);
  if (mode.obstacles) obs.set_obstacles(f.scene.site.obstacles);
  WindowOptions wopt;
  wopt.full_sweep_interval_frames = mode.interval ? 1 : 0;
  wopt.predicted_first = mode.predicted_first;
  std::vector<double> ms;
  std::size_t i = 0, seen = 0, swept = 0, predicted = 0;
  for (auto _ : state) {
    const std::size_t fi = i++ % std::min<std::size_t>(kFrames, f.images.size());
    const PosePrior prior = turned(prior_of(f, std::max(1, mode.windows), fi), mode.turn_deg);
    const double t0 = thread_cpu_ms();
    const ObserveResult r =
        mode.windows ? obs.observe(f.images[fi], &prior, 1, wopt) : obs.observe(f.images[fi]);
    ms.push_back(thread_cpu_ms() - t0);
    seen += r.seen.size();
    swept += r.full_sweep ? 1 : 0;
    predicted += r.predicted_reads;
    benchmark::DoNotOptimize(r.seen.data());
  }
  state.counters["median_cpu_ms"] = quantile(ms, 0.5);
  state.counters["p90_cpu_ms"] = quantile(ms, 0.9);
  double sum_ms = 0.0;
  for (double m : ms) sum_ms += m;
  state.counters["mean_cpu_ms"] = sum_ms / static_cast<double>(ms.size());
  state.counters["seen_per_frame"] = static_cast<double>(seen) / static_cast<double>(ms.size());
  state.counters["full_sweeps"] = static_cast<double>(swept);
  state.counters["predicted_per_frame"] =
      static_cast<double>(predicted) / static_cast<double>(ms.size());
}

void BM_FullSweepOld(benchmark::State& state) {
  ObserveOptions o;
  o.mirror_check = MirrorCheck::kFullFrame;
  run(state, o, {.windows = 0});
}
void BM_FullSweep(benchmark::State& state) { run(state, ObserveOptions{}, {.windows = 0}); }
void BM_FullSweepNoMirror(benchmark::State& state) {
  ObserveOptions o;
  o.mirror_check = MirrorCheck::kOff;
  run(state, o, {.windows = 0});
}
void BM_FullSweepDecimate2(benchmark::State& state) {
  ObserveOptions o;
  o.full_sweep_decimate = 2.0;
  run(state, o, {.windows = 0});
}
void BM_Windows(benchmark::State& state) { run(state, ObserveOptions{}, {.windows = 1}); }
void BM_WindowsTightPrior(benchmark::State& state) { run(state, ObserveOptions{}, {.windows = 2}); }
void BM_WindowsLocalizedPrior(benchmark::State& state) {
  run(state, ObserveOptions{}, {.windows = 3});
}
// The same three without the predicted path (libapriltag in every window).
void BM_WindowsNoPredicted(benchmark::State& state) {
  run(state, ObserveOptions{}, {.windows = 1, .predicted_first = false});
}
void BM_WindowsTightPriorNoPredicted(benchmark::State& state) {
  run(state, ObserveOptions{}, {.windows = 2, .predicted_first = false});
}
void BM_WindowsLocalizedPriorNoPredicted(benchmark::State& state) {
  run(state, ObserveOptions{}, {.windows = 3, .predicted_first = false});
}

// Without the site's racks given to the observer: landmarks behind them searched too.
void BM_WindowsNoObstacles(benchmark::State& state) {
  run(state, ObserveOptions{}, {.windows = 1, .obstacles = false});
}
void BM_WindowsLocalizedPriorNoObstacles(benchmark::State& state) {
  run(state, ObserveOptions{}, {.windows = 3, .obstacles = false});
}
// The interval's frame of a localized vehicle: the windows and the whole frame at quad
// decimation 2 (default), or a full sweep in their place (interval_sweep_decimate 1).
void BM_IntervalLocalized(benchmark::State& state) {
  run(state, ObserveOptions{}, {.windows = 3, .interval = true});
}
void BM_IntervalLocalizedFullSweep(benchmark::State& state) {
  ObserveOptions o;
  o.interval_sweep_decimate = 1.0;
  run(state, o, {.windows = 3, .interval = true});
}
// What the interval's search finds for a prior 20 degrees off that claims 0.03: its windows
// miss, the whole frame at quad decimation 2, 3 (decimate = state.range(0)) or a full sweep (1).
void BM_IntervalWrongPrior(benchmark::State& state) {
  ObserveOptions o;
  o.interval_sweep_decimate = static_cast<double>(state.range(0));
  run(state, o, {.windows = 3, .interval = true, .turn_deg = 20.0});
}

// The localized windows with the lens's focal doubt stated (focal_sigma_rel 0.002): each face
// yaw's share of it (one Gauss-Newton step per focal axis and landmark), and windows widened by it.
void BM_WindowsLocalizedPriorFocalDoubt(benchmark::State& state) {
  ObserveOptions o;
  o.focal_sigma_rel = 0.002;
  run(state, o, {.windows = 3});
}

// measure() alone (undistortion, pose, covariances) on the full sweep's detections; Arg(1) with
// the focal doubt stated (the face yaw's share of it), Arg(0) without.
// Measures the frames' detections one per iteration (range(0) != 0: a 0.2 % focal doubt stated)
// and hands each landmark measured to then.
template <typename Then>
void measure_each(benchmark::State& state, Then then) {
  const Frames& f = frames();
  ObserveOptions opt;
  opt.focal_sigma_rel = state.range(0) != 0 ? 0.002 : 0.0;
  const LandmarkObserver obs(f.k, f.mount, f.scene.site.wall_landmarks, opt);
  std::vector<overhead::TagObservation> all;
  for (const auto& d : f.detections) all.insert(all.end(), d.begin(), d.end());
  std::size_t i = 0;
  for (auto _ : state) {
    const overhead::TagObservation& d = all[i++ % all.size()];
    LandmarkObservation o;
    RefusalReason why{};
    const bool measured = obs.measure(d.id, d.corners_px, d.corner_sigma_px, &o, &why);
    benchmark::DoNotOptimize(measured);
    if (measured) then(f, o);
  }
}
void BM_MeasurePerLandmark(benchmark::State& state) {
  measure_each(state, [](const Frames&, const LandmarkObservation&) {});
}
// What the firmware does per landmark read (RackObserver): measure, then the fix's and the EKF's
// inputs; the lens response is read twice (vehicle and camera centre) when a focal doubt is stated.
void BM_MeasureForLocalizerPerLandmark(benchmark::State& state) {
  measure_each(state, [](const Frames& f, const LandmarkObservation& o) {
    benchmark::DoNotOptimize(fix_observation(o));
    benchmark::DoNotOptimize(sensor_range_bearing(f.mount, o, 0.001, 1.0));
  });
}
void BM_WindowsMirrorEachWindow(benchmark::State& state) {
  ObserveOptions o;
  o.mirror_check = MirrorCheck::kFullFrame;
  run(state, o, {.windows = 1});
}

BENCHMARK(BM_FullSweepOld)->Unit(benchmark::kMillisecond)->Iterations(kFrames)->UseRealTime();
BENCHMARK(BM_FullSweep)->Unit(benchmark::kMillisecond)->Iterations(kFrames)->UseRealTime();
BENCHMARK(BM_FullSweepNoMirror)->Unit(benchmark::kMillisecond)->Iterations(kFrames)->UseRealTime();
BENCHMARK(BM_FullSweepDecimate2)->Unit(benchmark::kMillisecond)->Iterations(kFrames)->UseRealTime();
BENCHMARK(BM_Windows)->Unit(benchmark::kMillisecond)->Iterations(4 * kFrames)->UseRealTime();
BENCHMARK(BM_WindowsTightPrior)
    ->Unit(benchmark::kMillisecond)
    ->Iterations(4 * kFrames)
    ->UseRealTime();
BENCHMARK(BM_WindowsLocalizedPrior)
    ->Unit(benchmark::kMillisecond)
    ->Iterations(4 * kFrames)
    ->UseRealTime();
BENCHMARK(BM_WindowsNoPredicted)
    ->Unit(benchmark::kMillisecond)
    ->Iterations(4 * kFrames)
    ->UseRealTime();
BENCHMARK(BM_WindowsTightPriorNoPredicted)
    ->Unit(benchmark::kMillisecond)
    ->Iterations(4 * kFrames)
    ->UseRealTime();
BENCHMARK(BM_WindowsLocalizedPriorNoPredicted)
    ->Unit(benchmark::kMillisecond)
    ->Iterations(4 * kFrames)
    ->UseRealTime();
BENCHMARK(BM_WindowsNoObstacles)
    ->Unit(benchmark::kMillisecond)
    ->Iterations(4 * kFrames)
    ->UseRealTime();
BENCHMARK(BM_WindowsLocalizedPriorNoObstacles)
    ->Unit(benchmark::kMillisecond)
    ->Iterations(4 * kFrames)
    ->UseRealTime();
BENCHMARK(BM_IntervalLocalized)->Unit(benchmark::kMillisecond)->Iterations(kFrames)->UseRealTime();
BENCHMARK(BM_IntervalLocalizedFullSweep)
    ->Unit(benchmark::kMillisecond)
    ->Iterations(kFrames)
    ->UseRealTime();
BENCHMARK(BM_IntervalWrongPrior)
    ->Arg(1)
    ->Arg(2)
    ->Arg(3)
    ->Unit(benchmark::kMillisecond)
    ->Iterations(kFrames)
    ->UseRealTime();
BENCHMARK(BM_WindowsLocalizedPriorFocalDoubt)
    ->Unit(benchmark::kMillisecond)
    ->Iterations(4 * kFrames)
    ->UseRealTime();
BENCHMARK(BM_MeasurePerLandmark)->Arg(0)->Arg(1)->Unit(benchmark::kMicrosecond);
BENCHMARK(BM_MeasureForLocalizerPerLandmark)->Arg(0)->Arg(1)->Unit(benchmark::kMicrosecond);
BENCHMARK(BM_WindowsMirrorEachWindow)
    ->Unit(benchmark::kMillisecond)
    ->Iterations(4 * kFrames)
    ->UseRealTime();

// libapriltag's own stage times (wall, from its time profile) on the frames, as the observer
// configures it for a full sweep.
void print_apriltag_stages(double decimate) {
  const Frames& f = frames();
  apriltag_family_t* family = tag36h11_create();
  apriltag_detector_t* td = apriltag_detector_create();
  apriltag_detector_add_family_bits(td, family, 2);
  td->quad_decimate = static_cast<float>(decimate);
  td->nthreads = 1;
  td->refine_edges = 1;
  td->decode_sharpening = 0.25;
  td->qtp.min_white_black_diff = ObserveOptions{}.quad_min_white_black_diff;
  std::map<std::string, double> total_ms;
  std::vector<std::string> order;
  for (const cv::Mat& g : f.images) {
    image_u8_t view{g.cols, g.rows, static_cast<std::int32_t>(g.step[0]), g.data};
    apriltag_detections_destroy(apriltag_detector_detect(td, &view));
    std::int64_t last = td->tp->utime;
    for (int i = 0; i < zarray_size(td->tp->stamps); ++i) {
      timeprofile_entry e{};
      zarray_get(td->tp->stamps, i, &e);
      if (!total_ms.count(e.name)) order.push_back(e.name);
      total_ms[e.name] += static_cast<double>(e.utime - last) * 1e-3;
      last = e.utime;
    }
  }
  std::printf("libapriltag stages, decimation %.0f, mean wall ms per frame:\n", decimate);
  for (const std::string& s : order) {
    std::printf("  %-24s %8.2f\n", s.c_str(), total_ms[s] / static_cast<double>(f.images.size()));
  }
  apriltag_detector_destroy(td);
  tag36h11_destroy(family);
}

// The windowed reads against the full sweep's on the same frames, per prior (the site's racks
// given to the observer), with the windowed path's CPU per frame (one pass, thread CPU).
void print_window_agreement(int kind, const char* name) {
  const Frames& f = frames();
  LandmarkObserver obs(f.k, f.mount, f.scene.site.wall_landmarks);
  obs.set_obstacles(f.scene.site.obstacles);
  WindowOptions wopt;
  wopt.full_sweep_interval_frames = 0;
  int both = 0, sweep_only = 0, window_only = 0;
  double worst_px = 0.0;
  std::size_t windows = 0, swept = 0, hidden = 0;
  std::vector<double> ms;
  for (std::size_t i = 0; i < f.images.size(); ++i) {
    const ObserveResult a = obs.observe(f.images[i]);
    const WindowPlan plan = obs.plan_windows(&prior_of(f, kind, i), 1, wopt);
    const double t0 = thread_cpu_ms();
    const ObserveResult b = obs.observe(f.images[i], plan);
    ms.push_back(thread_cpu_ms() - t0);
    windows += b.windows_searched;
    swept += b.full_sweep ? 1 : 0;
    hidden += plan.hidden;
    for (const LandmarkObservation& x : a.seen) {
      const auto y =
          std::find_if(b.seen.begin(), b.seen.end(), [&](const auto& o) { return o.id == x.id; });
      if (y == b.seen.end()) {
        ++sweep_only;
        continue;
      }
      ++both;
      for (std::size_t c = 0; c < 4; ++c) {
        worst_px = std::max(worst_px, std::hypot(x.corners_px[c].x - y->corners_px[c].x,
                                                 x.corners_px[c].y - y->corners_px[c].y));
      }
    }
    for (const LandmarkObservation& y : b.seen) {
      if (std::none_of(a.seen.begin(), a.seen.end(), [&](const auto& o) { return o.id == y.id; })) {
        ++window_only;
      }
    }
  }
  double sum_ms = 0.0;
  for (double m : ms) sum_ms += m;
  const double n = static_cast<double>(f.images.size());
  std::printf(
      "windows (%s) vs full sweep on %zu frames: %d landmarks in both (largest corner difference "
      "%.4f px), %d full sweep only, %d windows only; %.2f windows searched and %.2f landmarks "
      "hidden per frame, %zu full sweeps; CPU per frame mean %.3f ms, median %.3f ms\n",
      name, f.images.size(), both, worst_px, sweep_only, window_only,
      static_cast<double>(windows) / n, static_cast<double>(hidden) / n, swept, sum_ms / n,
      quantile(ms, 0.5));
}

bool has_id(const ObserveResult& r, std::uint32_t id) {
  return std::any_of(r.seen.begin(), r.seen.end(), [&](const auto& o) { return o.id == id; });
}

double visible_fraction(const Frames& f, std::size_t frame, std::uint32_t id) {
  for (const sim::WallLandmarkTruth& t : f.truths[frame]) {
    if (t.id == id) return t.visible_fraction;
  }
  return -1.0;
}

// Per frame: the whole plan's CPU (best of 3), each predicted landmark and how it was read (on the
// predicted path, by libapriltag in its window after the predicted path failed, or not at all)
// with the renderer's visible fraction, then each window alone (prior 1: the 30 mm ones, 8
// frames, with --profile; prior 3, the localized ones, every frame with --diag).
void print_window_diag(int kind, std::size_t n_frames) {
  const Frames& f = frames();
  LandmarkObserver obs(f.k, f.mount, f.scene.site.wall_landmarks);
  if (kind == 3) obs.set_obstacles(f.scene.site.obstacles);
  WindowOptions wopt;
  wopt.full_sweep_interval_frames = 0;
  for (std::size_t i = 0; i < std::min(n_frames, f.images.size()); ++i) {
    const WindowPlan plan = obs.plan_windows(&prior_of(f, kind, i), 1, wopt);
    double all_ms = 1e9;
    ObserveResult all;
    for (int rep = 0; rep < 3; ++rep) {
      const double t0 = thread_cpu_ms();
      all = obs.observe(f.images[i], plan);
      all_ms = std::min(all_ms, thread_cpu_ms() - t0);
    }
    WindowPlan no_windows = plan;
    no_windows.windows.clear();
    const ObserveResult pred = obs.observe(f.images[i], no_windows);
    std::printf("frame %zu: %s, %zu predicted, %zu read, %.3f ms\n", i,
                sweep_reason_name(plan.reason), plan.predicted.size(), all.seen.size(), all_ms);
    for (const auto& p : plan.predicted) {
      const char* how = has_id(pred, p.id)  ? "read on the predicted path"
                        : has_id(all, p.id) ? "read in its window"
                                            : "not read";
      std::printf("   id %u side %.1f sigma %.1f win %dx%d, %.2f visible: %s\n", p.id, p.side_px,
                  p.corner_sigma_px, p.window.width, p.window.height, visible_fraction(f, i, p.id),
                  how);
    }
    for (const SearchWindow& w : plan.windows) {
      WindowPlan one = plan;
      one.windows = {w};
      double best = 1e9;
      std::size_t seen = 0;
      for (int rep = 0; rep < 3; ++rep) {
        const double t0 = thread_cpu_ms();
        seen = obs.observe(f.images[i], one).seen.size();
        best = std::min(best, thread_cpu_ms() - t0);
      }
      std::printf("   window %dx%d dec %d: %.3f ms, %zu seen\n", w.rect.width, w.rect.height,
                  w.decimation, best, seen);
    }
  }
}

}  // namespace

int main(int argc, char** argv) {
  bool profile = false, diag = false;
  std::vector<char*> args;
  for (int i = 0; i < argc; ++i) {
    if (std::strcmp(argv[i], "--profile") == 0) {
      profile = true;
    } else if (std::strcmp(argv[i], "--diag") == 0) {
      diag = true;
    } else if (std::strcmp(argv[i], "--frames") == 0 && i + 1 < argc) {
      g_frames = std::max(1, std::atoi(argv[++i]));
    } else {
      args.push_back(argv[i]);
    }
  }
  if (profile) {
    print_apriltag_stages(1.0);
    print_apriltag_stages(2.0);
    print_window_agreement(1, "prior 30 mm / 0.3 deg");
    print_window_agreement(2, "prior 10 mm / 0.1 deg");
    print_window_agreement(3, "prior 3 mm / 0.03 deg");
    print_window_diag(1, 8);
  }
  if (diag) print_window_diag(3, static_cast<std::size_t>(g_frames));
  int n = static_cast<int>(args.size());
  benchmark::Initialize(&n, args.data());
  benchmark::RunSpecifiedBenchmarks();
  benchmark::Shutdown();
  return 0;
}
