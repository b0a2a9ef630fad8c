// Site renderer: per-pixel rays, tile binning and the two-pass raster (one sample per pixel, then
// sub-samples where the surface or the print changes, and sub-frame instants where a vehicle
// moves across the pixel). docs/design/site_render.md.
#include <algorithm>
#include <cmath>
#include <limits>

#include "site_render_internal.hpp"

namespace agv::sim {

using site_render_detail::CamFace;
using site_render_detail::Face;
using site_render_detail::FaceIndex;
using site_render_detail::Material;
using site_render_detail::Tracer;

SiteFrameRenderer::SiteFrameRenderer(const CameraIntrinsics& k) : k_(k) {
  const int w = std::max(0, k.width_px), h = std::max(0, k.height_px);
  k_.width_px = w;
  k_.height_px = h;
  if (w == 0 || h == 0) return;
  CameraModel model;
  model.intrinsics = k_;
  const FloorProjector proj(model);
  rays_.resize(2 * static_cast<size_t>(w + 1) * static_cast<size_t>(h + 1));
  const float nan = std::numeric_limits<float>::quiet_NaN();
  for (int j = 0; j <= h; ++j) {
    for (int i = 0; i <= w; ++i) {
      Vec2 xn;
      float* r = &rays_[2 * (static_cast<size_t>(j) * static_cast<size_t>(w + 1) +
                             static_cast<size_t>(i))];
      if (proj.undistort({i - 0.5, j - 0.5}, &xn)) {
        r[0] = static_cast<float>(xn.x);
        r[1] = static_cast<float>(xn.y);
      } else {
        r[0] = r[1] = nan;
      }
    }
  }
  tiles_x_ = (w + kTile - 1) / kTile;
  tiles_y_ = (h + kTile - 1) / kTile;
  tile_box_.resize(static_cast<size_t>(tiles_x_ * tiles_y_));
  for (int ty = 0; ty < tiles_y_; ++ty) {
    for (int tx = 0; tx < tiles_x_; ++tx) {
      std::array<float, 4> b{std::numeric_limits<float>::max(), std::numeric_limits<float>::max(),
                             -std::numeric_limits<float>::max(),
                             -std::numeric_limits<float>::max()};
      for (int j = ty * kTile; j <= std::min(h, (ty + 1) * kTile); ++j) {
        for (int i = tx * kTile; i <= std::min(w, (tx + 1) * kTile); ++i) {
          const float* r = corner_xy(i, j);
          if (!std::isfinite(r[0]) || !std::isfinite(r[1])) continue;
          b[0] = std::min(b[0], r[0]);
          b[1] = std::min(b[1], r[1]);
          b[2] = std::max(b[2], r[0]);
          b[3] = std::max(b[3], r[1]);
        }
      }
      tile_box_[static_cast<size_t>(ty * tiles_x_ + tx)] = b;
    }
  }
}

namespace site_render_detail {

int Tracer::trace(double x, double y, const int* cand, int n, double* grey) const {
  // Keys: 0 nothing, 4 floor, 4 * (face + 2) + print class for a face.
  double best_t = std::numeric_limits<double>::infinity();
  int best = -2;
  const double dz = r[6] * x + r[7] * y + r[8];
  if (dz < 0.0 && t.z > 0.0) {
    best_t = -t.z / dz;
    best = -1;
  }
  double bu = 0.0, bv = 0.0, bdn = 0.0;
  const auto xf = static_cast<float>(x), yf = static_cast<float>(y);
  for (int k = 0; k < n; ++k) {
    const int fi = cand[k];
    const CamFace& cf = (*cam)[static_cast<size_t>(fi)];
    if (!cf.visible || xf < cf.box[0] || xf > cf.box[2] || yf < cf.box[1] || yf > cf.box[3]) {
      continue;
    }
    const double dn = cf.nd.x * x + cf.nd.y * y + cf.nd.z;
    if (dn == 0.0) continue;
    const double tt = cf.c / dn;
    if (!(tt > 1e-6 && tt < best_t)) continue;
    const double u = cf.ou + tt * (cf.ud.x * x + cf.ud.y * y + cf.ud.z);
    const double v = cf.ov + tt * (cf.vd.x * x + cf.vd.y * y + cf.vd.z);
    const Face& f = (*faces)[static_cast<size_t>(fi)];
    if (u < f.lo.x || u > f.hi.x || v < f.lo.y || v > f.hi.y || !poly_contains(f.poly, u, v)) {
      continue;
    }
    best = fi;
    best_t = tt;
    bu = u;
    bv = v;
    bdn = dn;
  }
  if (best == -2) {
    *grey = scene->background_grey;
    return 0;
  }
  if (best == -1) {
    const double dx = r[0] * x + r[1] * y + r[2], dy = r[3] * x + r[4] * y + r[5];
    *grey = floor_texture(scene->floor, {t.x + best_t * dx, t.y + best_t * dy});
    return 4;
  }
  const Face& f = (*faces)[static_cast<size_t>(best)];
  const int key = 4 * (best + 2);
  // The print is on the side the normal points away from: seen from behind, a plain face.
  if (f.material != Material::kPage || !(bdn > 0.0) || std::abs(bu) > f.page_reach_mm ||
      std::abs(bv) > f.page_reach_mm) {
    *grey = f.grey;
    return key;
  }
  const PageInk ink = f.page->at({bu, bv});
  if (ink == PageInk::kOutside) {
    *grey = f.grey;
    return key;
  }
  const bool black = ink == PageInk::kBlack;
  *grey = (black ? scene->ink_black : scene->paper_white) * f.shade;
  return key + (black ? 2 : 1);
}

}  // namespace site_render_detail

namespace {

bool same_intrinsics(const CameraIntrinsics& a, const CameraIntrinsics& b) {
  return a.width_px == b.width_px && a.height_px == b.height_px && a.fx == b.fx && a.fy == b.fy &&
         a.cx == b.cx && a.cy == b.cy && a.k1 == b.k1 && a.k2 == b.k2 && a.p1 == b.p1 &&
         a.p2 == b.p2 && a.k3 == b.k3;
}

// Bilinear ray inside pixel (x, y) at fractional position (a, b) from its four corner rays.
inline void pixel_ray(const SiteFrameRenderer& r, int x, int y, double a, double b, double* rx,
                      double* ry) {
  const float* c00 = r.corner_xy(x, y);
  const float* c10 = r.corner_xy(x + 1, y);
  const float* c01 = r.corner_xy(x, y + 1);
  const float* c11 = r.corner_xy(x + 1, y + 1);
  const double w00 = (1 - a) * (1 - b), w10 = a * (1 - b), w01 = (1 - a) * b, w11 = a * b;
  auto d = [](float f) { return static_cast<double>(f); };
  *rx = w00 * d(c00[0]) + w10 * d(c10[0]) + w01 * d(c01[0]) + w11 * d(c11[0]);
  *ry = w00 * d(c00[1]) + w10 * d(c10[1]) + w01 * d(c01[1]) + w11 * d(c11[1]);
}

// One set of faces (the frame time or one sub-frame instant) with its camera form and tracer.
struct Instant {
  std::vector<Face> faces;
  std::vector<CamFace> cam;
  Tracer tracer;
  void prepare(const SiteScene& scene, const RenderCamera& c) {
    cam.clear();
    for (const Face& f : faces) cam.push_back(site_render_detail::cam_face(f, c));
    tracer.scene = &scene;
    tracer.faces = &faces;
    tracer.cam = &cam;
    tracer.r = c.r_site_cam;
    tracer.t = {c.t_site_cam_mm[0], c.t_site_cam_mm[1], c.t_site_cam_mm[2]};
  }
};

// Faces per tile: every face whose normalised box (over all instants) meets the tile's.
void bin_faces(const std::vector<std::array<float, 4>>& tile_box, const Instant& mid,
               const std::vector<Instant>& inst, std::vector<std::vector<int>>* tile_faces,
               std::vector<std::uint8_t>* tile_moving) {
  const size_t n_tiles = tile_box.size();
  tile_faces->assign(n_tiles, {});
  tile_moving->assign(n_tiles, 0);
  for (size_t fi = 0; fi < mid.faces.size(); ++fi) {
    float b[4] = {std::numeric_limits<float>::max(), std::numeric_limits<float>::max(),
                  -std::numeric_limits<float>::max(), -std::numeric_limits<float>::max()};
    auto grow = [&](const CamFace& cf) {
      if (!cf.visible) return;
      b[0] = std::min(b[0], cf.box[0]);
      b[1] = std::min(b[1], cf.box[1]);
      b[2] = std::max(b[2], cf.box[2]);
      b[3] = std::max(b[3], cf.box[3]);
    };
    grow(mid.cam[fi]);
    const bool moving = mid.faces[fi].moving && !inst.empty();
    if (moving) {
      for (const Instant& in : inst) grow(in.cam[fi]);
    }
    if (b[0] > b[2]) continue;
    for (size_t ti = 0; ti < n_tiles; ++ti) {
      const std::array<float, 4>& tb = tile_box[ti];
      if (b[2] < tb[0] || b[0] > tb[2] || b[3] < tb[1] || b[1] > tb[3]) continue;
      (*tile_faces)[ti].push_back(static_cast<int>(fi));
      if (moving) (*tile_moving)[ti] = 1;
    }
  }
}

}  // namespace

RenderResult SiteFrameRenderer::render(const SiteScene& scene, const RenderCamera& cam,
                                       const SiteRenderParams& p, std::uint64_t seed) const {
  RenderResult res;
  const int w = k_.width_px, h = k_.height_px;
  if (!same_intrinsics(cam.intrinsics, k_) || scene.agvs.size() != scene.site.fleet.size() ||
      w == 0 || h == 0) {
    return res;
  }
  const site_render_detail::Pages pages = site_render_detail::make_pages(scene);
  bool any_moving = false;
  for (const AgvState& s : scene.agvs) any_moving |= s.v_mps != 0.0 || s.omega_radps != 0.0;
  const int n_inst = p.exposure_s > 0.0 && any_moving ? std::clamp(p.blur_instants, 2, 64) : 0;
  Instant mid;
  FaceIndex index, unused;
  site_render_detail::build_faces(scene, pages, 0.0, &mid.faces, &index);
  mid.prepare(scene, cam);
  std::vector<Instant> inst(static_cast<size_t>(n_inst));
  for (int k = 0; k < n_inst; ++k) {
    const double dt = ((k + 0.5) / n_inst - 0.5) * p.exposure_s;
    site_render_detail::build_faces(scene, pages, dt, &inst[static_cast<size_t>(k)].faces, &unused);
    inst[static_cast<size_t>(k)].prepare(scene, cam);
  }

  std::vector<std::vector<int>> tile_faces;
  std::vector<std::uint8_t> tile_moving;
  bin_faces(tile_box_, mid, inst, &tile_faces, &tile_moving);

  cv::Mat radiance(h, w, CV_32FC1);
  std::vector<int> keys(static_cast<size_t>(w) * static_cast<size_t>(h), -1);
  auto key_at = [&](int x, int y) -> int& {
    return keys[static_cast<size_t>(y) * static_cast<size_t>(w) + static_cast<size_t>(x)];
  };
  // Pass 1: one sample at every pixel centre.
  for (int ty = 0; ty < tiles_y_; ++ty) {
    for (int tx = 0; tx < tiles_x_; ++tx) {
      const std::vector<int>& cand = tile_faces[static_cast<size_t>(ty * tiles_x_ + tx)];
      for (int y = ty * kTile; y < std::min(h, (ty + 1) * kTile); ++y) {
        float* row = radiance.ptr<float>(y);
        for (int x = tx * kTile; x < std::min(w, (tx + 1) * kTile); ++x) {
          double rx, ry, g = 0.0;
          pixel_ray(*this, x, y, 0.5, 0.5, &rx, &ry);
          if (!std::isfinite(rx) || !std::isfinite(ry)) {
            row[x] = 0.0f;  // outside the lens model's valid field
            continue;
          }
          key_at(x, y) = mid.tracer.trace(rx, ry, cand.data(), static_cast<int>(cand.size()), &g);
          row[x] = static_cast<float>(g);
        }
      }
    }
  }
  // Pass 2: sub-samples where a neighbour differs, sub-frame instants where a vehicle moves.
  const int n_sub = std::max(1, p.edge_supersample);
  for (int ty = 0; ty < tiles_y_; ++ty) {
    for (int tx = 0; tx < tiles_x_; ++tx) {
      const size_t ti = static_cast<size_t>(ty * tiles_x_ + tx);
      const int* cand = tile_faces[ti].data();
      const int nc = static_cast<int>(tile_faces[ti].size());
      for (int y = ty * kTile; y < std::min(h, (ty + 1) * kTile); ++y) {
        float* row = radiance.ptr<float>(y);
        for (int x = tx * kTile; x < std::min(w, (tx + 1) * kTile); ++x) {
          const int key = key_at(x, y);
          if (key < 0) continue;
          bool blur = false;
          double g = 0.0, rx, ry;
          if (tile_moving[ti]) {
            pixel_ray(*this, x, y, 0.5, 0.5, &rx, &ry);
            blur = inst.front().tracer.trace(rx, ry, cand, nc, &g) != key ||
                   inst.back().tracer.trace(rx, ry, cand, nc, &g) != key;
          }
          bool edge = false;
          if (!blur && n_sub > 1) {
            const int nb[4][2] = {{x - 1, y}, {x + 1, y}, {x, y - 1}, {x, y + 1}};
            for (const auto& q : nb) {
              if (q[0] < 0 || q[1] < 0 || q[0] >= w || q[1] >= h) continue;
              const int k2 = key_at(q[0], q[1]);
              if (k2 >= 0 && k2 != key) edge = true;
            }
          }
          if (!blur && !edge) continue;
          const int grid = n_sub * n_sub;
          const int n_samples = blur ? std::max(n_inst, grid) : grid;
          double sum = 0.0;
          for (int s = 0; s < n_samples; ++s) {
            const int q = s % grid;
            pixel_ray(*this, x, y, (q % n_sub + 0.5) / n_sub, (q / n_sub + 0.5) / n_sub, &rx, &ry);
            const Tracer& tr = blur ? inst[static_cast<size_t>(s % n_inst)].tracer : mid.tracer;
            tr.trace(rx, ry, cand, nc, &g);
            sum += g;
          }
          row[x] = static_cast<float>(sum / n_samples);
        }
      }
    }
  }
  res.image = site_render_detail::finish_image(radiance, p, seed);
  site_render_detail::fill_truth(scene, cam, p, mid.faces, mid.cam, index, &res);
  return res;
}

RenderResult render_site_frame(const SiteScene& scene, const RenderCamera& cam,
                               const SiteRenderParams& params, std::uint64_t seed) {
  return SiteFrameRenderer(cam.intrinsics).render(scene, cam, params, seed);
}

}  // namespace agv::sim
