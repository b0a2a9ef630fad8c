// Internals of the site renderer shared by its sources (site_render_*.cpp): the scene as planar
// faces, and the per-frame camera-relative form of each face that the tracer uses.
#pragma once

#include <array>
#include <cmath>
#include <cstdint>
#include <deque>
#include <vector>

#include "agv/sim/site_render.hpp"

namespace agv::sim::site_render_detail {

inline Vec3 add3(Vec3 a, Vec3 b) { return {a.x + b.x, a.y + b.y, a.z + b.z}; }
inline Vec3 sub3(Vec3 a, Vec3 b) { return {a.x - b.x, a.y - b.y, a.z - b.z}; }
inline Vec3 mul3(Vec3 a, double s) { return {a.x * s, a.y * s, a.z * s}; }
inline double dot3(Vec3 a, Vec3 b) { return a.x * b.x + a.y * b.y + a.z * b.z; }
inline Vec3 cross3(Vec3 a, Vec3 b) {
  return {a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x};
}
// R * v and R^T * v for a row-major 3x3.
inline Vec3 rot3(const std::array<double, 9>& r, Vec3 v) {
  return {r[0] * v.x + r[1] * v.y + r[2] * v.z, r[3] * v.x + r[4] * v.y + r[5] * v.z,
          r[6] * v.x + r[7] * v.y + r[8] * v.z};
}
inline Vec3 rot3t(const std::array<double, 9>& r, Vec3 v) {
  return {r[0] * v.x + r[3] * v.y + r[6] * v.z, r[1] * v.x + r[4] * v.y + r[7] * v.z,
          r[2] * v.x + r[5] * v.y + r[8] * v.z};
}

// Crossing-number test: any simple polygon (obstacle outlines need not be convex).
inline bool poly_contains(const std::vector<Vec2>& poly, double u, double v) {
  bool in = false;
  const size_t n = poly.size();
  for (size_t i = 0, j = n - 1; i < n; j = i++) {
    const Vec2 a = poly[i], b = poly[j];
    if ((a.y > v) != (b.y > v) && u < (b.x - a.x) * (v - a.y) / (b.y - a.y) + a.x) in = !in;
  }
  return in;
}

enum class Material : std::uint8_t { kFlat, kPage };

// A planar polygon: point o + u * eu + v * ev for (u, v) inside poly; n = eu x ev.
// Page faces carry a printed page whose (u, v) are the face's (u, v) (page centre at o); they are
// printed on the side that n points away from (a ray with d . n > 0 sees the print).
struct Face {
  Vec3 o, eu, ev, n;
  std::vector<Vec2> poly;
  Vec2 lo{}, hi{};  // poly's bounding box
  Material material = Material::kFlat;
  double grey = 128.0;  // flat colour after shading; page faces: the colour outside the page
  double shade = 1.0;   // page faces: multiplies paper and ink
  const LandmarkPattern* page = nullptr;
  double page_reach_mm = 0.0;
  bool moving = false;
};

// Where the truth finds an object's faces in a face list.
struct FaceIndex {
  std::vector<int> agv_tag_face;  // per vehicle
  std::vector<int> wall_face;     // per wall landmark
  std::vector<int> parcel_top_face;
  std::vector<int> clutter_top_face;
};

// Landmark pages of one render (faces point into it; a deque keeps the addresses stable).
struct Pages {
  std::vector<const LandmarkPattern*> agv;   // per vehicle (null: no valid tag)
  std::vector<const LandmarkPattern*> wall;  // per wall landmark (null: not renderable)
  std::deque<LandmarkPattern> store;
};
Pages make_pages(const SiteScene& scene);

// Every face of the scene with the vehicles (and their parcels) dt_s after the frame time.
void build_faces(const SiteScene& scene, const Pages& pages, double dt_s, std::vector<Face>* out,
                 FaceIndex* index);
double face_shade(Vec3 n_out);

// A face in the camera frame of one frame: with the ray direction d = (x, y, 1) in the camera
// frame (x, y normalised), the hit is at t = c / (nd . d), u = ou + t * (ud . d), v likewise.
struct CamFace {
  Vec3 nd, ud, vd;
  double c = 0.0, ou = 0.0, ov = 0.0;
  float box[4] = {0, 0, 0, 0};  // normalised bounding box of the visible part (x0, y0, x1, y1)
  bool visible = false;
};
CamFace cam_face(const Face& f, const RenderCamera& cam);

// The nearest hit along normalised ray (x, y) among faces cand (floor included), as a key (equal
// keys: same surface and same print class) and a grey (8-bit, before illumination).
struct Tracer {
  const SiteScene* scene = nullptr;
  const std::vector<Face>* faces = nullptr;
  const std::vector<CamFace>* cam = nullptr;
  std::array<double, 9> r{};
  Vec3 t{};
  int trace(double x, double y, const int* cand, int n, double* grey) const;
};

// Ground truth of one frame (site_render_truth.cpp).
void fill_truth(const SiteScene& scene, const RenderCamera& cam, const SiteRenderParams& p,
                const std::vector<Face>& faces, const std::vector<CamFace>& cam_faces,
                const FaceIndex& index, RenderResult* out);
// Illumination, defocus and sensor noise on a float image; returns the 8-bit image.
cv::Mat finish_image(const cv::Mat& radiance, const SiteRenderParams& p, std::uint64_t seed);

}  // namespace agv::sim::site_render_detail
