// Down-looking floor camera: OpenCV pinhole + Brown-Conrady distortion, optical axis nominally
// perpendicular to the floor at a known height, mounted on the vehicle with an offset, a yaw and
// a small tilt (roll, pitch).
// Frames and sign conventions: docs/design/frames.md ("Camera frame" and "Mounting").
#pragma once

#include <cmath>
#include <limits>

#include "agv/common/geometry.hpp"

namespace agv {

// OpenCV camera model; pixel centres at integer coordinates (pixel (0,0) covers [-0.5,0.5]^2).
struct CameraIntrinsics {
  int width_px = 640;
  int height_px = 480;
  double fx = 0.0, fy = 0.0;                                // focal lengths in pixels
  double cx = 0.0, cy = 0.0;                                // principal point in pixels
  double k1 = 0.0, k2 = 0.0, p1 = 0.0, p2 = 0.0, k3 = 0.0;  // OpenCV distortion
};

// Where the camera sits on the vehicle. The vehicle frame has x forward, y left (mm).
struct CameraMount {
  double offset_x_mm = 0.0;  // optical centre in the vehicle frame
  double offset_y_mm = 0.0;
  // Yaw of the image axes relative to the vehicle, counter-clockwise seen from above.
  // 0 means: image "up" (decreasing row) points along vehicle +x, image "right" along -y.
  double yaw_rad = 0.0;
  double height_mm = 200.0;  // optical centre above the floor
  // Tilt of the camera (docs/design/frames.md, "Camera tilt"): the camera body frame B (x = image
  // up, y = image left, z = against the optical axis) is R_VB = Rz(yaw) * Ry(pitch) * Rx(roll) in
  // the vehicle frame (intrinsic z-y'-x''). Positive roll turns the optical axis towards image
  // left, positive pitch towards image down. 0, 0 = optical axis perpendicular to the floor;
  // exactly 0, 0 takes the untilted code path, bit for bit.
  double roll_rad = 0.0;
  double pitch_rad = 0.0;

  bool tilted() const { return roll_rad != 0.0 || pitch_rad != 0.0; }
  // Camera-to-vehicle rotation R_VC (row-major 3x3): columns are the camera axes x_C (image
  // right), y_C (image down), z_C (optical axis) expressed in V.
  void rotation_vehicle_from_camera(double r[9]) const;
};

struct CameraModel {
  CameraIntrinsics intrinsics;
  CameraMount mount;

  // Floor point in the vehicle frame (mm) -> distorted pixel. False when the point cannot be
  // imaged (non-finite input, or behind a tilted camera). Does not check image bounds.
  bool vehicle_to_pixel(Vec2 p_vehicle_mm, Vec2* pixel) const;
  // Distorted pixel -> floor point in the vehicle frame (mm): the pixel's ray intersected with
  // the floor. False when undistortion does not converge (far outside the calibrated field) or
  // the ray of a tilted camera does not reach the floor.
  bool pixel_to_vehicle(Vec2 pixel, Vec2* p_vehicle_mm) const;

  // Normalised undistorted image coordinates <-> distorted pixels.
  Vec2 distort_normalized_to_pixel(Vec2 xn) const;
  bool undistort_pixel_to_normalized(Vec2 pixel, Vec2* xn) const;

  // Approximate floor size of one pixel at the image centre (mm/px), from fx, fy and height.
  double mm_per_px() const;

  // A consistent default: 640x480, 0.26 mm/px at the floor, no distortion, centred mount.
  static CameraModel default_640x480();
  // 1280x800 profile with the same field of view in x (about 0.13 mm/px).
  static CameraModel default_1280x800();
};

// CameraModel's floor mapping with the mount's trigonometry done once. A tilted mount's rotation
// takes six sines and cosines per point, which was a fifth of a tracked frame's instructions
// (edge points, QR modules and logo samples are mapped by the thousand); the localizer's loops
// map through one of these, built with the localizer. CameraModel's own methods build one per
// call, so both give the same result to the last bit. Keeps a copy of the model: later changes to
// the original do not reach it.
class PlaneProjector;

// Which of the distortion terms are non-zero: the projectors leave the others out. Non-finite
// coefficients count as kFull, so their NaN is kept rather than a term dropped.
enum class LensTerms { kNone, kRadial, kFull };
LensTerms lens_terms(const CameraIntrinsics& k);

class FloorProjector {
 public:
  explicit FloorProjector(const CameraModel& model);
  // As CameraModel::vehicle_to_pixel and pixel_to_vehicle.
  bool vehicle_to_pixel(Vec2 p_vehicle_mm, Vec2* pixel) const;
  bool pixel_to_vehicle(Vec2 pixel, Vec2* p_vehicle_mm) const;
  // As CameraModel::undistort_pixel_to_normalized, with the same round-trip check; every edge
  // point goes through it, and that Newton iteration was 5 % of a tracked frame's instructions
  // without distortion and 7 % with a radial lens (docs/design/performance.md).
  // - No distortion: that iteration takes one step of exactly zero, so the same point comes
  //   without it, to the last bit (including its refusals).
  // - Radial terms only: the undistorted point lies on the ray through the distorted one, so the
  //   2-D iteration is a 1-D Newton iteration on the scale along the ray; done as such it takes
  //   a third of the operations. It agrees with the 2-D one to rounding (2e-14 in the tests) and
  //   refuses where its Jacobian's determinant vanishes, as that one does.
  // - Tangential terms: CameraModel's iteration.
  bool undistort(Vec2 pixel, Vec2* xn) const;
  const CameraModel& model() const { return m_; }
  // The pixels of a plane on the floor whose point (u, v) lies at origin + u * axis_u +
  // v * axis_v in the vehicle frame (mm): a landmark's page at one pose (PlaneProjector).
  PlaneProjector plane(Vec2 origin_mm, Vec2 axis_u, Vec2 axis_v) const;

 private:
  // undistort with distortion terms (out of line; the lens-free case is inline below, because
  // every edge point of a frame goes through it).
  bool undistort_with_lens(Vec2 pixel, Vec2* xn) const;
  // undistort's radial-only iteration from the distorted normalised point (xd, yd).
  bool undistort_radial(Vec2 pixel, double xd, double yd, Vec2* xn) const;

  CameraModel m_;
  bool tilted_ = false;
  LensTerms lens_ = LensTerms::kFull;
  double r_[9] = {};                      // R_VC, tilted mounts only
  double cos_yaw_ = 1.0, sin_yaw_ = 0.0;  // untilted mounts only
};

inline bool FloorProjector::undistort(Vec2 pixel, Vec2* xn) const {
  if (lens_ != LensTerms::kNone) return undistort_with_lens(pixel, xn);
  const auto& k = m_.intrinsics;
  if (!(k.fx > 0.0) || !(k.fy > 0.0) || !std::isfinite(pixel.x) || !std::isfinite(pixel.y)) {
    return false;
  }
  const double xd = (pixel.x - k.cx) / k.fx;
  const double yd = (pixel.y - k.cy) / k.fy;
  // The Newton step's terms multiply zero coefficients by r2 and 3 r2: finite, they vanish and
  // the step is exactly zero; infinite, they give NaN and the iteration refuses the point. So
  // refuse it here too.
  if (!std::isfinite(3.0 * (xd * xd + yd * yd))) return false;
  // distort_normalized_to_pixel without its zero terms: the same round-trip check.
  const double bx = k.fx * xd + k.cx, by = k.fy * yd + k.cy;
  if (!(std::abs(bx - pixel.x) < 1e-6 && std::abs(by - pixel.y) < 1e-6)) return false;
  *xn = {xd, yd};
  return true;
}

inline bool FloorProjector::pixel_to_vehicle(Vec2 pixel, Vec2* p) const {
  const CameraMount& mount = m_.mount;
  Vec2 xn;
  if (!(mount.height_mm > 0.0) || !undistort(pixel, &xn)) return false;
  if (tilted_) {
    // Ray (xn, 1) in C, rotated into V, intersected with the floor z = 0.
    const double* r = r_;
    const double rx = r[0] * xn.x + r[1] * xn.y + r[2];
    const double ry = r[3] * xn.x + r[4] * xn.y + r[5];
    const double rz = r[6] * xn.x + r[7] * xn.y + r[8];
    if (!(rz < -1e-9)) return false;  // the ray does not reach the floor
    const double t = mount.height_mm / -rz;
    *p = {mount.offset_x_mm + t * rx, mount.offset_y_mm + t * ry};
    return true;
  }
  const double xc = xn.x * mount.height_mm, yc = xn.y * mount.height_mm;
  const double c = cos_yaw_, s = sin_yaw_;
  // Inverse of the rotation in vehicle_to_pixel.
  const double dx = xc * s - yc * c;
  const double dy = -xc * c - yc * s;
  *p = {dx + mount.offset_x_mm, dy + mount.offset_y_mm};
  return true;
}

// FloorProjector::vehicle_to_pixel for the points of one plane at one pose. The floor point ->
// camera point step is affine, and so is (u, v) -> floor point, so both fold into one 3x3
// matrix built once per pose: a point then costs 9 multiply-adds, two divisions and the lens
// model, instead of a rigid transform, the mount rotation and two calls. The projections of the
// logo and QR module samples (about 2000 points a landmark frame) were about a fifth of a tracked
// frame's instructions (docs/design/performance.md). Equal to vehicle_to_pixel up to rounding
// (within 1e-9 px in tests/common/test_camera_model.cpp). Keeps a copy of the intrinsics.
class PlaneProjector {
 public:
  // False (pixel untouched) where vehicle_to_pixel is false: behind a tilted camera, a
  // non-finite point, or a projector built from a model without a positive height.
  bool to_pixel(Vec2 uv, Vec2* pixel) const {
    const double* a = a_;
    const double x = a[0] * uv.x + a[1] * uv.y + a[2];
    const double y = a[3] * uv.x + a[4] * uv.y + a[5];
    const double z = a[6] * uv.x + a[7] * uv.y + a[8];
    if (!(z > z_min_) || !std::isfinite(x) || !std::isfinite(y)) return false;
    const double xn = x / z, yn = y / z;
    const CameraIntrinsics& k = k_;
    double xd = xn, yd = yn;
    // The terms of CameraModel::distort_normalized_to_pixel whose coefficients are all zero add
    // exact zeros (every value here is finite), so leaving them out gives the same pixel.
    if (lens_ != LensTerms::kNone) {
      const double r2 = xn * xn + yn * yn;
      const double radial = 1.0 + r2 * (k.k1 + r2 * (k.k2 + r2 * k.k3));
      if (lens_ == LensTerms::kRadial) {
        xd = xn * radial;
        yd = yn * radial;
      } else {
        xd = xn * radial + 2.0 * k.p1 * xn * yn + k.p2 * (r2 + 2.0 * xn * xn);
        yd = yn * radial + k.p1 * (r2 + 2.0 * yn * yn) + 2.0 * k.p2 * xn * yn;
      }
    }
    *pixel = {k.fx * xd + k.cx, k.fy * yd + k.cy};
    return true;
  }

 private:
  friend class FloorProjector;
  LensTerms lens_ = LensTerms::kFull;
  CameraIntrinsics k_;
  double a_[9] = {};  // camera point (x, y, z) = a * (u, v, 1)
  double z_min_ = std::numeric_limits<double>::infinity();  // built invalid: every point fails
};

}  // namespace agv
