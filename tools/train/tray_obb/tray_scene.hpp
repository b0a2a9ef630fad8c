// Random ceiling-camera scenes for the learned tray detector: its training and test sets
// (make_dataset.cpp), its evaluation (tools/eval/overhead/eval_tray_net.cpp) and its CI check
// (tests/overhead/test_tray_net.cpp) draw frames from here. A split holds out one camera height
// and one lighting: the training frames never see the test's.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <random>
#include <string>
#include <vector>

#include "agv/overhead/tag_fix.hpp"
#include "agv/sim/site_render.hpp"

namespace agv::tray_obb {

enum class Split { kTrain, kTest };

struct SceneDraw {
  sim::SiteScene scene;
  sim::SiteRenderParams render;
  site::CeilingCamera cam;
  double camera_height_mm = 0.0;
  double native_mm_per_px = 0.0;  // the frame's pixel on the tray plane at the image centre
  std::string lighting;           // "train" or the held-out "dim-gradient"
};

struct SceneOptions {
  int width_px = 1280, height_px = 720;
  // Camera height: training draws from 4..8 m except held_out_height_mm +- gap; the test set
  // uses held_out_height_mm. Negative: draw from the training range whatever the split.
  double held_out_height_mm = 7000.0;
  double held_out_gap_mm = 400.0;
  double fixed_height_mm = -1.0;      // > 0: every frame at this height (evaluation at 6 m)
  double native_mm_per_px_min = 3.0;  // the frame's resolution on the tray plane
  double native_mm_per_px_max = 9.0;
  double fixed_native_mm_per_px = -1;  // > 0: this resolution
  int agvs_min = 3, agvs_max = 8;
  double tray_length_mm = 600.0, tray_width_mm = 400.0, tray_height_mm = 400.0;
  double tag_size_mm = 160.0;
  double covered_fraction = 0.35;  // vehicles with a parcel over the whole tag
  bool all_covered = false;        // every vehicle's tag under a parcel (evaluation)
  // Vehicles given one more parcel, heavy and tall, overhanging the tray's sides: the case that
  // pulls a detector's box off the tray (training only; 0 keeps the frames as before).
  double overhang_fraction = 0.0;
};

// Camera 6-DoF: looking down from height_mm over the origin, turned yaw about the optical axis,
// tilted by tilt_x / tilt_y (rad) about the image axes.
inline site::CeilingCamera make_camera(int w, int h, double fx, double height_mm, double yaw,
                                       double tilt_x, double tilt_y, double k1) {
  site::CeilingCamera c;
  c.id = "cam0";
  CameraIntrinsics& k = c.intrinsics;
  k.width_px = w;
  k.height_px = h;
  k.fx = fx;
  k.fy = fx;
  k.cx = 0.5 * w - 0.5;
  k.cy = 0.5 * h - 0.5;
  k.k1 = k1;
  k.k2 = 0.0;
  const double ca = std::cos(yaw), sa = std::sin(yaw);
  const double cx = std::cos(tilt_x), sx = std::sin(tilt_x);
  const double cy = std::cos(tilt_y), sy = std::sin(tilt_y);
  const double r0[9] = {1, 0, 0, 0, -1, 0, 0, 0, -1};
  const double rz[9] = {ca, -sa, 0, sa, ca, 0, 0, 0, 1};
  const double rx[9] = {1, 0, 0, 0, cx, -sx, 0, sx, cx};
  const double ry[9] = {cy, 0, sy, 0, 1, 0, -sy, 0, cy};
  auto mul = [](const double* a, const double* b, double* o) {
    for (int i = 0; i < 3; ++i) {
      for (int j = 0; j < 3; ++j) {
        o[3 * i + j] = 0.0;
        for (int l = 0; l < 3; ++l) o[3 * i + j] += a[3 * i + l] * b[3 * l + j];
      }
    }
  };
  double m1[9], m2[9], r[9];
  mul(r0, rz, m1);
  mul(m1, rx, m2);
  mul(m2, ry, r);
  for (int i = 0; i < 9; ++i) c.r_site_cam[static_cast<std::size_t>(i)] = r[i];
  c.t_site_cam_mm = {0.0, 0.0, height_mm};
  return c;
}

inline double draw_height(std::mt19937_64& rng, Split split, const SceneOptions& o) {
  if (o.fixed_height_mm > 0.0) return o.fixed_height_mm;
  if (split == Split::kTest && o.held_out_height_mm > 0.0) return o.held_out_height_mm;
  std::uniform_real_distribution<double> u(4000.0, 8000.0);
  for (;;) {
    const double h = u(rng);
    if (o.held_out_height_mm <= 0.0 || std::abs(h - o.held_out_height_mm) > o.held_out_gap_mm) {
      return h;
    }
  }
}

// Lighting: training draws gain, gradient and vignetting around the realistic camera's; the
// held-out lighting is dimmer with a steeper gradient than any training frame.
inline void draw_lighting(std::mt19937_64& rng, Split split, SceneDraw* d) {
  std::uniform_real_distribution<double> u(0.0, 1.0);
  sim::SiteRenderParams& p = d->render;
  p = sim::realistic_site_params();
  p.exposure_s = 0.008 * u(rng);
  p.defocus_sigma_px = 0.3 + 0.9 * u(rng);
  p.read_noise_sigma = 1.0 + 3.0 * u(rng);
  p.illumination_direction_deg = 360.0 * u(rng);
  if (split == Split::kTest) {
    p.exposure_gain = 0.55;
    p.illumination_ratio = 0.55;
    p.vignetting = 0.45;
    d->lighting = "dim-gradient";
  } else {
    p.exposure_gain = 0.75 + 0.6 * u(rng);
    p.illumination_ratio = 0.75 + 0.25 * u(rng);
    p.vignetting = 0.3 * u(rng);
    d->lighting = "train";
  }
}

// SceneOptions::overhang_fraction: from its own generator, so that 0 leaves the frames unchanged.
inline void add_overhanging_parcels(std::uint64_t seed, const SceneOptions& o, sim::SiteScene* s) {
  if (!(o.overhang_fraction > 0.0)) return;
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  for (std::size_t i = 0; i < s->agvs.size(); ++i) {
    if (!(u(rng) < o.overhang_fraction)) continue;
    sim::Parcel p;
    p.agv = i;
    p.length_mm = o.tray_length_mm * (0.6 + 0.55 * u(rng));
    p.width_mm = o.tray_width_mm * (0.6 + 0.6 * u(rng));
    p.x_mm = 0.25 * o.tray_length_mm * (2.0 * u(rng) - 1.0);
    p.y_mm = 0.3 * o.tray_width_mm * (2.0 * u(rng) - 1.0);
    p.yaw_rad = 0.5 * (2.0 * u(rng) - 1.0);
    p.height_mm = 200.0 + 250.0 * u(rng);
    p.grey = 60.0 + 170.0 * u(rng);
    s->parcels.push_back(p);
  }
}

// One random frame's scene: camera, fleet in its view, parcels (some over the whole tag),
// clutter, floor, lighting.
inline SceneDraw draw_scene(std::uint64_t seed, Split split, const SceneOptions& o) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  SceneDraw d;
  d.camera_height_mm = draw_height(rng, split, o);
  const double range = d.camera_height_mm - o.tray_height_mm;
  d.native_mm_per_px =
      o.fixed_native_mm_per_px > 0.0
          ? o.fixed_native_mm_per_px
          : o.native_mm_per_px_min + (o.native_mm_per_px_max - o.native_mm_per_px_min) * u(rng);
  const double fx = range / d.native_mm_per_px;
  const double tilt = deg_to_rad(6.0);
  d.cam = make_camera(o.width_px, o.height_px, fx, d.camera_height_mm, kPi * (2.0 * u(rng) - 1.0),
                      tilt * (2.0 * u(rng) - 1.0), tilt * (2.0 * u(rng) - 1.0), -0.08 * u(rng));
  sim::SiteScene& s = d.scene;
  s.site.name = "tray_obb";
  // The floor seen by the camera at tray height, a little inside the image.
  const double hw = 0.5 * o.width_px * d.native_mm_per_px,
               hh = 0.5 * o.height_px * d.native_mm_per_px;
  const double half = std::max(hw, hh) + 2000.0;
  s.site.outline.vertices_mm = {{-half, -half}, {half, -half}, {half, half}, {-half, half}};
  s.site.cameras.push_back(d.cam);
  s.floor.mean = 100.0 + 70.0 * u(rng);
  s.floor.amplitude = 10.0 + 50.0 * u(rng);
  s.floor.seed = seed;
  s.tray_grey = 70.0 + 60.0 * u(rng);
  s.body_grey = 40.0 + 60.0 * u(rng);
  const int n = o.agvs_min + static_cast<int>((o.agvs_max - o.agvs_min + 1) * u(rng) * 0.999);
  // Vehicles at random free spots of a floor the size of the view (some reach its edge).
  sim::SiteScene view = s;
  const double r = std::max(hw, hh);
  view.site.outline.vertices_mm = {{-r, -r}, {r, -r}, {r, r}, {-r, r}};
  const std::vector<Pose2> poses = sim::random_free_poses(view.site, n, 380.0, seed ^ 0x5151);
  for (std::size_t i = 0; i < poses.size(); ++i) {
    site::FleetAgv a;
    a.id = "agv" + std::to_string(i);
    a.tag_id = static_cast<std::uint32_t>(1 + 3 * i);
    a.tag_size_mm = o.tag_size_mm;
    a.tray_length_mm = o.tray_length_mm;
    a.tray_width_mm = o.tray_width_mm;
    a.tray_height_mm = o.tray_height_mm;
    s.site.fleet.push_back(a);
    sim::AgvState st;
    st.pose = poses[i];
    st.v_mps = 1.5 * u(rng);
    st.omega_radps = 1.0 * (2.0 * u(rng) - 1.0);
    s.agvs.push_back(st);
  }
  sim::add_random_parcels(&s, u(rng), seed ^ 0x7a7a);
  for (std::size_t i = 0; i < s.agvs.size(); ++i) {
    if (!(o.all_covered || u(rng) < o.covered_fraction)) continue;
    // A box over the whole tag (and some of the tray), as the tray-fit tests draw them.
    sim::Parcel p;
    p.agv = i;
    p.x_mm = 40.0 * (2.0 * u(rng) - 1.0);
    p.y_mm = 30.0 * (2.0 * u(rng) - 1.0);
    p.yaw_rad = 0.3 * (2.0 * u(rng) - 1.0);
    p.length_mm = 250.0 + 150.0 * u(rng);
    p.width_mm = 230.0 + 100.0 * u(rng);
    p.height_mm = 80.0 + 250.0 * u(rng);
    p.grey = 60.0 + 170.0 * u(rng);
    if (o.all_covered) {
      s.parcels.erase(std::remove_if(s.parcels.begin(), s.parcels.end(),
                                     [&](const sim::Parcel& q) { return q.agv == i; }),
                      s.parcels.end());
    }
    s.parcels.push_back(p);
  }
  add_overhanging_parcels(seed ^ 0x0a0a, o, &s);
  const int people = static_cast<int>(3.0 * u(rng)), pallets = static_cast<int>(3.0 * u(rng));
  sim::add_random_clutter(&s, people, pallets, seed ^ 0x3c3c);
  draw_lighting(rng, split, &d);
  return d;
}

// A tray is labelled when it lies wholly inside the frame (its top's corners in the image).
inline bool tray_in_frame(const sim::AgvTruth& t, int w, int h) {
  if (!t.projected) return false;
  for (const Vec2& c : t.tray_corners_px) {
    if (!(c.x >= 1.0 && c.y >= 1.0 && c.x <= w - 2.0 && c.y <= h - 2.0)) return false;
  }
  return true;
}

}  // namespace agv::tray_obb
