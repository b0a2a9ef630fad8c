// Site renderer: cameras, projection, random scene contents and the scene as planar faces
// (docs/design/site_render.md).
#include <algorithm>
#include <cmath>
#include <limits>
#include <random>

#include "site_render_internal.hpp"

namespace agv::sim {

using site_render_detail::cross3;
using site_render_detail::rot3t;
using site_render_detail::sub3;

RenderCamera RenderCamera::from_ceiling(const site::CeilingCamera& c) {
  RenderCamera r;
  r.intrinsics = c.intrinsics;
  r.r_site_cam = c.r_site_cam;
  r.t_site_cam_mm = c.t_site_cam_mm;
  return r;
}

RenderCamera RenderCamera::on_vehicle(const CameraIntrinsics& intrinsics, const Pose2& vehicle_site,
                                      const VehicleCameraMount& m) {
  // Optical axis, image right (horizontal whatever the pitch) and image down, vehicle frame.
  const double cp = std::cos(m.pitch_rad), sp = std::sin(m.pitch_rad);
  const double cy = std::cos(m.yaw_rad), sy = std::sin(m.yaw_rad);
  const Vec3 f{cp * cy, cp * sy, -sp};
  const Vec3 right0{sy, -cy, 0.0};
  const Vec3 down0 = cross3(f, right0);
  const double cr = std::cos(m.roll_rad), sr = std::sin(m.roll_rad);
  const Vec3 x{cr * right0.x + sr * down0.x, cr * right0.y + sr * down0.y,
               cr * right0.z + sr * down0.z};
  const Vec3 y = cross3(f, x);
  const double c = std::cos(vehicle_site.theta_rad), s = std::sin(vehicle_site.theta_rad);
  RenderCamera r;
  r.intrinsics = intrinsics;
  const Vec3 cols[3] = {x, y, f};
  for (int k = 0; k < 3; ++k) {
    r.r_site_cam[static_cast<size_t>(k)] = c * cols[k].x - s * cols[k].y;
    r.r_site_cam[static_cast<size_t>(3 + k)] = s * cols[k].x + c * cols[k].y;
    r.r_site_cam[static_cast<size_t>(6 + k)] = cols[k].z;
  }
  r.t_site_cam_mm = {vehicle_site.x_mm + c * m.x_mm - s * m.y_mm,
                     vehicle_site.y_mm + s * m.x_mm + c * m.y_mm, m.z_mm};
  return r;
}

std::vector<Vec2> project_points(const RenderCamera& cam, const std::vector<Vec3>& pts,
                                 std::vector<std::uint8_t>* ok) {
  CameraModel model;
  model.intrinsics = cam.intrinsics;
  const Vec3 t{cam.t_site_cam_mm[0], cam.t_site_cam_mm[1], cam.t_site_cam_mm[2]};
  std::vector<Vec2> out(pts.size());
  if (ok) ok->assign(pts.size(), 0);
  const double nan = std::numeric_limits<double>::quiet_NaN();
  for (size_t i = 0; i < pts.size(); ++i) {
    const Vec3 pc = rot3t(cam.r_site_cam, sub3(pts[i], t));
    if (!(pc.z > 1.0) || !std::isfinite(pc.x) || !std::isfinite(pc.y) || !std::isfinite(pc.z)) {
      out[i] = {nan, nan};
      continue;
    }
    out[i] = model.distort_normalized_to_pixel({pc.x / pc.z, pc.y / pc.z});
    if (ok) (*ok)[i] = 1;
  }
  return out;
}

SiteRenderParams realistic_site_params() {
  return {.exposure_s = 0.004,
          .illumination_ratio = 0.85,
          .illumination_direction_deg = 20.0,
          .vignetting = 0.25,
          .defocus_sigma_px = 0.6,
          .read_noise_sigma = 2.0,
          .shot_noise_gain = 0.05};
}

namespace {

bool site_point_in_polygon(const std::vector<Vec2>& poly, Vec2 p) {
  bool in = false;
  const size_t n = poly.size();
  for (size_t i = 0, j = n - 1; i < n; j = i++) {
    const Vec2 a = poly[i], b = poly[j];
    if ((a.y > p.y) != (b.y > p.y) && p.x < (b.x - a.x) * (p.y - a.y) / (b.y - a.y) + a.x) {
      in = !in;
    }
  }
  return in;
}

double site_dist_to_polygon(const std::vector<Vec2>& poly, Vec2 p) {
  double best = std::numeric_limits<double>::infinity();
  const size_t n = poly.size();
  for (size_t i = 0; i < n; ++i) {
    const Vec2 a = poly[i], b = poly[(i + 1) % n];
    const double dx = b.x - a.x, dy = b.y - a.y, l2 = dx * dx + dy * dy;
    const double t = l2 > 0 ? std::clamp(((p.x - a.x) * dx + (p.y - a.y) * dy) / l2, 0.0, 1.0) : 0;
    best = std::min(best, std::hypot(p.x - a.x - t * dx, p.y - a.y - t * dy));
  }
  return best;
}

// Inside the drivable outline, r clear of its walls and of every obstacle, and clear of `taken`
// (centre, radius) by r plus their radius.
bool site_spot_free(const site::Site& s, Vec2 p, double r, const std::vector<Vec3>& taken) {
  const auto& outline = s.outline.vertices_mm;
  if (outline.size() >= 3 &&
      (!site_point_in_polygon(outline, p) || site_dist_to_polygon(outline, p) < r)) {
    return false;
  }
  for (const site::Obstacle& o : s.obstacles) {
    const auto& v = o.outline.vertices_mm;
    if (v.size() >= 3 && (site_point_in_polygon(v, p) || site_dist_to_polygon(v, p) < r)) {
      return false;
    }
  }
  for (const Vec3& q : taken) {
    if (std::hypot(p.x - q.x, p.y - q.y) < r + q.z) return false;
  }
  return true;
}

// Bounding box of the outline (or of the obstacles when it has none).
void site_extent(const site::Site& s, Vec2* lo, Vec2* hi) {
  *lo = {1e300, 1e300};
  *hi = {-1e300, -1e300};
  auto grow = [&](const std::vector<Vec2>& v) {
    for (const Vec2& p : v) {
      *lo = {std::min(lo->x, p.x), std::min(lo->y, p.y)};
      *hi = {std::max(hi->x, p.x), std::max(hi->y, p.y)};
    }
  };
  grow(s.outline.vertices_mm);
  if (s.outline.vertices_mm.size() < 3) {
    for (const auto& o : s.obstacles) grow(o.outline.vertices_mm);
  }
  if (lo->x > hi->x) {
    *lo = {-5000, -5000};
    *hi = {5000, 5000};
  }
}

}  // namespace

std::vector<Pose2> random_free_poses(const site::Site& site, int n, double radius_mm,
                                     std::uint64_t seed) {
  std::mt19937_64 rng(seed ^ 0x9f1e'e7a9'0c5eULL);
  Vec2 lo, hi;
  site_extent(site, &lo, &hi);
  std::uniform_real_distribution<double> ux(lo.x, hi.x), uy(lo.y, hi.y), ua(-kPi, kPi);
  const double r = std::max(0.0, radius_mm) + site.clearance_mm;
  std::vector<Vec3> taken;
  std::vector<Pose2> out;
  for (int tries = 0; static_cast<int>(out.size()) < n && tries < 400 * std::max(1, n); ++tries) {
    const Vec2 p{ux(rng), uy(rng)};
    const double a = ua(rng);
    if (!site_spot_free(site, p, r, taken)) continue;
    taken.push_back({p.x, p.y, r});
    out.push_back({p.x, p.y, a});
  }
  return out;
}

void add_random_parcels(SiteScene* scene, double loaded_fraction, std::uint64_t seed) {
  scene->parcels.clear();
  std::mt19937_64 rng(seed ^ 0x7a3c'11d5'2b90ULL);
  std::uniform_real_distribution<double> u01(0.0, 1.0);
  for (size_t i = 0; i < scene->site.fleet.size(); ++i) {
    const site::FleetAgv& a = scene->site.fleet[i];
    if (!(u01(rng) < loaded_fraction)) continue;
    const int count = u01(rng) < 0.7 ? 1 : 2;
    for (int k = 0; k < count; ++k) {
      Parcel p;
      p.agv = i;
      p.length_mm = 150.0 + 350.0 * u01(rng);
      p.width_mm = 150.0 + 350.0 * u01(rng);
      p.height_mm = 80.0 + 320.0 * u01(rng);
      p.x_mm = (u01(rng) - 0.5) * std::max(0.0, a.tray_length_mm - 100.0);
      p.y_mm = (u01(rng) - 0.5) * std::max(0.0, a.tray_width_mm - 100.0);
      p.yaw_rad = (u01(rng) - 0.5) * 0.6;
      p.grey = 60.0 + 140.0 * u01(rng);
      scene->parcels.push_back(p);
    }
  }
}

void add_random_clutter(SiteScene* scene, int people, int pallets, std::uint64_t seed) {
  scene->clutter.clear();
  std::mt19937_64 rng(seed ^ 0x3e5d'77c1'a04fULL);
  Vec2 lo, hi;
  site_extent(scene->site, &lo, &hi);
  std::uniform_real_distribution<double> ux(lo.x, hi.x), uy(lo.y, hi.y), ua(-kPi, kPi);
  std::uniform_real_distribution<double> u01(0.0, 1.0);
  std::vector<Vec3> taken;
  for (size_t i = 0; i < scene->agvs.size() && i < scene->site.fleet.size(); ++i) {
    taken.push_back(
        {scene->agvs[i].pose.x_mm, scene->agvs[i].pose.y_mm, scene->site.fleet[i].radius_mm});
  }
  for (int k = 0; k < people + pallets; ++k) {
    Clutter c;
    c.kind = k < people ? ClutterKind::kPerson : ClutterKind::kPallet;
    if (c.kind == ClutterKind::kPerson) {
      c.length_mm = 450.0 + 100.0 * u01(rng);
      c.width_mm = 400.0 + 100.0 * u01(rng);
      c.height_mm = 1650.0 + 250.0 * u01(rng);
      c.grey = 50.0 + 120.0 * u01(rng);
    } else {
      c.length_mm = 1200.0;
      c.width_mm = 800.0;
      c.height_mm = 150.0;
      c.grey = 140.0 + 40.0 * u01(rng);
    }
    const double r = 0.5 * std::hypot(c.length_mm, c.width_mm) + 300.0;
    for (int tries = 0; tries < 400; ++tries) {
      const Vec2 p{ux(rng), uy(rng)};
      const double a = ua(rng);
      if (!site_spot_free(scene->site, p, r, taken)) continue;
      c.x_mm = p.x;
      c.y_mm = p.y;
      c.yaw_rad = a;
      taken.push_back({p.x, p.y, r});
      scene->clutter.push_back(c);
      break;
    }
  }
}

}  // namespace agv::sim
