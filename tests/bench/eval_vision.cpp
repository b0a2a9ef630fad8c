// Evaluation of the landmark pose pipeline on simulator frames with ground truth:
// accuracy on clean and degraded frames, the part of the range where the landmark is cut by the
// image border, false detections on landmark-free floor, per-stage speed, and AprilTag 3
// (tag36h11, decimate 2, one thread) on the same kind of frames in the same run.
// Not a unit test. Usage and results: docs/design/accuracy.md.
//   eval_vision [--profile 640|1280] [--frames N] [--floor-frames N] [--seed S] [--ablation]
//               [--no-apriltag] [--dump DIR] [--family qr|tag36h11] [--speed-compare]
// --family tag36h11: the same conditions on a floor of tag36h11 landmarks (the tag family of the
// localizer); --speed-compare: only the speed comparison (eval_vision_tag.cpp).
#include "eval_vision.hpp"

#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <functional>
#include <string>
#include <vector>

#include "degradations.hpp"

using namespace eval_vision;

namespace {

struct Args {
  int profile = 640;
  int frames = 400;
  int floor_frames = 1000;
  std::uint64_t seed = 1;
  bool ablation = false;
  bool apriltag = true;
  std::string dump;
  std::string only;         // run only the fully-visible conditions whose name contains this
  int profile_reps = 0;     // --profile-loop: only process the clean frames this many times (perf)
  int qr_max_missing = -1;  // --qr-max-missing: VisionConfig::qr_max_missing_modules (-1 = default)
  int qr_max_grid_decodes = -1;  // --qr-max-grid-decodes: VisionConfig's (-1 = default)
  int row_step = 0;              // --row-step: VisionConfig::edge_row_step (0 = default)
  bool tag = false;              // --family tag36h11
  bool speed_compare = false;
};

// The fully visible conditions; the second last ("all combined") is rendered through the
// distorted lens and reused by the speed comparison and the ablation.
std::vector<Condition> make_conditions(double mmpp) {
  return {
      {"clean", nullptr, false, true},
      {"defocus sigma 2 px",
       [](std::mt19937_64&, sim::RenderOptions* o) { o->defocus_sigma_px = 2.0; }, false, true},
      {"motion blur 7 px",
       [=](std::mt19937_64&, sim::RenderOptions* o) { bench::motion_blur(7.0, mmpp, o); }, false,
       true},
      {"noise (read 4 + shot 0.3)",
       [](std::mt19937_64&, sim::RenderOptions* o) {
         o->read_noise_sigma = 4.0;
         o->shot_noise_gain = 0.3;
       },
       false, true},
      {"illumination 2:1",
       [](std::mt19937_64& r, sim::RenderOptions* o) {
         o->illumination_ratio = 0.5;
         o->illumination_direction_deg = std::uniform_real_distribution<double>(0, 360)(r);
       },
       false, true},
      {"lens distortion k1=-0.25", nullptr, true, true},
      {"3 scratches + 3 dirt spots",
       [](std::mt19937_64&, sim::RenderOptions* o) {
         o->scratches_per_landmark = 3;
         o->dirt_spots_per_landmark = 3;
       },
       false, true},
      {"occluder 15 % of border",
       [](std::mt19937_64&, sim::RenderOptions* o) { o->occluder_border_fraction = 0.15; }, false,
       true},
      {"all combined (random, up to the limits)",
       [=](std::mt19937_64& r, sim::RenderOptions* o) { bench::combined_degradations(mmpp, r, o); },
       true, true},
      // Stress, beyond the degraded set's "up to" limits: defocus, motion blur and noise all at
      // their limits in the same frame.
      {"stress: defocus 2 + motion 7 px + noise, all at the limits",
       [=](std::mt19937_64&, sim::RenderOptions* o) { bench::stress_degradations(mmpp, o); }, false,
       true},
  };
}

// Fully visible landmark over the paper range; keeps the clean and the combined frames.
void run_visible(const Args& a, const Setup& su, const std::vector<Condition>& conds,
                 std::vector<Frame>* clean_frames, std::vector<Frame>* combined_frames) {
  const size_t combined_index = conds.size() - 2;
  std::printf("## Fully visible landmark, paper range, full heading circle\n\n");
  print_header();
  for (size_t ci = 0; ci < conds.size(); ++ci) {
    const Condition& c = conds[ci];
    if (!a.only.empty() && c.name.find(a.only) == std::string::npos) continue;
    const CameraModel& cm = c.distorted_camera ? su.cam_dist : su.cam;
    auto frames = render_set(su.scene, cm, c, a.frames, a.seed * 1000 + ci);
    LandmarkLocalizer loc(su.cfg, cm, su.geom, &su.map);
    Stats s;
    evaluate(loc, frames, &s, "c" + std::to_string(ci));
    print_row(c.name, s);
    if (ci == 0) *clean_frames = std::move(frames);
    if (ci == combined_index) *combined_frames = std::move(frames);
  }
}

// Cut by the image border: the rest of the paper's range.
void run_cut(const Args& a, const Setup& su) {
  const CameraModel& cam = su.cam;
  std::printf("\n## Landmark cut by the image border (rest of the paper range)\n\n");
  print_header();
  Condition c{"partly outside, clean", nullptr, false, false};
  auto frames = render_set(su.scene, cam, c, a.frames, a.seed * 1000 + 77);
  LandmarkLocalizer loc(su.cfg, cam, su.geom, &su.map);
  Stats s;
  evaluate(loc, frames, &s, "cut");
  print_row(c.name, s);
  Condition c2{"partly outside, realistic",
               [](std::mt19937_64&, sim::RenderOptions* o) { *o = sim::realistic_options(); },
               false, false};
  auto frames2 = render_set(su.scene, cam, c2, a.frames, a.seed * 1000 + 78);
  Stats s2;
  evaluate(loc, frames2, &s2);
  print_row(c2.name, s2);
}

// Speed: medians over the clean frames, one option changed against the default, AprilTag 3.
void run_speed(const Args& a, const Setup& su, const std::vector<Frame>& clean_frames,
               const std::vector<Frame>& combined_frames) {
  const VisionConfig& cfg = su.cfg;
  const CameraModel &cam = su.cam, &cam_dist = su.cam_dist;
  const LandmarkGeometry& geom = su.geom;
  const LandmarkMap& map = su.map;
  LandmarkLocalizer loc(cfg, cam, geom, &map);
  Stats s;
  for (int rep = 0; rep < 3; ++rep) {
    s = Stats{};
    evaluate(loc, clean_frames, &s);
  }
  std::printf("\n## Speed (clean frames, one thread, median of %d frames)\n\n", s.n);
  std::printf("| stage | median (ms) | p95 (ms) |\n|---|---|---|\n");
  auto row = [](const char* n, const std::vector<double>& v) {
    std::printf("| %s | %.3f | %.3f |\n", n, pct(v, 50), pct(v, 95));
  };
  row("detect (pyramid, threshold, corner NCC, ring)", s.t_detect);
  row("decode (QR: guided sampling, else zxing search; payload; map)", s.t_decode);
  row("pose (Prewitt, classes, fits)", s.t_pose);
  row("direction (logo NCC at 4 turns + QR cross-check)", s.t_direction);
  row("total", s.t_total);
  const double ours = pct(s.t_total, 50);
  // One option changed against the default: decode time on the clean frames and detection on
  // the combined frames (rendered through the distorted lens: localizers that know it).
  LandmarkLocalizer loc_d(cfg, cam_dist, geom, &map);
  Stats scomb;
  evaluate(loc_d, combined_frames, &scomb);
  auto compare = [&](const char* what, const char* ref,
                     const std::function<void(VisionConfig*)>& set) {
    VisionConfig v = cfg;
    set(&v);
    LandmarkLocalizer lv(v, cam, geom, &map), lv_d(v, cam_dist, geom, &map);
    Stats sv, scomb_v;
    evaluate(lv, clean_frames, &sv);
    evaluate(lv_d, combined_frames, &scomb_v);
    std::printf(
        "%s: decode median %.3f ms (%s: %.3f ms); detection on combined degraded frames "
        "%.1f %% (%s: %.1f %%)\n",
        what, pct(sv.t_decode, 50), ref, pct(s.t_decode, 50),
        100.0 * scomb_v.ok / std::max(1, scomb_v.n), ref, 100.0 * scomb.ok / std::max(1, scomb.n));
  };
  std::printf("\n");
  compare("zxing TryHarder", "off", [](VisionConfig* v) { v->qr_try_harder = true; });
  // Guided QR sampling off: zxing's search on the crop only (the previous pipeline).
  compare("guided QR sampling off (zxing search only)", "on",
          [](VisionConfig* v) { v->qr_guided = false; });
  if (a.apriltag) run_apriltag(su, clean_frames, loc, s, ours, a.seed);
}

// Landmark-free floor: false fixes.
void run_floor(const Args& a, const Setup& su) {
  const sim::Scene& scene = su.scene;
  const CameraModel& cam = su.cam;
  const VisionConfig& cfg = su.cfg;
  const LandmarkGeometry& geom = su.geom;
  const LandmarkMap& map = su.map;
  sim::Scene empty = scene;
  empty.landmarks.clear();
  sim::FrameRenderer r(empty, cam);
  std::mt19937_64 rng(a.seed * 1000 + 55);
  std::uniform_real_distribution<double> upos(-5e4, 5e4), uang(-kPi, kPi);
  LandmarkLocalizer loc(cfg, cam, geom, &map);
  int false_ok = 0, not_none = 0;
  std::map<FixStatus, int> st;
  LandmarkFix fix;
  for (int i = 0; i < a.floor_frames; ++i) {
    sim::RenderOptions o = sim::realistic_options();
    if (i % 2) o = sim::RenderOptions{};
    const cv::Mat img = r.render({upos(rng), upos(rng), uang(rng)}, o, rng);
    loc.process(img, &fix);
    ++st[fix.status];
    if (fix.status == FixStatus::kOk) ++false_ok;
    if (fix.status != FixStatus::kNoLandmark) ++not_none;
  }
  std::printf(
      "\n## Landmark-free floor frames\n\n%d frames (half clean, half realistic): false fixes "
      "(kOk) %d; frames reaching the decode stage %d\n",
      a.floor_frames, false_ok, not_none);
}

int run(const Args& a) {
  g_dump_dir = a.dump;
  const CameraModel cam =
      a.profile == 1280 ? CameraModel::default_1280x800() : CameraModel::default_640x480();
  CameraModel cam_dist = cam;
  cam_dist.intrinsics.k1 = -0.25;
  cam_dist.intrinsics.k2 = 0.08;
  cam_dist.intrinsics.p1 = 0.001;
  const LandmarkGeometry geom;
  LandmarkMap map;
  map.entries[kId] = {kId, kLandmarkWorld};
  sim::Scene scene, tag_scene;
  std::string err;
  AprilTagGeometry tag_geom;
  tag_geom.size_mm = geom.size_mm;
  if (!sim::make_scene(map, geom, sim::PayloadMode::kFull, &scene, &err) ||
      !sim::make_tag_scene(map, tag_geom, &tag_scene, &err)) {
    std::fprintf(stderr, "scene: %s\n", err.c_str());
    return 1;
  }
  if (a.tag) scene = tag_scene;
  const double mmpp = cam.mm_per_px();
  std::printf("# eval_vision: profile %dx%d (%.3f mm/px), %d frames per condition, seed %llu\n\n",
              cam.intrinsics.width_px, cam.intrinsics.height_px, mmpp, a.frames,
              static_cast<unsigned long long>(a.seed));

  VisionConfig cfg;
  cfg.now_ns = now_ns;
  if (a.qr_max_missing >= 0) cfg.qr_max_missing_modules = a.qr_max_missing;
  if (a.qr_max_grid_decodes >= 0) cfg.qr_max_grid_decodes = a.qr_max_grid_decodes;
  if (a.row_step > 0) cfg.edge_row_step = a.row_step;
  std::printf("edge row step: %d\n", cfg.edge_row_step);
  if (a.tag) cfg.family = LandmarkFamily::kTag36h11;
  std::printf("landmark family: %s\n\n", a.tag ? "tag36h11" : "qr");

  Setup su{cam, cam_dist, geom, map, scene, cfg};
  const std::vector<Condition> conds = make_conditions(mmpp);

  std::vector<Frame> clean_frames, combined_frames;
  if (a.speed_compare) {
    Setup su_qr = su;
    sim::make_scene(map, geom, sim::PayloadMode::kFull, &su_qr.scene, &err);
    run_speed_compare(su_qr, render_set(su_qr.scene, cam, conds[0], a.frames, a.seed * 1000),
                      tag_scene);
    return 0;
  }
  if (a.profile_reps > 0) {
    // For a sampling profiler: rendering would dominate a normal run.
    auto frames = render_set(scene, cam, conds[0], a.frames, a.seed * 1000);
    LandmarkLocalizer loc(cfg, cam, geom, &map);
    Stats s;
    for (int rep = 0; rep < a.profile_reps; ++rep) evaluate(loc, frames, &s);
    std::printf("processed %d frames, total median %.3f ms\n", s.n, pct(s.t_total, 50));
    return 0;
  }
  run_visible(a, su, conds, &clean_frames, &combined_frames);
  const bool only_cut = !a.only.empty() && std::string("partly outside").find(a.only) == 0;
  if (!a.only.empty() && !only_cut) return 0;
  run_cut(a, su);
  if (only_cut) return 0;
  run_speed(a, su, clean_frames, combined_frames);
  run_floor(a, su);
  if (a.ablation) run_ablation(su, clean_frames, combined_frames);
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  Args a;
  for (int i = 1; i < argc; ++i) {
    const std::string s = argv[i];
    auto next = [&]() -> std::string {
      if (i + 1 >= argc) {
        std::fprintf(stderr, "missing value for %s\n", s.c_str());
        std::exit(2);
      }
      return argv[++i];
    };
    if (s == "--profile") {
      a.profile = std::atoi(next().c_str());
    } else if (s == "--frames") {
      a.frames = std::atoi(next().c_str());
    } else if (s == "--floor-frames") {
      a.floor_frames = std::atoi(next().c_str());
    } else if (s == "--seed") {
      a.seed = std::strtoull(next().c_str(), nullptr, 10);
    } else if (s == "--ablation") {
      a.ablation = true;
    } else if (s == "--no-apriltag") {
      a.apriltag = false;
    } else if (s == "--dump") {
      a.dump = next();
    } else if (s == "--only") {
      a.only = next();
    } else if (s == "--profile-loop") {
      a.profile_reps = std::atoi(next().c_str());
    } else if (s == "--family") {
      const std::string f = next();
      if (f != "qr" && f != "tag36h11") {
        std::fprintf(stderr, "--family must be qr or tag36h11\n");
        return 2;
      }
      a.tag = f == "tag36h11";
      if (a.tag) a.apriltag = false;  // the AprilTag comparison paints tags into QR frames
    } else if (s == "--speed-compare") {
      a.speed_compare = true;
    } else if (s == "--qr-max-grid-decodes") {
      a.qr_max_grid_decodes = std::atoi(next().c_str());
    } else if (s == "--qr-max-missing") {
      a.qr_max_missing = std::atoi(next().c_str());
    } else if (s == "--row-step") {
      a.row_step = std::atoi(next().c_str());
    } else {
      std::fprintf(
          stderr,
          "usage: eval_vision [--profile 640|1280] [--frames N] [--floor-frames N] "
          "[--seed S] [--ablation] [--no-apriltag] [--dump DIR] [--only NAME] "
          "[--profile-loop REPS] [--qr-max-missing N] [--qr-max-grid-decodes N] [--row-step N] "
          "[--family qr|tag36h11] "
          "[--speed-compare]\n");
      return 2;
    }
  }
  if (a.profile != 640 && a.profile != 1280) {
    std::fprintf(stderr, "--profile must be 640 or 1280\n");
    return 2;
  }
  return run(a);
}
