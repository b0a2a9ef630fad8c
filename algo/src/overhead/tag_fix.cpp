// Tray-plane fixes from a tag's corners (tag_fix.hpp).
#include "agv/overhead/tag_fix.hpp"

#include <cmath>

#include "agv/common/camera_model.hpp"
#include "agv/site/site_geometry.hpp"

namespace agv::overhead {

// Named, not anonymous: the library is built as one unity source.
namespace tag_fix_detail {

// Numerical Jacobian step on the corner pixels (px): small against the corner sigma, large
// against the undistortion's 1e-6 px round trip.
constexpr double kJacobianStepPx = 1e-3;
// A ray must reach the plane at least this far in front of the camera (mm).
constexpr double kMinRangeMm = 1.0;

bool valid_intrinsics(const CameraIntrinsics& k) {
  return k.fx > 0.0 && k.fy > 0.0 && std::isfinite(k.fx) && std::isfinite(k.fy) &&
         std::isfinite(k.cx) && std::isfinite(k.cy) && std::isfinite(k.k1) && std::isfinite(k.k2) &&
         std::isfinite(k.p1) && std::isfinite(k.p2) && std::isfinite(k.k3) && k.width_px > 0 &&
         k.height_px > 0;
}

CameraModel lens_of(const site::CeilingCamera& cam) {
  CameraModel m;
  m.intrinsics = cam.intrinsics;
  return m;
}

struct PlaneSquare {
  Vec2 c;
  double theta = 0.0;
  double scale = 0.0;  // fitted side / model side
  double rms = 0.0;
};

// The four corners of a tag of half side h in its own frame (x = page up, y = page left), page
// order TL, TR, BR, BL seen from above.
std::array<Vec2, 4> model_corners(double h) { return {{{h, h}, {h, -h}, {-h, -h}, {-h, h}}}; }

// Least-squares similarity (Procrustes) of the model corners q (centred on the origin) onto the
// points: the centre is the points' mean, the angle and scale closed form.
PlaneSquare fit_model(const std::array<Vec2, 4>& p, const std::array<Vec2, 4>& q) {
  PlaneSquare s;
  for (const Vec2& v : p) s.c.x += 0.25 * v.x, s.c.y += 0.25 * v.y;
  double a = 0, b = 0, qq = 0;
  for (std::size_t i = 0; i < 4; ++i) {
    const double dx = p[i].x - s.c.x, dy = p[i].y - s.c.y;
    a += q[i].x * dx + q[i].y * dy;
    b += q[i].x * dy - q[i].y * dx;
    qq += q[i].x * q[i].x + q[i].y * q[i].y;
  }
  s.theta = std::atan2(b, a);
  s.scale = std::hypot(a, b) / qq;
  const double c = std::cos(s.theta), sn = std::sin(s.theta);
  double ss = 0;
  for (std::size_t i = 0; i < 4; ++i) {
    const double mx = s.c.x + s.scale * (c * q[i].x - sn * q[i].y);
    const double my = s.c.y + s.scale * (sn * q[i].x + c * q[i].y);
    ss += (p[i].x - mx) * (p[i].x - mx) + (p[i].y - my) * (p[i].y - my);
  }
  s.rms = std::sqrt(ss / 4.0);
  return s;
}

PlaneSquare fit_square(const std::array<Vec2, 4>& p, double h) {
  return fit_model(p, model_corners(h));
}

// The tag's corners on a tray turned by Ry(pitch) Rx(roll), seen from above (dropping z): the
// square's outline the site frame sees, before the heading turns it.
std::array<Vec2, 4> tilted_model(double h, double roll_rad, double pitch_rad) {
  std::array<Vec2, 4> q = model_corners(h);
  const double cr = std::cos(roll_rad), sr = std::sin(roll_rad);
  const double cp = std::cos(pitch_rad), sp = std::sin(pitch_rad);
  for (Vec2& v : q) v = {cp * v.x + sp * sr * v.y, cr * v.y};
  return q;
}

// Where the ray of normalized camera point xn meets the plane z = h_mm, in the site frame.
bool ray_to_plane(const site::CeilingCamera& cam, Vec2 xn, double h_mm, Vec2* xy_mm) {
  const auto& r = cam.r_site_cam;
  const auto& t = cam.t_site_cam_mm;
  const double d[3] = {r[0] * xn.x + r[1] * xn.y + r[2], r[3] * xn.x + r[4] * xn.y + r[5],
                       r[6] * xn.x + r[7] * xn.y + r[8]};
  if (!(std::abs(d[2]) > 1e-12)) return false;
  const double s = (h_mm - t[2]) / d[2];  // camera-frame depth along the ray (z = 1)
  if (!(s >= kMinRangeMm) || !std::isfinite(s)) return false;
  *xy_mm = {t[0] + s * d[0], t[1] + s * d[1]};
  return true;
}

// The corners' undistorted rays: the same for every plane and every camera pose a fix tries (the
// intrinsics do not change), so the lens is inverted once per corner.
bool corner_rays(const site::CeilingCamera& cam, const std::array<Vec2, 4>& px,
                 std::array<Vec2, 4>* xn) {
  const CameraModel lens = lens_of(cam);
  for (std::size_t i = 0; i < 4; ++i) {
    if (!lens.undistort_pixel_to_normalized(px[i], &(*xn)[i])) return false;
  }
  return true;
}

bool rays_on_plane(const site::CeilingCamera& cam, const std::array<Vec2, 4>& xn, double h_mm,
                   std::array<Vec2, 4>* xy) {
  for (std::size_t i = 0; i < 4; ++i) {
    if (!ray_to_plane(cam, xn[i], h_mm, &(*xy)[i])) return false;
  }
  return true;
}

bool corners_on_plane(const site::CeilingCamera& cam, const std::array<Vec2, 4>& px, double h_mm,
                      std::array<Vec2, 4>* xy) {
  std::array<Vec2, 4> xn{};
  return corner_rays(cam, px, &xn) && rays_on_plane(cam, xn, h_mm, xy);
}

// Central-difference steps on the camera's pose: the fix is linear in the translation and
// smooth in the angles; these are small against any calibration sigma worth stating.
constexpr double kPoseStepMm = 0.1;
constexpr double kPoseStepRad = 1e-5;

// The camera with one pose parameter (x, y, z, roll, pitch, yaw: the calibration's order)
// moved by delta. An angle moves through the site file's angles: R' = R(a + d) R(a)^T R, exact
// for any rotation R, whatever its angles round trip gives.
site::CeilingCamera moved(const site::CeilingCamera& cam, int param, double delta) {
  site::CeilingCamera out = cam;
  if (param < 3) {
    out.t_site_cam_mm[static_cast<std::size_t>(param)] += delta;
    return out;
  }
  double a[3] = {0, 0, 0};  // roll, pitch, yaw
  site::camera_angles_from_rotation(cam.r_site_cam, &a[2], &a[1], &a[0]);
  const auto r0 = site::camera_rotation_from_angles(a[2], a[1], a[0]);
  a[param - 3] += delta;
  const auto r1 = site::camera_rotation_from_angles(a[2], a[1], a[0]);
  std::array<double, 9> step{}, r{};
  for (int i = 0; i < 3; ++i) {
    for (int j = 0; j < 3; ++j) {
      for (int k = 0; k < 3; ++k) step[i * 3 + j] += r1[i * 3 + k] * r0[j * 3 + k];
    }
  }
  for (int i = 0; i < 3; ++i) {
    for (int j = 0; j < 3; ++j) {
      for (int k = 0; k < 3; ++k) r[i * 3 + j] += step[i * 3 + k] * cam.r_site_cam[k * 3 + j];
    }
  }
  out.r_site_cam = r;
  return out;
}

// The central difference in (x, y, theta) of the squares fitted to the corners moved by +step
// (xp) and -step (xm).
std::array<double, 3> central_difference(const std::array<Vec2, 4>& xp,
                                         const std::array<Vec2, 4>& xm, double h, double step) {
  const PlaneSquare a = fit_square(xp, h), b = fit_square(xm, h);
  return {(a.c.x - b.c.x) / (2.0 * step), (a.c.y - b.c.y) / (2.0 * step),
          std::remainder(a.theta - b.theta, 2.0 * kPi) / (2.0 * step)};
}

// Adds var J J^T to *cov, J the central difference above.
void add_central_difference(const std::array<Vec2, 4>& xp, const std::array<Vec2, 4>& xm, double h,
                            double step, double var, std::array<double, 9>* cov) {
  const std::array<double, 3> j = central_difference(xp, xm, h, step);
  for (std::size_t r = 0; r < 3; ++r) {
    for (std::size_t c = 0; c < 3; ++c) (*cov)[r * 3 + c] += var * j[r] * j[c];
  }
}

// J S J^T of the camera's pose covariance S (its sigmas and their correlation), in (x, y, theta):
// a calibration error moves every fix of the camera alike, so a fix is no surer than the pose it
// is cast through.
bool pose_covariance(const site::CeilingCamera& cam, const std::array<Vec2, 4>& rays,
                     double plane_height_mm, double h, std::array<double, 9>* cov) {
  cov->fill(0.0);
  std::array<std::array<double, 3>, 6> j{};  // per parameter: d(x, y, theta) * its sigma
  for (int p = 0; p < 6; ++p) {
    const std::size_t i = static_cast<std::size_t>(p % 3);
    const double sigma = p < 3 ? cam.position_sigma_mm[i] : cam.angle_sigma_rad[i];
    if (!(sigma > 0.0)) continue;
    const double step = p < 3 ? kPoseStepMm : kPoseStepRad;
    std::array<Vec2, 4> xp{}, xm{};
    if (!rays_on_plane(moved(cam, p, step), rays, plane_height_mm, &xp) ||
        !rays_on_plane(moved(cam, p, -step), rays, plane_height_mm, &xm)) {
      return false;
    }
    j[static_cast<std::size_t>(p)] = central_difference(xp, xm, h, step);
    for (double& v : j[static_cast<std::size_t>(p)]) v *= sigma;
  }
  for (int p = 0; p < 6; ++p) {
    for (int q = 0; q < 6; ++q) {
      const double rho = site::pose_correlation_at(cam, p, q);
      if (rho == 0.0) continue;
      const auto& a = j[static_cast<std::size_t>(p)];
      const auto& b = j[static_cast<std::size_t>(q)];
      for (std::size_t r = 0; r < 3; ++r) {
        for (std::size_t c = 0; c < 3; ++c) (*cov)[r * 3 + c] += rho * a[r] * b[c];
      }
    }
  }
  // Symmetric to the last bit, whatever the order of the sums.
  for (std::size_t r = 0; r < 3; ++r) {
    for (std::size_t c = r + 1; c < 3; ++c) {
      (*cov)[r * 3 + c] = (*cov)[c * 3 + r] = 0.5 * ((*cov)[r * 3 + c] + (*cov)[c * 3 + r]);
    }
  }
  return true;
}

// The detector finds each corner as the meeting point of two lines fitted to edge points sampled
// along the middle of a side (from kEdgeSpanMargin to 1 - kEdgeSpanMargin of its length). So the
// corners' errors are not independent: a line's offset error moves the two corners on it alike
// (a shift, which leaves the heading), its angle error about the samples' centre moves them in
// opposite directions (a turn, which all of the heading comes from). The corner sigma it reports
// is sqrt(mean over corners of (va + vb) / (2 sin^2)), with a line's offset variance at a corner
// v = v0 + v1 (L/2)^2 and, for evenly spread samples over a span l, v1 = 12 v0 / l^2.
constexpr double kEdgeSpanMargin = 0.12;
// A floor on each line's offset sigma (px): what moves an edge that its points' scatter does not
// show (the light's gradient and the vignetting across the tag, the pixel grid's phase), so it
// shifts the centre, not the heading. Calibrated on rendered frames (realistic effects, 60 px
// tags at 6 m, 20 vehicles for 10 s): with the lines' scatter alone the fixes' position error /
// sigma RMS was 1.62 per axis, with this floor 0.95 (40 px tags at 8 m: 0.97 but for one
// vehicle's outliers); the heading's, 1.22 there, is not moved by it.
constexpr double kEdgeOffsetFloorPx = 0.0075;

// The corners with side k's line moved by offset_px along its normal and turned by angle_rad
// about its midpoint; corner i is where sides i - 1 and i meet (the detector's order).
bool corners_with_side_moved(const std::array<Vec2, 4>& c, std::size_t k, double offset_px,
                             double angle_rad, std::array<Vec2, 4>* out) {
  std::array<Vec2, 4> p{}, d{};
  for (std::size_t j = 0; j < 4; ++j) {
    const Vec2 a = c[j], b = c[(j + 1) % 4];
    const double len = std::hypot(b.x - a.x, b.y - a.y);
    if (!(len > 0.0)) return false;
    p[j] = {0.5 * (a.x + b.x), 0.5 * (a.y + b.y)};
    d[j] = {(b.x - a.x) / len, (b.y - a.y) / len};
  }
  p[k] = {p[k].x - offset_px * d[k].y, p[k].y + offset_px * d[k].x};
  const double ca = std::cos(angle_rad), sa = std::sin(angle_rad);
  d[k] = {ca * d[k].x - sa * d[k].y, sa * d[k].x + ca * d[k].y};
  for (std::size_t i = 0; i < 4; ++i) {
    const std::size_t a = (i + 3) % 4;
    const double den = d[a].x * d[i].y - d[a].y * d[i].x;
    if (!(std::abs(den) > 1e-9)) return false;
    const double t = ((p[i].x - p[a].x) * d[i].y - (p[i].y - p[a].y) * d[i].x) / den;
    (*out)[i] = {p[a].x + t * d[a].x, p[a].y + t * d[a].y};
  }
  return true;
}

// Covariance of (x, y, theta) from the four edge lines' offset and angle errors (J diag J^T,
// central differences), their variances recovered from the reported corner sigma.
bool edge_covariance(const site::CeilingCamera& cam, const std::array<Vec2, 4>& px,
                     double corner_sigma_px, double plane_height_mm, double h,
                     std::array<double, 9>* cov) {
  cov->fill(0.0);
  const double span = 1.0 - 2.0 * kEdgeSpanMargin;
  double inv_sin2 = 0.0;
  std::array<double, 4> len{};
  for (std::size_t k = 0; k < 4; ++k) {
    const Vec2 a = px[(k + 3) % 4], b = px[k], c = px[(k + 1) % 4];
    len[k] = std::hypot(c.x - b.x, c.y - b.y);
    const double la = std::hypot(b.x - a.x, b.y - a.y);
    const double cr = ((b.x - a.x) * (c.y - b.y) - (b.y - a.y) * (c.x - b.x)) / (la * len[k]);
    if (!(std::abs(cr) > 1e-6) || !std::isfinite(cr)) return false;
    inv_sin2 += 0.25 / (cr * cr);
  }
  const double v0 = corner_sigma_px * corner_sigma_px / ((1.0 + 3.0 / (span * span)) * inv_sin2);
  for (std::size_t k = 0; k < 4; ++k) {
    const double l = span * len[k];
    const double var[2] = {v0 + kEdgeOffsetFloorPx * kEdgeOffsetFloorPx, 12.0 * v0 / (l * l)};
    const double step[2] = {kJacobianStepPx, kJacobianStepPx / len[k]};
    for (int q = 0; q < 2; ++q) {
      std::array<Vec2, 4> cp{}, cm{}, xp{}, xm{};
      const double sp = step[q], so = q == 0 ? 1.0 : 0.0;
      if (!corners_with_side_moved(px, k, so * sp, (1.0 - so) * sp, &cp) ||
          !corners_with_side_moved(px, k, -so * sp, -(1.0 - so) * sp, &cm) ||
          !corners_on_plane(cam, cp, plane_height_mm, &xp) ||
          !corners_on_plane(cam, cm, plane_height_mm, &xm)) {
        return false;
      }
      add_central_difference(xp, xm, h, sp, var[q], cov);
    }
  }
  return true;
}

// Central-difference steps on the tray plane: a slope (dimensionless) and a height (mm).
constexpr double kSlopeStep = 1e-4;
constexpr double kHeightStepMm = 0.1;

// The corners' rays met by the tray plane raised by dz at the centre and sloped by (gx, gy)
// about c, each corner's height taken at its point `at` of a previous cast.
bool rays_on_sloped_plane(const site::CeilingCamera& cam, const std::array<Vec2, 4>& rays,
                          double h_mm, const std::array<Vec2, 4>& at, Vec2 c, double gx, double gy,
                          double dz, std::array<Vec2, 4>* xy) {
  for (std::size_t i = 0; i < 4; ++i) {
    const double z = h_mm + dz + gx * (at[i].x - c.x) + gy * (at[i].y - c.y);
    if (!ray_to_plane(cam, rays[i], z, &(*xy)[i])) return false;
  }
  return true;
}

// J diag(sigma^2) J^T of the tray plane's slope along x and y and its height, added to *cov.
bool tray_plane_covariance(const site::CeilingCamera& cam, const std::array<Vec2, 4>& rays,
                           double plane_height_mm, double h, const std::array<Vec2, 4>& level,
                           const TrayPlaneSigma& sigma, std::array<double, 9>* cov) {
  const double slope_sigma = std::tan(sigma.tilt_rad);
  Vec2 c;
  for (const Vec2& v : level) c.x += 0.25 * v.x, c.y += 0.25 * v.y;
  for (int q = 0; q < 3; ++q) {
    const double s = q < 2 ? slope_sigma : sigma.height_mm;
    if (!(s > 0.0)) continue;
    const double step = q < 2 ? kSlopeStep : kHeightStepMm;
    const double d[3] = {q == 0 ? step : 0.0, q == 1 ? step : 0.0, q == 2 ? step : 0.0};
    std::array<Vec2, 4> xp{}, xm{};
    if (!rays_on_sloped_plane(cam, rays, plane_height_mm, level, c, d[0], d[1], d[2], &xp) ||
        !rays_on_sloped_plane(cam, rays, plane_height_mm, level, c, -d[0], -d[1], -d[2], &xm)) {
      return false;
    }
    add_central_difference(xp, xm, h, step, s * s, cov);
  }
  return true;
}

struct Tray {
  double height_mm, tag_size_mm, roll_rad, pitch_rad;
};

// The square fitted to the corners cast onto the tray's plane: level, or tilted by the tray's
// roll and pitch in the vehicle frame, which the fitted heading turns into the site frame (the
// heights taken at the previous pass's corners; three passes leave well under a micrometre).
bool fit_on_tray(const site::CeilingCamera& cam, const std::array<Vec2, 4>& rays, const Tray& t,
                 std::array<Vec2, 4>* xy, PlaneSquare* sq) {
  const double h = 0.5 * t.tag_size_mm;
  if (!rays_on_plane(cam, rays, t.height_mm, xy)) return false;
  *sq = fit_square(*xy, h);
  if (t.roll_rad == 0.0 && t.pitch_rad == 0.0) return true;
  // The plane's slope along the vehicle's x and y (its normal Ry(pitch) Rx(roll) z).
  const double gxv = -std::tan(t.pitch_rad), gyv = std::tan(t.roll_rad) / std::cos(t.pitch_rad);
  const std::array<Vec2, 4> model = tilted_model(h, t.roll_rad, t.pitch_rad);
  for (int pass = 0; pass < 3; ++pass) {
    const double c = std::cos(sq->theta), s = std::sin(sq->theta);
    const std::array<Vec2, 4> at = *xy;
    if (!rays_on_sloped_plane(cam, rays, t.height_mm, at, sq->c, c * gxv - s * gyv,
                              s * gxv + c * gyv, 0.0, xy)) {
      return false;
    }
    *sq = fit_model(*xy, model);
  }
  return true;
}

bool fix_on_plane(const site::CeilingCamera& cam, const std::array<Vec2, 4>& corners_px,
                  double corner_sigma_px, const Tray& t, double max_size_error_rel,
                  const TrayPlaneSigma& tray, TagFix* out) {
  if (!out || !(t.tag_size_mm > 0.0) || !std::isfinite(t.tag_size_mm) ||
      !(corner_sigma_px >= 0.0) || !std::isfinite(corner_sigma_px) ||
      !(tray.tilt_rad >= 0.0 && tray.tilt_rad < 0.5 * kPi) || !(tray.height_mm >= 0.0) ||
      !std::isfinite(tray.height_mm) || !(std::abs(t.roll_rad) < 0.5 * kPi) ||
      !(std::abs(t.pitch_rad) < 0.5 * kPi)) {
    return false;
  }
  const double h = 0.5 * t.tag_size_mm;
  std::array<Vec2, 4> rays{}, xy{};
  PlaneSquare s;
  if (!valid_intrinsics(cam.intrinsics) || !corner_rays(cam, corners_px, &rays) ||
      !fit_on_tray(cam, rays, t, &xy, &s)) {
    return false;
  }
  if (!(std::abs(s.scale - 1.0) <= max_size_error_rel)) return false;
  if (!edge_covariance(cam, corners_px, corner_sigma_px, t.height_mm, h, &out->cov)) {
    return false;
  }
  if (!pose_covariance(cam, rays, t.height_mm, h, &out->cov_camera) ||
      !tray_plane_covariance(cam, rays, t.height_mm, h, xy, tray, &out->cov_camera)) {
    return false;
  }
  out->cov_camera[0] += cam.floor_sigma_mm * cam.floor_sigma_mm;
  out->cov_camera[4] += cam.floor_sigma_mm * cam.floor_sigma_mm;
  for (std::size_t i = 0; i < 9; ++i) out->cov[i] += out->cov_camera[i];
  out->pose = {s.c.x, s.c.y, s.theta};
  out->size_error_rel = s.scale - 1.0;
  out->residual_mm = s.rms;
  return true;
}

}  // namespace tag_fix_detail

bool pixel_to_plane(const site::CeilingCamera& cam, Vec2 px, double plane_height_mm, Vec2* xy_mm) {
  using namespace tag_fix_detail;
  if (!xy_mm || !valid_intrinsics(cam.intrinsics) || !std::isfinite(plane_height_mm)) return false;
  Vec2 xn;
  return lens_of(cam).undistort_pixel_to_normalized(px, &xn) &&
         ray_to_plane(cam, xn, plane_height_mm, xy_mm);
}

bool site_to_pixel(const site::CeilingCamera& cam, double x_mm, double y_mm, double z_mm,
                   Vec2* px) {
  using namespace tag_fix_detail;
  if (!px || !valid_intrinsics(cam.intrinsics) || !std::isfinite(x_mm) || !std::isfinite(y_mm) ||
      !std::isfinite(z_mm)) {
    return false;
  }
  const auto& r = cam.r_site_cam;
  const auto& t = cam.t_site_cam_mm;
  const double v[3] = {x_mm - t[0], y_mm - t[1], z_mm - t[2]};
  // p_cam = R^T (p_site - t).
  const double xc = r[0] * v[0] + r[3] * v[1] + r[6] * v[2];
  const double yc = r[1] * v[0] + r[4] * v[1] + r[7] * v[2];
  const double zc = r[2] * v[0] + r[5] * v[1] + r[8] * v[2];
  if (!(zc > kMinRangeMm)) return false;
  *px = lens_of(cam).distort_normalized_to_pixel({xc / zc, yc / zc});
  return std::isfinite(px->x) && std::isfinite(px->y);
}

bool tag_fix_on_plane(const site::CeilingCamera& cam, const std::array<Vec2, 4>& corners_px,
                      double corner_sigma_px, double plane_height_mm, double tag_size_mm,
                      TagFix* out, double max_size_error_rel) {
  return tag_fix_detail::fix_on_plane(cam, corners_px, corner_sigma_px,
                                      {plane_height_mm, tag_size_mm, 0.0, 0.0}, max_size_error_rel,
                                      {}, out);
}

bool tag_fix_on_tray(const site::CeilingCamera& cam, const std::array<Vec2, 4>& corners_px,
                     double corner_sigma_px, const site::FleetAgv& agv, const TrayPlaneSigma& sigma,
                     TagFix* out) {
  return tag_fix_detail::fix_on_plane(
      cam, corners_px, corner_sigma_px,
      {agv.tray_height_mm, agv.tag_size_mm, agv.tray_roll_rad, agv.tray_pitch_rad},
      kDefaultMaxSizeErrorRel, sigma, out);
}

}  // namespace agv::overhead
