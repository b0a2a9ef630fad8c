// A small site for the tag detection tests: one ceiling camera 6 m up (1280 x 720, tilted a few
// degrees, mild distortion) over a few vehicles whose 160 mm tags are side_px wide in the image,
// rendered with the renderer's realistic effects (motion blur, defocus, vignetting, noise).
#pragma once

#include <cmath>
#include <cstdint>
#include <random>

#include "agv/sim/site_render.hpp"

namespace agv::overhead::test {

inline site::CeilingCamera ceiling_camera(double tag_side_px) {
  site::CeilingCamera c;
  c.id = "cam0";
  // 160 mm tag at 6000 - 400 mm range.
  const double f_px = tag_side_px * 5600.0 / 160.0;
  c.intrinsics = {.width_px = 1280, .height_px = 720, .fx = f_px, .fy = f_px * 1.002,
                  .cx = 641.3, .cy = 357.8, .k1 = -0.08, .k2 = 0.02, .p1 = 0.0004,
                  .p2 = -0.0003};
  // Looking down (image right = site +x, image down = site -y), turned 0.2 rad about the optical
  // axis and tilted 3 degrees about the image x axis.
  const double a = 0.2, t = 3.0 * kPi / 180.0;
  const double ca = std::cos(a), sa = std::sin(a), ct = std::cos(t), st = std::sin(t);
  // R0 = [1 0 0; 0 -1 0; 0 0 -1], Rz(a) about the optical axis, Rx(t) about image x.
  const double rz[9] = {ca, -sa, 0, sa, ca, 0, 0, 0, 1};
  const double rx[9] = {1, 0, 0, 0, ct, -st, 0, st, ct};
  const double r0[9] = {1, 0, 0, 0, -1, 0, 0, 0, -1};
  double m[9], r[9];
  for (int i = 0; i < 3; ++i) {
    for (int j = 0; j < 3; ++j) {
      m[3 * i + j] = 0;
      for (int l = 0; l < 3; ++l) m[3 * i + j] += r0[3 * i + l] * rz[3 * l + j];
    }
  }
  for (int i = 0; i < 3; ++i) {
    for (int j = 0; j < 3; ++j) {
      r[3 * i + j] = 0;
      for (int l = 0; l < 3; ++l) r[3 * i + j] += m[3 * i + l] * rx[3 * l + j];
    }
  }
  for (int i = 0; i < 9; ++i) c.r_site_cam[static_cast<std::size_t>(i)] = r[i];
  c.t_site_cam_mm = {100.0, -50.0, 6000.0};
  return c;
}

// n vehicles (tags 1, 5, 9, ...) on a grid in the camera's view, headings spread over the turn.
inline sim::SiteScene tag_scene(double tag_side_px, int n, std::uint64_t seed) {
  sim::SiteScene s;
  s.site.name = "tag_test";
  s.site.outline.vertices_mm = {{-8000, -8000}, {8000, -8000}, {8000, 8000}, {-8000, 8000}};
  s.site.cameras.push_back(ceiling_camera(tag_side_px));
  // The view's half extent on the tray plane, less a tray.
  const double half_x = 0.5 * 1280 / s.site.cameras[0].intrinsics.fx * 5600.0 - 500.0;
  const double half_y = 0.5 * 720 / s.site.cameras[0].intrinsics.fy * 5600.0 - 500.0;
  const int cols = (n + 1) / 2;
  for (int i = 0; i < n; ++i) {
    site::FleetAgv a;
    a.id = "agv" + std::to_string(i);
    a.tag_id = static_cast<std::uint32_t>(1 + 4 * i);
    s.site.fleet.push_back(a);
    const int col = i % cols, row = i / cols;
    const double fx = cols > 1 ? static_cast<double>(col) / (cols - 1) : 0.5;
    const double j =
        static_cast<double>((seed * 7919 + static_cast<std::uint64_t>(i) * 104729) % 1000) / 1000.0;
    sim::AgvState st;
    st.pose = {-half_x + 2.0 * half_x * fx + 60.0 * (j - 0.5) + 100.0,
               (row == 0 ? 0.6 : -0.6) * half_y - 50.0, 2.0 * kPi * (i + j) / n - kPi};
    st.v_mps = 0.5;
    st.omega_radps = 0.2;
    s.agvs.push_back(st);
  }
  return s;
}

// The same view on a sensor `scale` times larger in pixels (pixel centres kept:
// c' = (c + 0.5) * scale - 0.5).
inline void scale_camera(site::CeilingCamera* c, int scale) {
  CameraIntrinsics& k = c->intrinsics;
  k.width_px *= scale;
  k.height_px *= scale;
  k.fx *= scale;
  k.fy *= scale;
  k.cx = (k.cx + 0.5) * scale - 0.5;
  k.cy = (k.cy + 0.5) * scale - 0.5;
}

// tag_scene seen by `cam`, each vehicle moved a little and turned at random, with a parcel over
// its tag (visible fraction 0) that may overhang the tray a little: the covered trays of the
// tray fit's tests and benchmark.
inline sim::SiteScene covered_tag_scene(const site::CeilingCamera& cam, double tag_side_px, int n,
                                        std::uint64_t seed) {
  sim::SiteScene s = tag_scene(tag_side_px, n, seed);
  s.site.cameras[0] = cam;
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  for (std::size_t i = 0; i < s.agvs.size(); ++i) {
    s.agvs[i].pose.theta_rad = kPi * u(rng);
    s.agvs[i].pose.x_mm += 150.0 * u(rng);
    s.agvs[i].pose.y_mm += 150.0 * u(rng);
    sim::Parcel p;
    p.agv = i;
    p.x_mm = 30.0 * u(rng);
    p.y_mm = 25.0 * u(rng);
    p.yaw_rad = 0.3 * u(rng);
    p.length_mm = 300.0 + 60.0 * u(rng);
    p.width_mm = 260.0 + 40.0 * u(rng);
    p.height_mm = 190.0 + 110.0 * u(rng);
    p.grey = 130.0 + 70.0 * u(rng);
    s.parcels.push_back(p);
  }
  return s;
}

}  // namespace agv::overhead::test
