// The tray fit's window and edge points (tray_fit_internal.hpp).
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <vector>

#include "agv/vision/edges.hpp"
#include "tray_fit_internal.hpp"

namespace agv::overhead::tray_fit_detail {

bool tray_window(const site::CeilingCamera& cam, const site::FleetAgv& agv, const Pose2& predicted,
                 double sigma_pos_mm, double sigma_theta_rad, const TrayFitParams& p,
                 TrayWindow* out, std::string* why) {
  const double z = agv.tray_height_mm;
  Vec2 c_px, u_px;
  if (!site_to_pixel(cam, predicted.x_mm, predicted.y_mm, z, &c_px) ||
      !site_to_pixel(cam, predicted.x_mm + 1.0, predicted.y_mm, z, &u_px)) {
    if (why) *why = "predicted tray is behind the camera";
    return false;
  }
  const double px_per_mm = std::hypot(u_px.x - c_px.x, u_px.y - c_px.y);
  if (!(px_per_mm > 0.0)) {
    if (why) *why = "camera scale at the predicted tray is zero";
    return false;
  }
  out->mm_per_px = 1.0 / px_per_mm;
  out->reach_mm = p.sigma_window * sigma_pos_mm + p.margin_mm;
  // The tray's corners widened by the reach, turned through the heading's swing (a rectangle's
  // corners sweep at most a quarter turn before the box repeats).
  const double swing = std::min(p.sigma_window * sigma_theta_rad, 0.5 * kPi);
  const double hl = 0.5 * agv.tray_length_mm + out->reach_mm;
  const double hw = 0.5 * agv.tray_width_mm + out->reach_mm;
  constexpr int kTurns = 9;
  double x0 = 1e300, y0 = 1e300, x1 = -1e300, y1 = -1e300;
  for (int k = 0; k < kTurns; ++k) {
    const double a = swing * (2.0 * k / (kTurns - 1) - 1.0);
    const Pose2 pose{predicted.x_mm, predicted.y_mm, predicted.theta_rad + a};
    for (const Vec2 corner : {Vec2{hl, hw}, Vec2{hl, -hw}, Vec2{-hl, -hw}, Vec2{-hl, hw}}) {
      const Vec2 s = transform(pose, corner);
      Vec2 px;
      if (!site_to_pixel(cam, s.x, s.y, z, &px)) {
        if (why) *why = "predicted tray window reaches behind the camera";
        return false;
      }
      x0 = std::min(x0, px.x);
      y0 = std::min(y0, px.y);
      x1 = std::max(x1, px.x);
      y1 = std::max(y1, px.y);
    }
  }
  // One pixel of the image's rim is left out: the gradient needs both neighbours.
  const int w = cam.intrinsics.width_px, h = cam.intrinsics.height_px;
  const double lx = std::max(x0 - 2.0, 1.0), ly = std::max(y0 - 2.0, 1.0);
  const double hx = std::min(x1 + 2.0, w - 2.0), hy = std::min(y1 + 2.0, h - 2.0);
  if (!(hx - lx >= 4.0 && hy - ly >= 4.0)) {
    if (why) *why = "predicted tray is outside the image";
    return false;
  }
  const int ix = static_cast<int>(std::floor(lx)), iy = static_cast<int>(std::floor(ly));
  out->roi = cv::Rect(ix, iy, static_cast<int>(std::ceil(hx)) - ix + 1,
                      static_cast<int>(std::ceil(hy)) - iy + 1);
  return true;
}

namespace {

// Bilinear sample of a float image at (x, y) inside it.
float bilinear(const cv::Mat& m, double x, double y) {
  const int ix = std::clamp(static_cast<int>(std::floor(x)), 0, m.cols - 2);
  const int iy = std::clamp(static_cast<int>(std::floor(y)), 0, m.rows - 2);
  const float fx = static_cast<float>(x - ix), fy = static_cast<float>(y - iy);
  const float* r0 = m.ptr<float>(iy);
  const float* r1 = m.ptr<float>(iy + 1);
  return (1.0f - fy) * ((1.0f - fx) * r0[ix] + fx * r0[ix + 1]) +
         fy * ((1.0f - fx) * r1[ix] + fx * r1[ix + 1]);
}

// Pixel -> tray plane over a window: exact rays on a grid, bilinear between them. The mapping is
// smooth (perspective and a lens polynomial), so on 16-pixel cells the interpolation is off by
// thousandths of a pixel, at a tenth of the undistortions.
class PlaneGrid {
 public:
  static constexpr int kStepPx = 16;
  bool build(const site::CeilingCamera& cam, const cv::Rect& roi, double z) {
    x0_ = roi.x;
    y0_ = roi.y;
    nx_ = roi.width / kStepPx + 2;
    ny_ = roi.height / kStepPx + 2;
    nodes_.resize(static_cast<std::size_t>(nx_ * ny_));
    for (int j = 0; j < ny_; ++j) {
      for (int i = 0; i < nx_; ++i) {
        const Vec2 px{static_cast<double>(x0_ + i * kStepPx),
                      static_cast<double>(y0_ + j * kStepPx)};
        if (!pixel_to_plane(cam, px, z, &nodes_[static_cast<std::size_t>(j * nx_ + i)])) {
          return false;
        }
      }
    }
    return true;
  }
  Vec2 at(Vec2 px) const {
    const double gx = (px.x - x0_) / kStepPx, gy = (px.y - y0_) / kStepPx;
    const int i = std::clamp(static_cast<int>(std::floor(gx)), 0, nx_ - 2);
    const int j = std::clamp(static_cast<int>(std::floor(gy)), 0, ny_ - 2);
    const double fx = gx - i, fy = gy - j;
    const Vec2& a = nodes_[static_cast<std::size_t>(j * nx_ + i)];
    const Vec2& b = nodes_[static_cast<std::size_t>(j * nx_ + i + 1)];
    const Vec2& c = nodes_[static_cast<std::size_t>((j + 1) * nx_ + i)];
    const Vec2& d = nodes_[static_cast<std::size_t>((j + 1) * nx_ + i + 1)];
    return {(1 - fy) * ((1 - fx) * a.x + fx * b.x) + fy * ((1 - fx) * c.x + fx * d.x),
            (1 - fy) * ((1 - fx) * a.y + fx * b.y) + fy * ((1 - fx) * c.y + fx * d.y)};
  }

 private:
  int x0_ = 0, y0_ = 0, nx_ = 0, ny_ = 0;
  std::vector<Vec2> nodes_;
};

}  // namespace

void plane_edges(const cv::Mat& gray, const site::CeilingCamera& cam, const site::FleetAgv& agv,
                 const Pose2& predicted, const TrayWindow& win, const TrayFitParams& p,
                 std::vector<PlaneEdge>* out) {
  out->clear();
  cv::Mat gx, gy;
  vision::prewitt(gray, win.roi, &gx, &gy);
  cv::Mat mag(win.roi.height, win.roi.width, CV_32FC1);
  for (int y = 0; y < mag.rows; ++y) {
    const std::int16_t* ax = gx.ptr<std::int16_t>(y);
    const std::int16_t* ay = gy.ptr<std::int16_t>(y);
    float* m = mag.ptr<float>(y);
    for (int x = 0; x < mag.cols; ++x) {
      m[x] = std::hypot(static_cast<float>(ax[x]), static_cast<float>(ay[x]));
    }
  }
  const double z = agv.tray_height_mm;
  // The lens and the perspective change little across a window: one Jacobian (plane mm per
  // pixel) at its centre carries every edge's direction onto the plane.
  const Vec2 mid{win.roi.x + 0.5 * win.roi.width, win.roi.y + 0.5 * win.roi.height};
  Vec2 p0, px_step, py_step;
  if (!pixel_to_plane(cam, mid, z, &p0) ||
      !pixel_to_plane(cam, {mid.x + 1.0, mid.y}, z, &px_step) ||
      !pixel_to_plane(cam, {mid.x, mid.y + 1.0}, z, &py_step)) {
    return;
  }
  const double j[4] = {px_step.x - p0.x, py_step.x - p0.x, px_step.y - p0.y, py_step.y - p0.y};
  thread_local PlaneGrid grid;
  if (!grid.build(cam, win.roi, z)) return;
  for (int y = 1; y + 1 < mag.rows; ++y) {
    const std::int16_t* ax = gx.ptr<std::int16_t>(y);
    const std::int16_t* ay = gy.ptr<std::int16_t>(y);
    const float* m = mag.ptr<float>(y);
    for (int x = 1; x + 1 < mag.cols; ++x) {
      const double g = static_cast<double>(m[x]);
      if (!(g >= p.min_gradient)) continue;
      const double ux = ax[x] / g, uy = ay[x] / g;
      // Thinned along the gradient: a maximum of the magnitude one pixel either way.
      const double before = static_cast<double>(bilinear(mag, x - ux, y - uy));
      const double after = static_cast<double>(bilinear(mag, x + ux, y + uy));
      if (!(g > before && g >= after)) continue;
      const double curvature = before - 2.0 * g + after;
      const double t =
          curvature < 0.0 ? std::clamp(0.5 * (before - after) / curvature, -0.5, 0.5) : 0.0;
      const Vec2 px{win.roi.x + x + t * ux, win.roi.y + y + t * uy};
      const Vec2 a = grid.at(px);
      // The gradient's axis on the plane: the edge's tangent (-uy, ux) carried over, turned.
      const double tx = -j[0] * uy + j[1] * ux, ty = -j[2] * uy + j[3] * ux;
      double axis = std::atan2(ty, tx) + 0.5 * kPi;
      axis = std::fmod(axis, kPi);
      if (axis < 0.0) axis += kPi;
      out->push_back({{a.x - predicted.x_mm, a.y - predicted.y_mm},
                      axis,
                      {std::cos(2.0 * axis), std::sin(2.0 * axis)}});
    }
  }
}

}  // namespace agv::overhead::tray_fit_detail
