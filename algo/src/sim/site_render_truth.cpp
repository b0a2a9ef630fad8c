// Site renderer: ground truth of a frame (projected corners, visible fractions by ray casting
// against every face) and the imaging effects (illumination, defocus, sensor noise).
// docs/design/site_render.md.
#include <algorithm>
#include <cmath>
#include <opencv2/imgproc.hpp>
#include <random>

#include "render_effects.hpp"
#include "site_render_internal.hpp"

namespace agv::sim::site_render_detail {

namespace {

Vec3 face_point(const Face& f, double u, double v) {
  return add3(f.o, add3(mul3(f.eu, u), mul3(f.ev, v)));
}

// Fraction of a page face's black square (half-side h) seen by the camera: grid x grid points,
// each inside the image, on the printed side, and with no other face nearer along its ray.
double visible_fraction(const RenderCamera& cam, const std::vector<Face>& faces,
                        const std::vector<CamFace>& cfs, int self, double h, int grid) {
  const Face& f = faces[static_cast<size_t>(self)];
  const Vec3 c{cam.t_site_cam_mm[0], cam.t_site_cam_mm[1], cam.t_site_cam_mm[2]};
  const int w = cam.intrinsics.width_px, hh = cam.intrinsics.height_px;
  std::vector<Vec3> pts;
  for (int j = 0; j < grid; ++j) {
    for (int i = 0; i < grid; ++i) {
      pts.push_back(
          face_point(f, -h + 2.0 * h * (i + 0.5) / grid, -h + 2.0 * h * (j + 0.5) / grid));
    }
  }
  std::vector<std::uint8_t> ok;
  const std::vector<Vec2> px = project_points(cam, pts, &ok);
  int seen = 0;
  for (size_t k = 0; k < pts.size(); ++k) {
    if (!ok[k] ||
        !(px[k].x >= -0.5 && px[k].y >= -0.5 && px[k].x < w - 0.5 && px[k].y < hh - 0.5)) {
      continue;
    }
    if (!(dot3(sub3(pts[k], c), f.n) > 0.0)) continue;  // the back of the print
    const Vec3 pc = rot3t(cam.r_site_cam, sub3(pts[k], c));
    const double x = pc.x / pc.z, y = pc.y / pc.z;
    const auto xf = static_cast<float>(x), yf = static_cast<float>(y);
    bool hidden = false;
    for (size_t j = 0; j < faces.size() && !hidden; ++j) {
      const CamFace& cf = cfs[j];
      if (static_cast<int>(j) == self || !cf.visible || xf < cf.box[0] || xf > cf.box[2] ||
          yf < cf.box[1] || yf > cf.box[3]) {
        continue;
      }
      const double dn = cf.nd.x * x + cf.nd.y * y + cf.nd.z;
      if (dn == 0.0) continue;
      const double tt = cf.c / dn;  // the point itself is at t = pc.z
      if (!(tt > 1e-6 && tt < pc.z - 1e-3)) continue;
      const double u = cf.ou + tt * (cf.ud.x * x + cf.ud.y * y + cf.ud.z);
      const double v = cf.ov + tt * (cf.vd.x * x + cf.vd.y * y + cf.vd.z);
      hidden = poly_contains(faces[j].poly, u, v);
    }
    if (!hidden) ++seen;
  }
  return pts.empty() ? 0.0 : static_cast<double>(seen) / static_cast<double>(pts.size());
}

template <size_t N>
bool project_all(const RenderCamera& cam, const std::vector<Vec3>& pts, std::array<Vec2, N>* out) {
  std::vector<std::uint8_t> ok;
  const std::vector<Vec2> px = project_points(cam, pts, &ok);
  bool all = true;
  for (size_t i = 0; i < N; ++i) {
    (*out)[i] = px[i];
    all = all && ok[i];
  }
  return all;
}

BoxTruth top_truth(const RenderCamera& cam, const std::vector<Face>& faces, int top, size_t k) {
  BoxTruth b;
  b.index = k;
  if (top < 0) return b;
  const Face& f = faces[static_cast<size_t>(top)];
  Vec2 m{0, 0};
  for (const Vec2& q : f.poly) m = {m.x + q.x, m.y + q.y};
  const double n = static_cast<double>(f.poly.size());
  b.centre_site = face_point(f, m.x / n, m.y / n);
  std::array<Vec2, 1> px{};
  b.projected = project_all(cam, {b.centre_site}, &px);
  b.centre_px = px[0];
  return b;
}

}  // namespace

void fill_truth(const SiteScene& scene, const RenderCamera& cam, const SiteRenderParams& p,
                const std::vector<Face>& faces, const std::vector<CamFace>& cfs,
                const FaceIndex& index, RenderResult* out) {
  const int grid = std::clamp(p.visibility_grid, 1, 256);
  for (size_t i = 0; i < scene.site.fleet.size(); ++i) {
    const site::FleetAgv& a = scene.site.fleet[i];
    AgvTruth t;
    t.index = i;
    t.id = a.id;
    t.tag_id = a.tag_id;
    t.pose = scene.agvs[i].pose;
    const int fi = index.agv_tag_face[i];
    const Face& f = faces[static_cast<size_t>(fi)];
    const double h = 0.5 * a.tag_size_mm;
    const std::vector<Vec3> tag = {face_point(f, -h, -h), face_point(f, h, -h), face_point(f, h, h),
                                   face_point(f, -h, h)};
    // Tray page axes: u = vehicle -y, v = vehicle -x.
    const double hl = 0.5 * a.tray_length_mm, hw = 0.5 * a.tray_width_mm;
    const std::vector<Vec3> tray = {face_point(f, -hw, -hl), face_point(f, hw, -hl),
                                    face_point(f, hw, hl), face_point(f, -hw, hl)};
    t.projected =
        project_all(cam, tag, &t.tag_corners_px) && project_all(cam, tray, &t.tray_corners_px);
    t.tag_visible_fraction = f.page ? visible_fraction(cam, faces, cfs, fi, h, grid) : 0.0;
    out->agvs.push_back(t);
  }
  for (size_t k = 0; k < scene.site.wall_landmarks.size(); ++k) {
    const site::WallLandmark& wl = scene.site.wall_landmarks[k];
    WallLandmarkTruth t;
    t.id = wl.id;
    const int fi = index.wall_face[k];
    if (fi >= 0) {
      const Face& f = faces[static_cast<size_t>(fi)];
      const double h = 0.5 * wl.size_mm;
      t.projected = project_all(
          cam,
          {face_point(f, -h, -h), face_point(f, h, -h), face_point(f, h, h), face_point(f, -h, h)},
          &t.corners_px);
      t.visible_fraction = visible_fraction(cam, faces, cfs, fi, h, grid);
    }
    out->wall_landmarks.push_back(t);
  }
  for (size_t k = 0; k < scene.parcels.size(); ++k) {
    out->parcels.push_back(top_truth(cam, faces, index.parcel_top_face[k], k));
  }
  for (size_t k = 0; k < scene.clutter.size(); ++k) {
    out->clutter.push_back(top_truth(cam, faces, index.clutter_top_face[k], k));
  }
}

cv::Mat finish_image(const cv::Mat& radiance, const SiteRenderParams& p, std::uint64_t seed) {
  cv::Mat img = radiance.clone();
  const int w = img.cols, h = img.rows;
  const double gain = std::max(0.0, p.exposure_gain);
  const double ratio = std::clamp(p.illumination_ratio, 0.0, 10.0);
  const double vig = std::clamp(p.vignetting, 0.0, 1.0);
  if (ratio != 1.0 || gain != 1.0 || vig > 0.0) {
    const IlluminationGradient g = illumination_gradient(w, h, p.illumination_direction_deg);
    const double mx = 0.5 * (w - 1), my = 0.5 * (h - 1);
    const double r2c = std::max(1e-9, mx * mx + my * my);
    for (int y = 0; y < h; ++y) {
      float* row = img.ptr<float>(y);
      for (int x = 0; x < w; ++x) {
        const double t = g.at(x, y);
        const double r2 = ((x - mx) * (x - mx) + (y - my) * (y - my)) / r2c;
        row[x] = static_cast<float>(static_cast<double>(row[x]) * gain * (1.0 + (ratio - 1.0) * t) *
                                    (1.0 - vig * r2));
      }
    }
  }
  if (p.defocus_sigma_px > 0.0) {
    cv::GaussianBlur(img, img, cv::Size(0, 0), p.defocus_sigma_px, p.defocus_sigma_px,
                     cv::BORDER_REFLECT);
  }
  std::mt19937_64 rng(seed);
  return quantise_with_noise(img, p.read_noise_sigma, p.shot_noise_gain, rng);
}

}  // namespace agv::sim::site_render_detail
