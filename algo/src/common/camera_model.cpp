#include "agv/common/camera_model.hpp"

#include <algorithm>
#include <cmath>

namespace agv {

Vec2 CameraModel::distort_normalized_to_pixel(Vec2 xn) const {
  const auto& k = intrinsics;
  const double r2 = xn.x * xn.x + xn.y * xn.y;
  const double radial = 1.0 + r2 * (k.k1 + r2 * (k.k2 + r2 * k.k3));
  const double xd = xn.x * radial + 2.0 * k.p1 * xn.x * xn.y + k.p2 * (r2 + 2.0 * xn.x * xn.x);
  const double yd = xn.y * radial + k.p1 * (r2 + 2.0 * xn.y * xn.y) + 2.0 * k.p2 * xn.x * xn.y;
  return {k.fx * xd + k.cx, k.fy * yd + k.cy};
}

bool CameraModel::undistort_pixel_to_normalized(Vec2 pixel, Vec2* xn) const {
  const auto& k = intrinsics;
  if (!(k.fx > 0.0) || !(k.fy > 0.0) || !std::isfinite(pixel.x) || !std::isfinite(pixel.y)) {
    return false;
  }
  const double xd = (pixel.x - k.cx) / k.fx;
  const double yd = (pixel.y - k.cy) / k.fy;
  // Newton iterations on the forward model: converges in a few steps for realistic lenses,
  // unlike the fixed-point scheme, and lets us detect divergence.
  double x = xd, y = yd;
  for (int it = 0; it < 20; ++it) {
    const double r2 = x * x + y * y;
    const double radial = 1.0 + r2 * (k.k1 + r2 * (k.k2 + r2 * k.k3));
    const double dradial_dr2 = k.k1 + r2 * (2.0 * k.k2 + 3.0 * r2 * k.k3);
    const double fx_ = x * radial + 2.0 * k.p1 * x * y + k.p2 * (r2 + 2.0 * x * x) - xd;
    const double fy_ = y * radial + k.p1 * (r2 + 2.0 * y * y) + 2.0 * k.p2 * x * y - yd;
    const double j11 = radial + 2.0 * x * x * dradial_dr2 + 2.0 * k.p1 * y + 6.0 * k.p2 * x;
    const double j12 = 2.0 * x * y * dradial_dr2 + 2.0 * k.p1 * x + 2.0 * k.p2 * y;
    const double j21 = 2.0 * x * y * dradial_dr2 + 2.0 * k.p1 * x + 2.0 * k.p2 * y;
    const double j22 = radial + 2.0 * y * y * dradial_dr2 + 6.0 * k.p1 * y + 2.0 * k.p2 * x;
    const double det = j11 * j22 - j12 * j21;
    if (!(std::abs(det) > 1e-12)) return false;
    const double dx = (j22 * fx_ - j12 * fy_) / det;
    const double dy = (-j21 * fx_ + j11 * fy_) / det;
    x -= dx;
    y -= dy;
    if (std::abs(dx) < 1e-14 && std::abs(dy) < 1e-14) break;
  }
  const Vec2 back = distort_normalized_to_pixel({x, y});
  if (!(std::abs(back.x - pixel.x) < 1e-6 && std::abs(back.y - pixel.y) < 1e-6)) return false;
  *xn = {x, y};
  return true;
}

void CameraMount::rotation_vehicle_from_camera(double r[9]) const {
  const double cy = std::cos(yaw_rad), sy = std::sin(yaw_rad);
  const double cp = std::cos(pitch_rad), sp = std::sin(pitch_rad);
  const double cr = std::cos(roll_rad), sr = std::sin(roll_rad);
  // R_VB = Rz(yaw) Ry(pitch) Rx(roll).
  const double b[9] = {cy * cp,
                       cy * sp * sr - sy * cr,
                       cy * sp * cr + sy * sr,  //
                       sy * cp,
                       sy * sp * sr + cy * cr,
                       sy * sp * cr - cy * sr,  //
                       -sp,
                       cp * sr,
                       cp * cr};
  // R_BC: x_C = -y_B, y_C = -x_B, z_C = -z_B, so R_VC = R_VB R_BC = [-b1, -b0, -b2] (columns).
  for (int i = 0; i < 3; ++i) {
    r[3 * i + 0] = -b[3 * i + 1];
    r[3 * i + 1] = -b[3 * i + 0];
    r[3 * i + 2] = -b[3 * i + 2];
  }
}

LensTerms lens_terms(const CameraIntrinsics& k) {
  const bool radial = k.k1 != 0.0 || k.k2 != 0.0 || k.k3 != 0.0;
  const bool tangential = k.p1 != 0.0 || k.p2 != 0.0;
  const bool finite = std::isfinite(k.k1) && std::isfinite(k.k2) && std::isfinite(k.k3) &&
                      std::isfinite(k.p1) && std::isfinite(k.p2);
  return !finite || tangential ? LensTerms::kFull : radial ? LensTerms::kRadial : LensTerms::kNone;
}

FloorProjector::FloorProjector(const CameraModel& model)
    : m_(model), tilted_(model.mount.tilted()) {
  lens_ = lens_terms(m_.intrinsics);
  if (tilted_) {
    m_.mount.rotation_vehicle_from_camera(r_);
  } else {
    cos_yaw_ = std::cos(m_.mount.yaw_rad);
    sin_yaw_ = std::sin(m_.mount.yaw_rad);
  }
}

bool FloorProjector::vehicle_to_pixel(Vec2 p, Vec2* pixel) const {
  const CameraMount& mount = m_.mount;
  if (!std::isfinite(p.x) || !std::isfinite(p.y) || !(mount.height_mm > 0.0)) return false;
  const double dx = p.x - mount.offset_x_mm, dy = p.y - mount.offset_y_mm;
  if (tilted_) {
    // Camera coordinates of the floor point: R_VC^T (p - c), c = (offset_x, offset_y, height).
    const double* r = r_;
    const double dz = -mount.height_mm;
    const double xc = r[0] * dx + r[3] * dy + r[6] * dz;
    const double yc = r[1] * dx + r[4] * dy + r[7] * dz;
    const double zc = r[2] * dx + r[5] * dy + r[8] * dz;
    if (!(zc > 1e-9 * mount.height_mm)) return false;  // behind the camera
    *pixel = m_.distort_normalized_to_pixel({xc / zc, yc / zc});
    return true;
  }
  const double c = cos_yaw_, s = sin_yaw_;
  // image right = (sin, -cos), image up = (cos, sin) in the vehicle frame.
  const double xc = dx * s - dy * c;
  const double yc = -(dx * c + dy * s);
  *pixel = m_.distort_normalized_to_pixel({xc / mount.height_mm, yc / mount.height_mm});
  return true;
}

PlaneProjector FloorProjector::plane(Vec2 o, Vec2 eu, Vec2 ev) const {
  PlaneProjector p;
  const CameraMount& mount = m_.mount;
  p.k_ = m_.intrinsics;
  p.lens_ = lens_;
  if (!(mount.height_mm > 0.0)) return p;
  // Camera point = C * (floor point - camera position), C the 3x3 floor -> camera rotation
  // (rows), then floor point - camera position = (o - offset) + u * eu + v * ev, z = -height.
  double c[9];
  if (tilted_) {
    // Rows of R_VC^T are the columns of R_VC.
    for (int i = 0; i < 3; ++i) {
      c[3 * i + 0] = r_[i];
      c[3 * i + 1] = r_[3 + i];
      c[3 * i + 2] = r_[6 + i];
    }
    p.z_min_ = 1e-9 * mount.height_mm;
  } else {
    // As vehicle_to_pixel's untilted branch: xc = dx s - dy c, yc = -(dx c + dy s), and the
    // normalised coordinates are those over the height (a camera point at depth height).
    const double co = cos_yaw_, si = sin_yaw_;
    const double rows[9] = {si, -co, 0.0, -co, -si, 0.0, 0.0, 0.0, -1.0};
    for (int i = 0; i < 9; ++i) c[i] = rows[i];
    p.z_min_ = 0.0;
  }
  const double d[3] = {o.x - mount.offset_x_mm, o.y - mount.offset_y_mm, -mount.height_mm};
  for (int i = 0; i < 3; ++i) {
    const double* ci = c + 3 * i;
    p.a_[3 * i + 0] = ci[0] * eu.x + ci[1] * eu.y;
    p.a_[3 * i + 1] = ci[0] * ev.x + ci[1] * ev.y;
    p.a_[3 * i + 2] = ci[0] * d[0] + ci[1] * d[1] + ci[2] * d[2];
  }
  return p;
}

bool FloorProjector::undistort_with_lens(Vec2 pixel, Vec2* xn) const {
  if (lens_ == LensTerms::kFull) return m_.undistort_pixel_to_normalized(pixel, xn);
  const auto& k = m_.intrinsics;
  if (!(k.fx > 0.0) || !(k.fy > 0.0) || !std::isfinite(pixel.x) || !std::isfinite(pixel.y)) {
    return false;
  }
  const double xd = (pixel.x - k.cx) / k.fx;
  const double yd = (pixel.y - k.cy) / k.fy;
  return undistort_radial(pixel, xd, yd, xn);
}

bool FloorProjector::undistort_radial(Vec2 pixel, double xd, double yd, Vec2* xn) const {
  const auto& k = m_.intrinsics;
  // (x, y) = s (xd, yd) with s radial(s^2 rd2) = 1. The 2-D Jacobian has eigenvalues radial
  // (across the ray) and g = radial + 2 r2 radial' (along it): its determinant is their product.
  const double rd2 = xd * xd + yd * yd;
  const double step_scale = std::max(std::abs(xd), std::abs(yd));
  // Start from the inverted series r_u = r_d (1 - k1 r_d^2 + (3 k1^2 - k2) r_d^4 + ...): on a
  // lens inside its fold that is one or two of the iteration's steps from the root. Where the
  // series is far from 1 (far outside the image, a strong lens) it is no better than s = 1.
  const double series = 1.0 + rd2 * (-k.k1 + rd2 * (3.0 * k.k1 * k.k1 - k.k2));
  double s = std::abs(series - 1.0) < 0.1 ? series : 1.0;
  for (int it = 0; it < 20; ++it) {
    const double r2 = s * s * rd2;
    const double radial = 1.0 + r2 * (k.k1 + r2 * (k.k2 + r2 * k.k3));
    const double dradial_dr2 = k.k1 + r2 * (2.0 * k.k2 + 3.0 * r2 * k.k3);
    const double g = radial + 2.0 * r2 * dradial_dr2;
    if (!(std::abs(radial * g) > 1e-12)) return false;
    const double ds = (s * radial - 1.0) / g;
    s -= ds;
    // Quadratic convergence: after a step of 1e-9 the error left is of order 1e-18 (the 2-D
    // iteration takes one more step, to 1e-14, which changes nothing the tests can see).
    if (std::abs(ds) * step_scale < 1e-9) break;
  }
  const double x = s * xd, y = s * yd;
  const Vec2 back = m_.distort_normalized_to_pixel({x, y});
  if (!(std::abs(back.x - pixel.x) < 1e-6 && std::abs(back.y - pixel.y) < 1e-6)) return false;
  *xn = {x, y};
  return true;
}

bool CameraModel::vehicle_to_pixel(Vec2 p, Vec2* pixel) const {
  return FloorProjector(*this).vehicle_to_pixel(p, pixel);
}

bool CameraModel::pixel_to_vehicle(Vec2 pixel, Vec2* p) const {
  return FloorProjector(*this).pixel_to_vehicle(pixel, p);
}

double CameraModel::mm_per_px() const {
  return mount.height_mm * 0.5 * (1.0 / intrinsics.fx + 1.0 / intrinsics.fy);
}

CameraModel CameraModel::default_640x480() {
  CameraModel m;
  m.intrinsics.width_px = 640;
  m.intrinsics.height_px = 480;
  m.mount.height_mm = 200.0;
  m.intrinsics.fx = m.intrinsics.fy = 200.0 / 0.26;  // 0.26 mm/px at the floor
  m.intrinsics.cx = 319.5;
  m.intrinsics.cy = 239.5;
  return m;
}

CameraModel CameraModel::default_1280x800() {
  CameraModel m = default_640x480();
  m.intrinsics.width_px = 1280;
  m.intrinsics.height_px = 800;
  m.intrinsics.fx = m.intrinsics.fy = 200.0 / 0.13;
  m.intrinsics.cx = 639.5;
  m.intrinsics.cy = 399.5;
  return m;
}

}  // namespace agv
