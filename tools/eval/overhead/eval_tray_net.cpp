// eval_tray_net: the learned tray detector (tray_net.hpp) on rendered frames (hand-run; figures
// in docs/design/overhead.md).
//
//   eval_tray_net --model models/tray_obb.onnx [--frames 40] [--covered-frames 30] [--seed 1]
//                 [--min-score 0.5] [--fuse 1] [--verbose 0]
//
// 1. Recall and precision on held-out frames (a camera height and a lighting not in training):
//    a window around each tray wholly in the frame, centred a few centimetres off (as a track's
//    prediction); a box within 60 mm of a tray's centre is that tray's, any other is a false one.
// 2. Time per 256 x 256 window on one core (cv::setNumThreads(1)): rectification and network.
// 3. Learned against classical fixes of covered trays at 6 m (the tag under a parcel; 60 px tags
//    at 3840 x 2160 = 2.67 mm per pixel on the tray, rendered 1280 x 720 of that resolution):
//    position and heading errors and NEES of each, from predictions drawn around the truth.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <ctime>
#include <fstream>
#include <iterator>
#include <opencv2/core.hpp>
#include <random>
#include <string>
#include <vector>

#include "agv/overhead/tray_fit.hpp"
#include "agv/overhead/tray_net.hpp"
#include "tray_scene.hpp"

namespace {

using namespace agv;
using namespace agv::overhead;

TrayNetParams g_params;  // --min-score, --fuse (0: plain NMS)
bool g_verbose = false;  // --verbose 1: each miss and false box

double pct(std::vector<double> v, double q) {
  if (v.empty()) return 0.0;
  std::sort(v.begin(), v.end());
  return v[static_cast<std::size_t>(std::ceil(q * static_cast<double>(v.size() - 1)))];
}

double mean(const std::vector<double>& v) {
  double s = 0.0;
  for (const double x : v) s += x;
  return v.empty() ? 0.0 : s / static_cast<double>(v.size());
}

double nees(const TagFix& f, const Pose2& t) {
  const double e[3] = {f.pose.x_mm - t.x_mm, f.pose.y_mm - t.y_mm,
                       wrap_angle_rad(f.pose.theta_rad - t.theta_rad)};
  const cv::Matx33d c(f.cov[0], f.cov[1], f.cov[2], f.cov[3], f.cov[4], f.cov[5], f.cov[6],
                      f.cov[7], f.cov[8]);
  const cv::Vec3d ev(e[0], e[1], e[2]);
  return ev.dot(c.inv() * ev);
}

struct Errors {
  std::vector<double> pos_mm, head_deg, nees_v;
  int refused = 0;
  void add(const TagFix& f, const Pose2& t) {
    pos_mm.push_back(std::hypot(f.pose.x_mm - t.x_mm, f.pose.y_mm - t.y_mm));
    head_deg.push_back(std::abs(rad_to_deg(wrap_angle_rad(f.pose.theta_rad - t.theta_rad))));
    nees_v.push_back(nees(f, t));
  }
  void print(const char* name) const {
    std::printf(
        "%-9s fixes %zu, refused %d; position p50 %.2f p95 %.2f max %.2f mm; heading p50 %.3f "
        "p95 %.3f max %.3f deg; NEES mean %.2f, within chi2(3) 99.9%% %.1f%%\n",
        name, pos_mm.size(), refused, pct(pos_mm, 0.5), pct(pos_mm, 0.95), pct(pos_mm, 1.0),
        pct(head_deg, 0.5), pct(head_deg, 0.95), pct(head_deg, 1.0), mean(nees_v),
        100.0 *
            static_cast<double>(
                std::count_if(nees_v.begin(), nees_v.end(), [](double x) { return x <= 16.27; })) /
            std::max<double>(1.0, static_cast<double>(nees_v.size())));
  }
};

void held_out(const TrayNet& net, int frames, std::uint64_t seed) {
  tray_obb::SceneOptions o;
  int tp = 0, fn = 0, fp = 0;
  std::vector<double> centre_mm, axis_deg;
  for (int f = 0; f < frames; ++f) {
    const tray_obb::SceneDraw d = tray_obb::draw_scene(
        seed * 100003 + static_cast<std::uint64_t>(f), tray_obb::Split::kTest, o);
    const sim::RenderResult r =
        sim::render_site_frame(d.scene, sim::RenderCamera::from_ceiling(d.cam), d.render, seed + f);
    for (const sim::AgvTruth& t : r.agvs) {
      if (!tray_obb::tray_in_frame(t, o.width_px, o.height_px)) continue;
      const std::vector<PlaneTray> found = net.detect_on_plane(
          r.image, d.cam, {t.pose.x_mm + 30.0, t.pose.y_mm - 20.0}, o.tray_height_mm, g_params);
      bool hit = false;
      for (const PlaneTray& p : found) {
        bool matched = false;
        for (const sim::AgvTruth& u : r.agvs) {
          const double e = std::hypot(p.centre_mm.x - u.pose.x_mm, p.centre_mm.y - u.pose.y_mm);
          if (e > 60.0) continue;
          matched = true;
          if (u.index == t.index && !hit) {
            hit = true;
            centre_mm.push_back(e);
            const double a = std::abs(wrap_angle_rad(2.0 * (p.axis_rad - u.pose.theta_rad))) / 2;
            axis_deg.push_back(rad_to_deg(a));
          }
        }
        fp += matched ? 0 : 1;
        if (!matched && g_verbose) {
          const double e = std::hypot(p.centre_mm.x - t.pose.x_mm, p.centre_mm.y - t.pose.y_mm);
          std::printf("  false: frame %d, %.0f mm from the window's tray, score %.2f\n", f, e,
                      p.score);
        }
      }
      (hit ? tp : fn) += 1;
      if (!hit && g_verbose) {
        std::printf("  missed: frame %d, tag visible %.2f, %zu boxes in the window\n", f,
                    t.tag_visible_fraction, found.size());
      }
    }
  }
  std::printf(
      "held-out (7 m, dim light, %d frames): %d trays, recall %.4f, precision %.4f (%d missed, %d "
      "false); centre p50 %.1f p95 %.1f mm, axis p50 %.2f p95 %.2f deg\n",
      frames, tp + fn, tp / std::max(1.0, static_cast<double>(tp + fn)),
      tp / std::max(1.0, static_cast<double>(tp + fp)), fn, fp, pct(centre_mm, 0.5),
      pct(centre_mm, 0.95), pct(axis_deg, 0.5), pct(axis_deg, 0.95));
}

void timing(const TrayNet& net) {
  cv::setNumThreads(1);
  tray_obb::SceneOptions o;
  o.fixed_height_mm = 6000.0;
  o.fixed_native_mm_per_px = 160.0 / 60.0;
  const tray_obb::SceneDraw d = tray_obb::draw_scene(4242, tray_obb::Split::kTrain, o);
  const sim::RenderResult r =
      sim::render_site_frame(d.scene, sim::RenderCamera::from_ceiling(d.cam), d.render, 1);
  RectifiedWindow w;
  rectify_window(r.image, d.cam, {0, 0}, o.tray_height_mm, 256, 8.0, &w);
  for (int i = 0; i < 5; ++i) net.detect(w.gray, {});
  // Thread CPU time: the shared machine's other load does not count.
  auto cpu_ms = [] {
    timespec ts{};
    clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
    return 1e3 * static_cast<double>(ts.tv_sec) + 1e-6 * static_cast<double>(ts.tv_nsec);
  };
  const int n = 200;
  double t0 = cpu_ms();
  for (int i = 0; i < n; ++i) net.detect(w.gray, {});
  const double net_ms = (cpu_ms() - t0) / n;
  t0 = cpu_ms();
  for (int i = 0; i < n; ++i) rectify_window(r.image, d.cam, {10.0 * i, 0}, 400.0, 256, 8.0, &w);
  const double rect_ms = (cpu_ms() - t0) / n;
  std::printf(
      "one core (thread CPU time): network + decode %.2f ms per 256 x 256 window, rectification "
      "%.2f ms (from a "
      "frame of 2.67 mm per pixel)\n",
      net_ms, rect_ms);
}

void learned_vs_classical(const TrayNet& net, int frames, std::uint64_t seed) {
  tray_obb::SceneOptions o;
  o.fixed_height_mm = 6000.0;
  o.fixed_native_mm_per_px = 160.0 / 60.0;
  o.all_covered = true;
  std::mt19937_64 rng(seed);
  std::normal_distribution<double> n01;
  const double sp = 20.0, st = deg_to_rad(3.0);
  const std::array<double, 9> cov{sp * sp, 0, 0, 0, sp * sp, 0, 0, 0, st * st};
  Errors learned, classical;
  int trays = 0;
  for (int f = 0; f < frames; ++f) {
    const tray_obb::SceneDraw d = tray_obb::draw_scene(seed * 7777 + static_cast<std::uint64_t>(f),
                                                       tray_obb::Split::kTrain, o);
    const sim::RenderResult r =
        sim::render_site_frame(d.scene, sim::RenderCamera::from_ceiling(d.cam), d.render, seed + f);
    for (const sim::AgvTruth& t : r.agvs) {
      if (!tray_obb::tray_in_frame(t, o.width_px, o.height_px) || t.tag_visible_fraction > 0.0) {
        continue;
      }
      ++trays;
      const Pose2 pred{t.pose.x_mm + sp * n01(rng), t.pose.y_mm + sp * n01(rng),
                       t.pose.theta_rad + st * n01(rng)};
      const site::FleetAgv& agv = d.scene.site.fleet[t.index];
      TrayFix tf;
      if (fit_tray(r.image, d.cam, agv, pred, cov, {}, &tf)) {
        classical.add(tf.fix, t.pose);
      } else {
        ++classical.refused;
      }
      TagFix lf;
      bool ok = false;
      const PlaneTray* best = nullptr;
      double best_d = 200.0;
      const std::vector<PlaneTray> found =
          net.detect_on_plane(r.image, d.cam, {pred.x_mm, pred.y_mm}, agv.tray_height_mm, g_params);
      for (const PlaneTray& p : found) {
        const double dd = std::hypot(p.centre_mm.x - pred.x_mm, p.centre_mm.y - pred.y_mm);
        if (dd < best_d) best = &p, best_d = dd;
      }
      ok = best && tray_box_fix(*best, agv, pred, cov, g_params, net.geometry().mm_per_px, &lf);
      if (ok) {
        learned.add(lf, t.pose);
      } else {
        ++learned.refused;
      }
    }
  }
  std::printf("covered trays at 6 m, 2.67 mm per pixel: %d trays in %d frames\n", trays, frames);
  classical.print("classical");
  learned.print("learned");
}

}  // namespace

int main(int argc, char** argv) {
  std::string model;
  int frames = 40, covered = 30;
  std::uint64_t seed = 1;
  for (int i = 1; i + 1 < argc; i += 2) {
    const std::string k = argv[i], v = argv[i + 1];
    if (k == "--model")
      model = v;
    else if (k == "--frames")
      frames = std::atoi(v.c_str());
    else if (k == "--covered-frames")
      covered = std::atoi(v.c_str());
    else if (k == "--min-score")
      g_params.min_score = std::atof(v.c_str());
    else if (k == "--verbose")
      g_verbose = std::atoi(v.c_str()) != 0;
    else if (k == "--fuse")
      g_params.fuse_boxes = std::atoi(v.c_str()) != 0;
    else if (k == "--seed")
      seed = std::strtoull(v.c_str(), nullptr, 10);
    else {
      std::fprintf(stderr, "eval_tray_net: unknown option %s\n", k.c_str());
      return 2;
    }
  }
  std::ifstream f(model, std::ios::binary);
  const std::string bytes((std::istreambuf_iterator<char>(f)), std::istreambuf_iterator<char>());
  TrayNet net;
  std::string error;
  if (!net.load(bytes.data(), bytes.size(), &error)) {
    std::fprintf(stderr, "eval_tray_net: %s: %s\n", model.c_str(), error.c_str());
    return 2;
  }
  timing(net);
  if (frames > 0) held_out(net, frames, seed);
  if (covered > 0) learned_vs_classical(net, covered, seed);
  return 0;
}
