// render_ranging_stream: adds a second camera's stream (ranging/) to a simulated recording, for
// the drive evaluation of docs/design/ranging.md ("Drive evaluation"; driver:
// tools/eval/ranging/rack_drive_eval.sh). The site is generated here: one rack between the two
// aisles of the sim's two-row lawnmower, with pairs of tag36h11 landmarks on both long faces every
// cluster period and a pair on each end face. A camera looking left renders each frame at the
// recording's truth pose (linear between truth rows) with the site renderer's realistic effects
// (defocus, illumination gradient, vignetting, read and shot noise). Writes REC/ranging/frames.csv
// and the PNGs, REC/ranging_site.yaml and REC/ranging.yaml (the replay configuration). Not a
// ctest.
// Usage: render_ranging_stream REC [--fps 10] [--rack-y0-mm 1200] [--rack-y1-mm 2800]
//        [--rack-x0-mm 500] [--rack-x1-mm 8200] [--cluster-period-mm 2000] [--pair-gap-mm 500]
//        [--clean] [--seed 1]
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <map>
#include <string>
#include <vector>

#include "agv/recording/recording.hpp"
#include "agv/sim/ranging_camera.hpp"
#include "agv/sim/site_render.hpp"
#include "agv/site/site_file.hpp"

namespace {

using namespace agv;
namespace fs = std::filesystem;

constexpr int kWidthPx = 640;
constexpr int kHeightPx = 400;
constexpr double kFocalPx = 400.0;
constexpr double kMountXMm = 200.0;  // camera on the vehicle's left side, 1 m up, looking left
constexpr double kMountYMm = 250.0;
constexpr double kMountZMm = 1000.0;
constexpr double kMountYawDeg = 90.0;
constexpr double kTagZMm = 1000.0;
constexpr double kTagSizeMm = 150.0;
constexpr double kFirstClusterMm = 500.0;  // first pair's centre from the rack's start

struct Options {
  std::string rec;
  double fps = 10.0;
  double rack_x0_mm = 500.0, rack_x1_mm = 8200.0;
  double rack_y0_mm = 1200.0, rack_y1_mm = 2800.0;
  double cluster_period_mm = 2000.0;
  double pair_gap_mm = 500.0;
  bool clean = false;
  std::uint64_t seed = 1;
};

int usage(const char* why) {
  std::fprintf(stderr,
               "render_ranging_stream: %s\nusage: render_ranging_stream REC [--fps F] "
               "[--rack-x0-mm X] [--rack-x1-mm X] [--rack-y0-mm Y] [--rack-y1-mm Y] "
               "[--cluster-period-mm D] [--pair-gap-mm G] [--clean] [--seed N]\n",
               why);
  return 2;
}

bool parse_args(int argc, char** argv, Options* o) {
  std::map<std::string, double*> num = {{"--fps", &o->fps},
                                        {"--rack-x0-mm", &o->rack_x0_mm},
                                        {"--rack-x1-mm", &o->rack_x1_mm},
                                        {"--rack-y0-mm", &o->rack_y0_mm},
                                        {"--rack-y1-mm", &o->rack_y1_mm},
                                        {"--cluster-period-mm", &o->cluster_period_mm},
                                        {"--pair-gap-mm", &o->pair_gap_mm}};
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    if (a == "--clean") {
      o->clean = true;
    } else if (a == "--seed" && i + 1 < argc) {
      o->seed = std::strtoull(argv[++i], nullptr, 10);
    } else if (num.count(a) && i + 1 < argc) {
      char* end = nullptr;
      *num[a] = std::strtod(argv[++i], &end);
      if (end == nullptr || *end != '\0' || !std::isfinite(*num[a])) return false;
    } else if (a.rfind("--", 0) != 0 && o->rec.empty()) {
      o->rec = a;
    } else {
      return false;
    }
  }
  return !o->rec.empty() && o->fps > 0.0 && o->rack_x1_mm > o->rack_x0_mm &&
         o->rack_y1_mm > o->rack_y0_mm && o->cluster_period_mm > o->pair_gap_mm &&
         o->pair_gap_mm > kTagSizeMm;
}

CameraIntrinsics intrinsics() {
  CameraIntrinsics k;
  k.width_px = kWidthPx;
  k.height_px = kHeightPx;
  k.fx = k.fy = kFocalPx;
  k.cx = 0.5 * kWidthPx - 0.5;
  k.cy = 0.5 * kHeightPx - 0.5;
  return k;
}

ranging::RangingMount mount() {
  ranging::RangingMount m;
  m.x_mm = kMountXMm;
  m.y_mm = kMountYMm;
  m.z_mm = kMountZMm;
  m.yaw_rad = kMountYawDeg * kPi / 180.0;
  return m;
}

// The rack, its landmarks and an outline around the whole drive.
sim::SiteScene rack_site(const Options& o) {
  sim::SiteScene s;
  s.site.name = "rack drive";
  const double x0 = o.rack_x0_mm, x1 = o.rack_x1_mm, y0 = o.rack_y0_mm, y1 = o.rack_y1_mm;
  s.site.outline.vertices_mm = {{x0 - 3000, y0 - 3000},
                                {x1 + 5000, y0 - 3000},
                                {x1 + 5000, y1 + 3000},
                                {x0 - 3000, y1 + 3000}};
  site::Obstacle rack;
  rack.id = "rack";
  rack.outline.vertices_mm = {{x0, y0}, {x1, y0}, {x1, y1}, {x0, y1}};
  rack.height_mm = 2500.0;
  s.site.obstacles.push_back(rack);
  std::uint32_t id = 101;
  auto add = [&](double x, double y, double facing_rad) {
    s.site.wall_landmarks.push_back(
        {id++, site::LandmarkFamily::kTag36h11, x, y, kTagZMm, facing_rad, kTagSizeMm});
  };
  const double half = 0.5 * o.pair_gap_mm;
  for (double c = x0 + kFirstClusterMm; c + half < x1; c += o.cluster_period_mm) {
    add(c - half, y0, -kPi / 2);  // seen from the aisle below the rack
    add(c + half, y0, -kPi / 2);
    add(c - half, y1, kPi / 2);  // seen from the aisle above
    add(c + half, y1, kPi / 2);
  }
  const double ym = 0.5 * (y0 + y1);
  for (double dy : {-half, half}) {
    add(x1, ym + dy, 0.0);  // the end the U-turn faces
    add(x0, ym + dy, kPi);  // the end the return leg faces
  }
  return s;
}

Pose2 truth_at(const std::vector<recording::TruthRow>& tr, std::int64_t t_ns) {
  auto it =
      std::lower_bound(tr.begin(), tr.end(), t_ns,
                       [](const recording::TruthRow& r, std::int64_t t) { return r.t_ns < t; });
  if (it == tr.begin()) return {it->x_mm, it->y_mm, it->theta_deg * kPi / 180.0};
  if (it == tr.end()) --it;
  const recording::TruthRow& b = *it;
  const recording::TruthRow& a = *(it - 1);
  const double f = b.t_ns == a.t_ns
                       ? 0.0
                       : static_cast<double>(t_ns - a.t_ns) / static_cast<double>(b.t_ns - a.t_ns);
  const double dth = std::remainder(b.theta_deg - a.theta_deg, 360.0);
  return {a.x_mm + f * (b.x_mm - a.x_mm), a.y_mm + f * (b.y_mm - a.y_mm),
          (a.theta_deg + f * dth) * kPi / 180.0};
}

bool write_config(const Options& o, std::string* err) {
  std::ofstream(fs::path(o.rec) / "ranging_site.yaml") << site::write_site(rack_site(o).site);
  std::ofstream f(fs::path(o.rec) / "ranging.yaml");
  f << "# Second camera of the rack drive evaluation (render_ranging_stream).\n"
    << "ranging_camera:\n  enabled: true\n  driver: replay\n  site: ranging_site.yaml\n"
    << "  width: " << kWidthPx << "\n  height: " << kHeightPx << "\n  fps: " << o.fps << "\n"
    << "  intrinsics: {fx: " << kFocalPx << ", fy: " << kFocalPx << ", cx: " << intrinsics().cx
    << ", cy: " << intrinsics().cy << "}\n"
    << "  mount: {x_mm: " << kMountXMm << ", y_mm: " << kMountYMm << ", z_mm: " << kMountZMm
    << ", yaw_deg: " << kMountYawDeg << "}\n";
  if (!f) *err = "cannot write ranging.yaml";
  return static_cast<bool>(f);
}

}  // namespace

int main(int argc, char** argv) {
  Options o;
  if (!parse_args(argc, argv, &o)) return usage("bad arguments");
  std::string text, err;
  std::vector<recording::TruthRow> truth;
  if (!recording::read_file_bounded((fs::path(o.rec) / "truth.csv").string(), 1u << 28, &text,
                                    &err) ||
      !recording::parse_truth_csv(text, &truth, &err) || truth.size() < 2) {
    std::fprintf(stderr, "render_ranging_stream: %s\n",
                 err.empty() ? "truth.csv too short" : err.c_str());
    return 1;
  }
  const sim::SiteScene scene = rack_site(o);
  const sim::SiteFrameRenderer renderer(intrinsics());
  const sim::SiteRenderParams params =
      o.clean ? sim::SiteRenderParams{} : sim::realistic_site_params();
  const fs::path dir = fs::path(o.rec) / "ranging";
  fs::create_directories(dir);
  const auto period_ns = static_cast<std::int64_t>(std::llround(1e9 / o.fps));
  std::vector<recording::FrameRow> rows;
  int tags_seen = 0, frames_with_two = 0;
  const auto t0 = std::chrono::steady_clock::now();
  for (std::int64_t t = truth.front().t_ns; t <= truth.back().t_ns; t += period_ns) {
    const sim::RenderCamera cam = sim::ranging_camera(intrinsics(), truth_at(truth, t), mount());
    const sim::RenderResult r = renderer.render(scene, cam, params, o.seed * 100003 + rows.size());
    int in_view = 0;
    for (const sim::WallLandmarkTruth& w : r.wall_landmarks) {
      in_view += w.projected && w.visible_fraction > 0.99 ? 1 : 0;
    }
    tags_seen += in_view;
    frames_with_two += in_view >= 2 ? 1 : 0;
    const std::string file = std::to_string(rows.size()) + ".png";
    if (!recording::write_frame_png(dir.string(), file, r.image, &err)) {
      std::fprintf(stderr, "render_ranging_stream: %s\n", err.c_str());
      return 1;
    }
    rows.push_back({t, file});
  }
  const double render_s =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  if (!recording::write_frames_csv(dir.string(), rows, &err) || !write_config(o, &err)) {
    std::fprintf(stderr, "render_ranging_stream: %s\n", err.c_str());
    return 1;
  }
  std::printf(
      "render_ranging_stream: %zu frames (%d x %d, %.0f fps), %zu rack landmarks, %.2f tags fully "
      "in view per frame, %.1f %% of frames with 2+; %.1f s (%.1f ms/frame incl. PNG)\n",
      rows.size(), kWidthPx, kHeightPx, o.fps, scene.site.wall_landmarks.size(),
      static_cast<double>(tags_seen) / static_cast<double>(rows.size()),
      100.0 * frames_with_two / static_cast<double>(rows.size()), render_s,
      1000.0 * render_s / static_cast<double>(rows.size()));
  return 0;
}
