// Ceiling-camera geometry and polygon measures of the site model (site_geometry.hpp).
#include "agv/site/site_geometry.hpp"

#include <algorithm>
#include <cmath>
#include <utility>

#include "agv/common/camera_model.hpp"

namespace agv::site {

namespace detail {
namespace {
using Mat3 = std::array<double, 9>;

Mat3 mat_mul(const Mat3& a, const Mat3& b) {
  Mat3 c{};
  for (int i = 0; i < 3; ++i) {
    for (int j = 0; j < 3; ++j) {
      c[i * 3 + j] = a[i * 3] * b[j] + a[i * 3 + 1] * b[3 + j] + a[i * 3 + 2] * b[6 + j];
    }
  }
  return c;
}
}  // namespace
}  // namespace detail

std::array<double, 9> camera_rotation_from_angles(double yaw_rad, double pitch_rad,
                                                  double roll_rad) {
  const double cy = std::cos(yaw_rad), sy = std::sin(yaw_rad);
  const double cp = std::cos(pitch_rad), sp = std::sin(pitch_rad);
  const double cr = std::cos(roll_rad), sr = std::sin(roll_rad);
  const detail::Mat3 rz{cy, -sy, 0, sy, cy, 0, 0, 0, 1};
  const detail::Mat3 down{1, 0, 0, 0, -1, 0, 0, 0, -1};
  const detail::Mat3 rx{1, 0, 0, 0, cp, -sp, 0, sp, cp};
  const detail::Mat3 ry{cr, 0, sr, 0, 1, 0, -sr, 0, cr};
  return detail::mat_mul(detail::mat_mul(rz, down), detail::mat_mul(rx, ry));
}

void camera_angles_from_rotation(const std::array<double, 9>& r, double* yaw_rad, double* pitch_rad,
                                 double* roll_rad) {
  // M = R_down * Rz(-yaw) * R... : undo the fixed part first. Rz(yaw) * R_down = R_down *
  // Rz(-yaw) (R_down flips y and z), so R_down * R = Rz(-yaw) * Rx(pitch) * Ry(roll) =: M.
  const detail::Mat3 down{1, 0, 0, 0, -1, 0, 0, 0, -1};
  const detail::Mat3 m = detail::mat_mul(down, r);
  // Rz(a) Rx(p) Ry(q) with a = -yaw:
  //   row 2 = [-cp sq, sp, cp cq];  column 1 = [-sa cp, ca cp, sp]
  const double sp = std::clamp(m[7], -1.0, 1.0);
  *pitch_rad = std::asin(sp);
  if (std::abs(sp) < 1.0 - 1e-12) {
    *roll_rad = std::atan2(-m[6], m[8]);
    *yaw_rad = -std::atan2(-m[1], m[4]);
  } else {
    // Gimbal lock: only yaw - roll (or yaw + roll) is determined; roll := 0. With q = 0,
    // column 0 = [ca, sa, 0].
    *roll_rad = 0.0;
    *yaw_rad = -std::atan2(m[3], m[0]);
  }
}

std::array<double, 3> camera_optical_axis(const CeilingCamera& cam) {
  const auto& r = cam.r_site_cam;
  return {r[2], r[5], r[8]};
}

double camera_tilt_rad(const CeilingCamera& cam) {
  const auto a = camera_optical_axis(cam);
  const double n = std::sqrt(a[0] * a[0] + a[1] * a[1] + a[2] * a[2]);
  if (!(n > 0.0)) return M_PI;
  return std::acos(std::clamp(-a[2] / n, -1.0, 1.0));
}

namespace detail {
namespace {
// The ray direction in the site frame of a pixel; false when it does not undistort.
bool pixel_ray(const CeilingCamera& cam, Vec2 pixel, std::array<double, 3>* d) {
  CameraModel model;
  model.intrinsics = cam.intrinsics;
  Vec2 xn;
  if (!model.undistort_pixel_to_normalized(pixel, &xn)) return false;
  const auto& r = cam.r_site_cam;
  for (int i = 0; i < 3; ++i) (*d)[i] = r[i * 3] * xn.x + r[i * 3 + 1] * xn.y + r[i * 3 + 2];
  return std::isfinite((*d)[0]) && std::isfinite((*d)[1]) && std::isfinite((*d)[2]);
}
}  // namespace
}  // namespace detail

bool camera_pixel_to_plane(const CeilingCamera& cam, Vec2 pixel, double z_mm, Vec2* at_mm) {
  std::array<double, 3> d{};
  if (!detail::pixel_ray(cam, pixel, &d)) return false;
  const double n = std::sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]);
  const double dz = z_mm - cam.t_site_cam_mm[2];
  // A ray within ~0.06 deg of the horizon meets the plane kilometres away: not a view of it.
  if (!(dz < 0.0) || !(d[2] < -1e-3 * n)) return false;
  const double t = dz / d[2];
  *at_mm = {cam.t_site_cam_mm[0] + t * d[0], cam.t_site_cam_mm[1] + t * d[1]};
  return std::isfinite(at_mm->x) && std::isfinite(at_mm->y);
}

bool camera_pixel_to_floor(const CeilingCamera& cam, Vec2 pixel, Vec2* floor_mm) {
  return camera_pixel_to_plane(cam, pixel, 0.0, floor_mm);
}

std::vector<Vec2> camera_floor_footprint(const CeilingCamera& cam, int samples_per_edge,
                                         double max_range_mm) {
  const int n = std::max(1, samples_per_edge);
  const double w = cam.intrinsics.width_px - 1.0, h = cam.intrinsics.height_px - 1.0;
  // Counter-clockwise in the image as seen on the page (y down): top-left, bottom-left, ...
  const Vec2 corners[4] = {{0, 0}, {0, h}, {w, h}, {w, 0}};
  const Vec2 cam_xy{cam.t_site_cam_mm[0], cam.t_site_cam_mm[1]};
  std::vector<Vec2> out;
  for (int e = 0; e < 4; ++e) {
    const Vec2 a = corners[e], b = corners[(e + 1) % 4];
    for (int i = 0; i < n; ++i) {
      const double s = static_cast<double>(i) / n;
      const Vec2 px{a.x + s * (b.x - a.x), a.y + s * (b.y - a.y)};
      Vec2 f;
      if (camera_pixel_to_floor(cam, px, &f) &&
          std::hypot(f.x - cam_xy.x, f.y - cam_xy.y) <= max_range_mm) {
        out.push_back(f);
        continue;
      }
      std::array<double, 3> d{};
      if (!detail::pixel_ray(cam, px, &d)) continue;
      const double hn = std::hypot(d[0], d[1]);
      if (!(hn > 0.0)) continue;
      out.push_back({cam_xy.x + max_range_mm * d[0] / hn, cam_xy.y + max_range_mm * d[1] / hn});
    }
  }
  return out;
}

double signed_area_mm2(const Polygon& p) {
  const auto& v = p.vertices_mm;
  double a = 0.0;
  for (std::size_t i = 0; i < v.size(); ++i) {
    const Vec2& p0 = v[i];
    const Vec2& p1 = v[(i + 1) % v.size()];
    a += p0.x * p1.y - p1.x * p0.y;
  }
  return 0.5 * a;
}

namespace detail {
// The parameter along p + t d (t in [0, t_max]) where it crosses the edge a-b, or -1.
double edge_crossing(Vec2 p, Vec2 d, double t_max, Vec2 a, Vec2 b) {
  const Vec2 e{b.x - a.x, b.y - a.y};
  const double den = d.x * e.y - d.y * e.x;
  if (std::abs(den) < 1e-12) return -1.0;  // parallel: grazing an edge hides nothing
  const Vec2 ap{a.x - p.x, a.y - p.y};
  const double t = (ap.x * e.y - ap.y * e.x) / den;
  const double u = (ap.x * d.y - ap.y * d.x) / den;
  return t >= 0.0 && t <= t_max && u >= 0.0 && u <= 1.0 ? t : -1.0;
}
}  // namespace detail

bool sight_line_blocked(const std::array<double, 3>& from_mm, const std::array<double, 3>& to_mm,
                        std::span<const Obstacle> obstacles, double end_clearance_mm) {
  const Vec2 p{from_mm[0], from_mm[1]};
  const Vec2 d{to_mm[0] - from_mm[0], to_mm[1] - from_mm[1]};
  const double length_mm = std::hypot(d.x, d.y);
  if (!(length_mm > end_clearance_mm)) return false;
  const double t_max = 1.0 - end_clearance_mm / length_mm;
  for (const Obstacle& o : obstacles) {
    const std::vector<Vec2>& v = o.outline.vertices_mm;
    for (std::size_t i = 0; i < v.size(); ++i) {
      const double t = detail::edge_crossing(p, d, t_max, v[i], v[(i + 1) % v.size()]);
      if (t < 0.0) continue;
      if (from_mm[2] + t * (to_mm[2] - from_mm[2]) < o.height_mm) return true;
    }
  }
  return false;
}

double pose_correlation_at(const CeilingCamera& cam, int p, int q) {
  if (p == q) return 1.0;
  if (p > q) std::swap(p, q);
  if (p < 0 || q > 5) return 0.0;
  return cam.pose_correlation[static_cast<std::size_t>(p * 6 - p * (p + 1) / 2 + (q - p - 1))];
}

}  // namespace agv::site
