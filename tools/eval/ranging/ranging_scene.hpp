// The rendered scene of the ranging evaluation and benchmark (eval_ranging_frames,
// tests/bench/bench_ranging_observe.cpp): a forward camera 1280x800 with lens distortion, an open
// area lined with racks carrying tag36h11 landmarks of 150 mm, per-frame degradations, vehicle
// poses. Header-only; not part of algo.
#pragma once

#include <cstdint>
#include <random>
#include <vector>

#include "agv/ranging/observe.hpp"
#include "agv/sim/site_render.hpp"

namespace agv::ranging_eval {

inline CameraIntrinsics true_camera() {
  return {.width_px = 1280,
          .height_px = 800,
          .fx = 1000.0,
          .fy = 1001.5,
          .cx = 642.0,
          .cy = 397.0,
          .k1 = -0.09,
          .k2 = 0.02,
          .p1 = 0.0006,
          .p2 = -0.0004};
}

// An open area 10 x 8 m lined with racks 1 m deep, landmarks every 1.5 m on their inner faces,
// one pillar in the middle with a landmark on each side.
inline sim::SiteScene warehouse(std::uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> height(800.0, 1600.0);
  sim::SiteScene s;
  s.site.outline.vertices_mm = {{0, 0}, {12000, 0}, {12000, 10000}, {0, 10000}};
  auto rack = [&](const char* id, double x0, double y0, double x1, double y1) {
    site::Obstacle o;
    o.id = id;
    o.outline.vertices_mm = {{x0, y0}, {x1, y0}, {x1, y1}, {x0, y1}};
    o.height_mm = 2500.0;
    s.site.obstacles.push_back(o);
  };
  rack("south", 0, 0, 12000, 1000);
  rack("north", 0, 9000, 12000, 10000);
  rack("west", 0, 1000, 1000, 9000);
  rack("east", 11000, 1000, 12000, 9000);
  rack("pillar", 5800, 4800, 6200, 5200);
  std::uint32_t id = 0;
  auto tag = [&](double x, double y, double facing) {
    s.site.wall_landmarks.push_back(
        {id++, site::LandmarkFamily::kTag36h11, x, y, height(rng), facing, 150.0});
  };
  for (double x = 1750; x < 10500; x += 1500) {
    tag(x, 1000, kPi / 2);
    tag(x, 9000, -kPi / 2);
  }
  for (double y = 1750; y < 8500; y += 1500) {
    tag(1000, y, 0.0);
    tag(11000, y, kPi);
  }
  tag(6200, 5000, 0.0);
  tag(5800, 5000, kPi);
  tag(6000, 5200, kPi / 2);
  tag(6000, 4800, -kPi / 2);
  s.floor.amplitude = 10.0;
  return s;
}

inline sim::SiteRenderParams degraded(std::mt19937_64& rng) {
  std::uniform_real_distribution<double> u(0.0, 1.0);
  sim::SiteRenderParams p;
  p.defocus_sigma_px = 0.3 + 0.7 * u(rng);
  p.read_noise_sigma = 1.5 + 2.5 * u(rng);
  p.shot_noise_gain = 0.3;
  p.illumination_ratio = 0.55 + 0.45 * u(rng);
  p.illumination_direction_deg = 360.0 * u(rng);
  p.vignetting = 0.25;
  p.exposure_gain = 0.7 + 0.5 * u(rng);
  return p;
}

// Vehicle poses for the trials. random_free_poses keeps its poses apart from each other: draw them
// in small batches.
inline std::vector<Pose2> trial_poses(const sim::SiteScene& scene, int trials, std::uint64_t seed) {
  std::vector<Pose2> poses;
  for (std::uint64_t batch = 0; static_cast<int>(poses.size()) < trials && batch < 10000; ++batch) {
    for (const Pose2& p : sim::random_free_poses(scene.site, 8, 500.0, seed * 1000003 + batch)) {
      if (static_cast<int>(poses.size()) < trials) poses.push_back(p);
    }
  }
  return poses;
}

// Which lens calibration errors believed_observer draws (all by default).
struct CalibrationErrors {
  double scale = 1.0;  // times each 1-sigma figure below
  bool focal = true, principal_point = true, distortion = true;
  // Instead of drawn errors, this lens (a calibration's result); the draws are still made.
  const CameraIntrinsics* calibrated = nullptr;
};

// What the vehicle believes: a calibration with small errors (fx, fy 0.2 %, cx, cy 1 px, k1
// 0.003, 1 sigma; as cal says) and a mount off by up to +-mount_deg / +-mount_mm per axis
// (uniform); the believed mount in *m_est when given. The draws are the same whatever cal says.
inline ranging::LandmarkObserver believed_observer(
    std::mt19937_64& rng, const CameraIntrinsics& k_true, const ranging::RangingMount& mount_true,
    double mount_deg, double mount_mm, const sim::SiteScene& scene,
    const ranging::ObserveOptions& oopt, ranging::RangingMount* m_est = nullptr,
    const CalibrationErrors& cal = {}) {
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  std::normal_distribution<double> n(0.0, 1.0);
  CameraIntrinsics k_est = k_true;
  const double f = cal.focal ? cal.scale : 0.0, c = cal.principal_point ? cal.scale : 0.0;
  const double k = cal.distortion ? cal.scale : 0.0;
  k_est.fx *= 1.0 + f * 0.002 * n(rng);
  k_est.fy *= 1.0 + f * 0.002 * n(rng);
  k_est.cx += c * 1.0 * n(rng);
  k_est.cy += c * 1.0 * n(rng);
  k_est.k1 += k * 0.003 * n(rng);
  if (cal.calibrated) k_est = *cal.calibrated;
  ranging::RangingMount m = mount_true;
  m.x_mm += mount_mm * u(rng);
  m.y_mm += mount_mm * u(rng);
  m.z_mm += mount_mm * u(rng);
  m.roll_rad += deg_to_rad(mount_deg) * u(rng);
  m.pitch_rad += deg_to_rad(mount_deg) * u(rng);
  m.yaw_rad += deg_to_rad(mount_deg) * u(rng);
  if (m_est) *m_est = m;
  return ranging::LandmarkObserver(k_est, m, scene.site.wall_landmarks, oopt);
}

}  // namespace agv::ranging_eval
