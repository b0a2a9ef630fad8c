// Evaluation program (not a test): cost of a landmark frame with the prediction's search windows
// against the full-frame search, in the same run on the same frames (docs/design/tracking.md).
// Frames: the simulator's realistic profile over the default 1 m grid, one landmark fully in view
// at a random offset and heading. Prediction: the truth moved by a Gaussian error of the stated
// sigma, with that covariance (what the filter reports between fixes).
//   eval_tracking [--frames N] [--sigma-mm S] [--sigma-deg D] [--seed K] [--row-step N]
//                 [--detect-from-prediction 0|1] [--probe-edges 0|1] [--logo-at-code-turn 0|1]
//                 [--condition realistic|motion7|occluder15|dirt|combined|stress]
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <random>
#include <string>
#include <vector>

#include "agv/sim/render.hpp"
#include "agv/vision/landmark_localizer.hpp"
#include "agv/vision/tracking.hpp"
#include "degradations.hpp"

using namespace agv;

namespace {

double median(std::vector<double> v) {
  if (v.empty()) return 0.0;
  std::sort(v.begin(), v.end());
  const size_t n = v.size();
  return n % 2 ? v[n / 2] : 0.5 * (v[n / 2 - 1] + v[n / 2]);
}

// Nearest-rank percentile (q in [0, 1]).
double percentile(std::vector<double> v, double q) {
  if (v.empty()) return 0.0;
  std::sort(v.begin(), v.end());
  const size_t k = static_cast<size_t>(std::ceil(q * static_cast<double>(v.size())));
  return v[std::min(v.size() - 1, k == 0 ? 0 : k - 1)];
}

std::int64_t now_ns() {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(
             std::chrono::steady_clock::now().time_since_epoch())
      .count();
}

constexpr double kSameFixMm = 0.005;
constexpr double kSameFixDeg = 0.002;

// The degradations of eval_vision's conditions on top of the realistic rendering; false for an
// unknown name.
bool degrade(const std::string& name, double mm_per_px, std::mt19937_64& rng,
             sim::RenderOptions* o) {
  if (name == "realistic") return true;
  if (name == "motion7") {
    bench::motion_blur(7.0, mm_per_px, o);
  } else if (name == "occluder15") {
    o->occluder_border_fraction = 0.15;
  } else if (name == "dirt") {
    o->scratches_per_landmark = 3;
    o->dirt_spots_per_landmark = 3;
  } else if (name == "combined") {
    bench::combined_degradations(mm_per_px, rng, o);
  } else if (name == "stress") {
    bench::stress_degradations(mm_per_px, o);
  } else {
    return false;
  }
  return true;
}

}  // namespace

int main(int argc, char** argv) {
  int frames = 200;
  double sigma_mm = 3.0, sigma_deg = 0.3;
  unsigned seed = 1;
  int row_step = 0;          // 0: VisionConfig's default
  int from_prediction = -1;  // -1: TrackingConfig's default
  int probe_edges = -1;      // likewise
  int logo_one_turn = -1;    // likewise (TrackingConfig::logo_at_code_turn)
  // Rendering on top of sim::realistic_options (the degradations of eval_vision's conditions):
  // realistic, motion7, occluder15, dirt, combined (each at random up to those), stress.
  std::string condition = "realistic";
  for (int i = 1; i + 1 < argc; i += 2) {
    if (!std::strcmp(argv[i], "--frames")) frames = std::atoi(argv[i + 1]);
    if (!std::strcmp(argv[i], "--sigma-mm")) sigma_mm = std::atof(argv[i + 1]);
    if (!std::strcmp(argv[i], "--sigma-deg")) sigma_deg = std::atof(argv[i + 1]);
    if (!std::strcmp(argv[i], "--seed")) seed = static_cast<unsigned>(std::atoi(argv[i + 1]));
    if (!std::strcmp(argv[i], "--row-step")) row_step = std::atoi(argv[i + 1]);
    if (!std::strcmp(argv[i], "--detect-from-prediction")) {
      from_prediction = std::atoi(argv[i + 1]);
    }
    if (!std::strcmp(argv[i], "--probe-edges")) probe_edges = std::atoi(argv[i + 1]);
    if (!std::strcmp(argv[i], "--logo-at-code-turn")) logo_one_turn = std::atoi(argv[i + 1]);
    if (!std::strcmp(argv[i], "--condition")) condition = argv[i + 1];
  }
  const LandmarkMap map = sim::default_landmark_grid();
  const CameraModel cam = CameraModel::default_640x480();
  const LandmarkGeometry geom;
  sim::Scene scene;
  std::string err;
  if (!sim::make_scene(map, geom, sim::PayloadMode::kFull, &scene, &err)) {
    std::fprintf(stderr, "%s\n", err.c_str());
    return 1;
  }
  sim::FrameRenderer renderer(scene, cam);
  vision::VisionConfig vc;
  vc.now_ns = now_ns;
  if (row_step > 0) vc.edge_row_step = row_step;
  if (from_prediction >= 0) vc.tracking.detect_from_prediction = from_prediction != 0;
  if (probe_edges >= 0) vc.tracking.probe_edges = probe_edges != 0;
  if (logo_one_turn >= 0) vc.tracking.logo_at_code_turn = logo_one_turn != 0;
  std::printf("edge row step: %d\n", vc.edge_row_step);
  vision::LandmarkLocalizer loc(vc, cam, geom, &map);
  vision::WindowPlanner planner(vc, cam, geom, &map);
  std::vector<vision::SearchWindow> windows;
  std::vector<double> area_frac;
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> ux(-15.0, 15.0), uy(-35.0, 35.0), uh(-kPi, kPi);
  std::normal_distribution<double> n01(0.0, 1.0);
  std::vector<const LandmarkMapEntry*> entries;
  for (const auto& [id, e] : map.entries) entries.push_back(&e);
  std::vector<double> full_ms, win_ms, full_det, win_det;
  // The tracked frame's other stages: where the time goes once the corner search is skipped.
  std::vector<double> win_decode, win_dir, win_pose;
  // Error of each fix against the rendered truth: the accuracy the tracked detection must keep.
  std::vector<double> full_err_mm, win_err_mm, full_err_deg, win_err_deg;
  int ok_full = 0, ok_win = 0, in_window = 0, then_full = 0, differ = 0, not_bitwise = 0,
      tracked = 0, predicted = 0, probed = 0, one_turn = 0;
  double worst_deg = 0.0;
  double worst_mm = 0.0;
  for (int i = 0; i < frames; ++i) {
    const LandmarkMapEntry& e = *entries[rng() % entries.size()];
    const Pose2 lm_in_v{ux(rng), uy(rng), uh(rng)};
    const Pose2 truth = compose(e.pose, inverse(lm_in_v));
    sim::RenderOptions ro = sim::realistic_options();
    if (!degrade(condition, cam.mm_per_px(), rng, &ro)) {
      std::fprintf(stderr, "eval_tracking: unknown --condition %s\n", condition.c_str());
      return 2;
    }
    const cv::Mat img = renderer.render(truth, ro, rng);
    vision::Prediction pred;
    pred.valid = true;
    pred.vehicle_in_world = {truth.x_mm + sigma_mm * n01(rng), truth.y_mm + sigma_mm * n01(rng),
                             truth.theta_rad + deg_to_rad(sigma_deg) * n01(rng)};
    const double sh = deg_to_rad(sigma_deg);
    pred.cov = Eigen::Vector3d(sigma_mm * sigma_mm, sigma_mm * sigma_mm, sh * sh).asDiagonal();
    planner.plan(pred, &windows);
    if (!windows.empty()) {
      int x0 = cam.intrinsics.width_px, y0 = cam.intrinsics.height_px, x1 = 0, y1 = 0;
      for (const auto& w : windows) {
        x0 = std::min(x0, w.x0);
        y0 = std::min(y0, w.y0);
        x1 = std::max(x1, w.x1);
        y1 = std::max(y1, w.y1);
      }
      area_frac.push_back(static_cast<double>((x1 - x0) * (y1 - y0)) /
                          (cam.intrinsics.width_px * cam.intrinsics.height_px));
    }
    vision::LandmarkFix full, win;
    // Alternate the order so neither mode always runs on a warm cache.
    for (int k = 0; k < 2; ++k) {
      if ((i + k) % 2 == 0) {
        loc.process(img, vision::Prediction{}, &full);
      } else {
        loc.process(img, pred, &win);
      }
    }
    if (full.status == vision::FixStatus::kOk) ++ok_full;
    if (win.status == vision::FixStatus::kOk) ++ok_win;
    if (win.search == vision::SearchMode::kWindow) ++in_window;
    if (win.search == vision::SearchMode::kWindowThenFull) ++then_full;
    if (win.detection_predicted) ++predicted;
    if (win.detection_probed) ++probed;
    if (win.logo_one_turn) ++one_turn;
    // The windowed corner search reproduces the full search's detection exactly; the tracked
    // detection (track_detect.cpp) has its own.
    if (win.search == vision::SearchMode::kWindow && !win.detection_predicted &&
        (win.detect_x_px != full.detect_x_px || win.detect_y_px != full.detect_y_px)) {
      ++tracked;
    }
    const auto add_error = [&truth](const vision::LandmarkFix& f, std::vector<double>* mm,
                                    std::vector<double>* deg) {
      if (f.status != vision::FixStatus::kOk) return;
      mm->push_back(
          std::hypot(f.vehicle_in_world.x_mm - truth.x_mm, f.vehicle_in_world.y_mm - truth.y_mm));
      deg->push_back(
          std::abs(rad_to_deg(wrap_angle_rad(f.vehicle_in_world.theta_rad - truth.theta_rad))));
    };
    add_error(full, &full_err_mm, &full_err_deg);
    add_error(win, &win_err_mm, &win_err_deg);
    if (full.status != vision::FixStatus::kOk) continue;
    full_ms.push_back(full.timings.total_ms);
    win_ms.push_back(win.timings.total_ms);
    full_det.push_back(full.timings.detect_ms);
    win_det.push_back(win.timings.detect_ms);
    win_decode.push_back(win.timings.decode_ms);
    win_dir.push_back(win.timings.direction_ms);
    win_pose.push_back(win.timings.pose_ms);
    if (win.status != full.status || win.landmark_id != full.landmark_id ||
        win.identity != full.identity) {
      ++differ;
      continue;
    }
    // The tracked detection starts the pose stage from its own estimate: the fix agrees to the
    // tolerance of tests/vision/test_tracking.cpp, not bit for bit.
    const double d = std::hypot(win.vehicle_in_world.x_mm - full.vehicle_in_world.x_mm,
                                win.vehicle_in_world.y_mm - full.vehicle_in_world.y_mm);
    const double dh = std::abs(rad_to_deg(
        wrap_angle_rad(win.vehicle_in_world.theta_rad - full.vehicle_in_world.theta_rad)));
    worst_mm = std::max(worst_mm, d);
    worst_deg = std::max(worst_deg, dh);
    if (d > 1e-9 || dh > 1e-9) ++not_bitwise;
    if (d > kSameFixMm || dh > kSameFixDeg) ++differ;
  }
  std::printf("eval_tracking: %d frames, prediction sigma %.1f mm / %.2f deg, condition %s\n",
              frames, sigma_mm, sigma_deg, condition.c_str());
  std::printf("  fixes: full %d, tracking %d; found in window %d, window then full %d\n", ok_full,
              ok_win, in_window, then_full);
  std::printf("  tracked detection (prediction replaced the corner search): %d\n", tracked);
  std::printf("  detection from the prediction (no detection ran): %d, of which edge probes %d\n",
              predicted, probed);
  std::printf("  logo scored at the verified code's turn only: %d\n", one_turn);
  std::printf("  window: median %.0f %% of the frame (margin %.1f mm beyond the outer corners)\n",
              100.0 * median(area_frac), planner.margin_mm());
  std::printf(
      "  same fix as full search (status, id, identity, pose within %.3f mm / %.3f deg): %d of %zu "
      "differ; %d not bit-identical (worst %.2e mm, %.2e deg)\n",
      kSameFixMm, kSameFixDeg, differ, full_ms.size(), not_bitwise, worst_mm, worst_deg);
  std::printf(
      "  error vs truth p95 / max: full %.4f / %.4f mm, %.4f / %.4f deg; tracking %.4f / %.4f mm, "
      "%.4f / %.4f deg\n",
      percentile(full_err_mm, 0.95), percentile(full_err_mm, 1.0), percentile(full_err_deg, 0.95),
      percentile(full_err_deg, 1.0), percentile(win_err_mm, 0.95), percentile(win_err_mm, 1.0),
      percentile(win_err_deg, 0.95), percentile(win_err_deg, 1.0));
  std::printf("  median per landmark frame  total: full %.3f ms, tracking %.3f ms (x%.2f)\n",
              median(full_ms), median(win_ms), median(full_ms) / std::max(1e-9, median(win_ms)));
  std::printf("  median per landmark frame detect: full %.3f ms, tracking %.3f ms (x%.2f)\n",
              median(full_det), median(win_det),
              median(full_det) / std::max(1e-9, median(win_det)));
  std::printf(
      "  median per tracked landmark frame: decode %.3f ms, direction %.3f ms, pose %.3f ms\n",
      median(win_decode), median(win_dir), median(win_pose));
  return 0;
}
