// Floor scenes and camera frames: floor texture, landmark placement, degradations and the
// frame renderer (docs/design/simulator.md). Printable landmarks are in landmark_page.cpp.
#include "agv/sim/render.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <opencv2/imgproc.hpp>

#include "render_effects.hpp"

namespace agv::sim {

namespace {

std::uint64_t splitmix64(std::uint64_t x) {
  x += 0x9e3779b97f4a7c15ULL;
  x = (x ^ (x >> 30)) * 0xbf58476d1ce4e5b9ULL;
  x = (x ^ (x >> 27)) * 0x94d049bb133111ebULL;
  return x ^ (x >> 31);
}

// One mixing round per lattice point: texture needs decorrelation, not cryptography, and this is
// the renderer's innermost loop. `salt` is pre-mixed by the caller.
double hash01(std::int64_t ix, std::int64_t iy, std::uint64_t salt) {
  const std::uint64_t h = splitmix64(static_cast<std::uint64_t>(ix) * 0x9E3779B97F4A7C15ULL +
                                     static_cast<std::uint64_t>(iy) * 0xC2B2AE3D27D4EB4FULL + salt);
  return static_cast<double>(h >> 11) * (1.0 / 9007199254740992.0);
}

double value_noise(double x, double y, std::uint64_t salt) {
  const double fx = std::floor(x), fy = std::floor(y);
  const auto ix = static_cast<std::int64_t>(fx), iy = static_cast<std::int64_t>(fy);
  double tx = x - fx, ty = y - fy;
  tx = tx * tx * (3.0 - 2.0 * tx);
  ty = ty * ty * (3.0 - 2.0 * ty);
  const double a = hash01(ix, iy, salt), b = hash01(ix + 1, iy, salt);
  const double c = hash01(ix, iy + 1, salt), d = hash01(ix + 1, iy + 1, salt);
  return (a + (b - a) * tx) + ((c + (d - c) * tx) - (a + (b - a) * tx)) * ty;
}

}  // namespace

double floor_texture(const FloorTexture& t, Vec2 p) {
  if (t.amplitude == 0.0) return t.mean;
  // Octaves of value noise (wavelength mm, weight): large stains, aggregate, fine grain.
  static constexpr double kWave[4] = {90.0, 22.0, 5.0, 1.3};
  static constexpr double kWeight[4] = {0.30, 0.30, 0.25, 0.15};
  double s = 0.0;
  for (int o = 0; o < 4; ++o) {
    const std::uint64_t salt = splitmix64(t.seed * 31 + static_cast<std::uint64_t>(o));
    s += kWeight[o] * (value_noise(p.x / kWave[o], p.y / kWave[o], salt) - 0.5);
  }
  return t.mean + 2.0 * t.amplitude * s;
}

LandmarkMap default_landmark_grid(int columns, int rows, double spacing_mm) {
  LandmarkMap m;
  std::uint32_t id = 1;
  static constexpr double kHeadings_deg[4] = {0.0, 90.0, 180.0, -90.0};
  for (int r = 0; r < rows; ++r) {
    for (int c = 0; c < columns; ++c, ++id) {
      m.entries[id] = {id,
                       {c * spacing_mm, r * spacing_mm, deg_to_rad(kHeadings_deg[(id - 1) % 4])}};
    }
  }
  return m;
}

bool make_scene(const LandmarkMap& map, const LandmarkGeometry& geometry, PayloadMode mode,
                Scene* out, std::string* error) {
  Scene s;
  s.geometry = geometry;
  for (const auto& [id, e] : map.entries) {
    std::string payload;
    if (mode == PayloadMode::kFull) {
      payload = full_payload(e);
    } else {
      LandmarkPayload p;
      p.id = id;
      p.has_pose = false;
      payload = format_payload(p);
    }
    if (payload.empty()) {
      if (error) *error = "landmark " + std::to_string(id) + ": pose cannot be put in a payload";
      return false;
    }
    SceneLandmark l;
    l.id = id;
    l.world_pose = e.pose;
    if (!LandmarkPattern::make(geometry, payload, &l.pattern, error)) return false;
    s.landmarks.push_back(std::move(l));
  }
  *out = std::move(s);
  return true;
}

bool misprint_landmark(Scene* scene, std::uint32_t id, Vec2 offset_mm, std::string* error) {
  for (SceneLandmark& l : scene->landmarks) {
    if (l.id != id) continue;
    LandmarkMapEntry claimed{id, l.world_pose};
    claimed.pose.x_mm += offset_mm.x;
    claimed.pose.y_mm += offset_mm.y;
    const std::string payload = full_payload(claimed);
    if (payload.empty()) {
      if (error) *error = "landmark " + std::to_string(id) + ": misprinted pose out of range";
      return false;
    }
    return LandmarkPattern::make(scene->geometry, payload, &l.pattern, error);
  }
  if (error) *error = "landmark " + std::to_string(id) + " is not in the map";
  return false;
}

RenderOptions realistic_options() {
  return {.defocus_sigma_px = 0.8,
          .exposure_s = 0.002,
          .illumination_ratio = 0.7,
          .illumination_direction_deg = 30.0,
          .read_noise_sigma = 2.0,
          .shot_noise_gain = 0.05};
}

// ---------------------------------------------------------------------------------------------

namespace {

// Degradations of one landmark in page coordinates, generated from the seed and the id.
struct Scratch {
  Vec2 a, b;          // segment on the page (mm)
  double half_width;  // mm
};
struct Spot {
  Vec2 c;
  double radius;    // mm
  double darkness;  // 0..1 multiplier reduction at the centre
};
// An opaque patch over part of the QR code (page rectangle [u0, u1) x [v0, v1)).
struct QrCover {
  bool on = false;
  double u0 = 0, v0 = 0, u1 = 0, v1 = 0;
  double grey = 0;
};
// Ink rubbed off along one border edge: side k (0..3 as perimeter order below), outer or inner
// edge, along-edge interval [t0, t1] (mm), depth into the ink (mm).
struct Scuff {
  int side = 0;
  bool inner = false;
  double t0 = 0, t1 = 0, depth = 0;
};
struct LandmarkDegradation {
  std::vector<Scratch> scratches;
  std::vector<Spot> spots;
  QrCover cover;
  std::vector<Scuff> scuffs;
  bool occluded = false;  // under the occluder of occluder_border_fraction
  // Ink grey = ink_black + ink_lift * (paper - ink) * (1 + ramp . uv / outer_half) / 2.
  double ink_lift = 0.0, paper_factor = 1.0;
  Vec2 ramp{0, 0};
};

bool is_worn(const RenderOptions& o, std::uint32_t id) {
  return o.worn_ids.empty() ||
         std::find(o.worn_ids.begin(), o.worn_ids.end(), id) != o.worn_ids.end();
}

// Scuffs and ink variation, from their own stream.
void add_print_wear(const RenderOptions& o, const LandmarkGeometry& g, std::uint32_t id,
                    LandmarkDegradation* d) {
  std::mt19937_64 r(
      splitmix64(o.degradation_seed ^ 0x5c0f'f5a1ULL ^ (static_cast<std::uint64_t>(id) << 28)));
  std::uniform_real_distribution<double> u01(0.0, 1.0);
  std::uniform_int_distribution<int> side(0, 3);
  const double h = g.inner_half_mm();
  for (int i = 0; i < o.edge_scuffs_per_landmark; ++i) {
    Scuff s;
    s.side = side(r);
    s.inner = u01(r) < 0.5;
    const double len = g.k() * (1.5 + 4.5 * u01(r));
    s.t0 = -h + (2.0 * h - len) * u01(r);
    s.t1 = s.t0 + len;
    s.depth = g.k() * (0.05 + 0.25 * u01(r));
    d->scuffs.push_back(s);
  }
  const double f = std::clamp(o.ink_variation, 0.0, 1.0);
  if (f > 0.0) {
    d->ink_lift = f * u01(r);
    d->paper_factor = 1.0 - 0.5 * f * u01(r);
    const double a = 2.0 * kPi * u01(r);
    d->ramp = {std::cos(a), std::sin(a)};
  }
}

// Page point inside a scuff: within its depth of the edge, on the ink side.
bool in_scuff(const Scuff& s, const LandmarkGeometry& g, Vec2 uv) {
  // Side k: across coordinate (outward positive) and along coordinate on the page.
  const double across = s.side == 0 ? -uv.x : s.side == 1 ? uv.y : s.side == 2 ? uv.x : -uv.y;
  const double along = s.side == 0 || s.side == 2 ? uv.y : uv.x;
  if (along < s.t0 || along > s.t1) return false;
  if (s.inner) return across >= g.inner_half_mm() && across < g.inner_half_mm() + s.depth;
  return across <= g.outer_half_mm() && across > g.outer_half_mm() - s.depth;
}

// Its own random stream, so the scratches and dirt of existing seeds stay where they were.
// Shape: a square at one of the four corners, a strip along one of the four edges, or a square in
// the middle (shifted by up to a module); colour: the floor, the ink or the paper.
QrCover make_qr_cover(const RenderOptions& o, const Scene& scene, std::uint32_t id) {
  QrCover c;
  const double f = std::clamp(o.qr_cover_fraction, 0.0, 1.0 / 3.0);
  if (!(f > 0.0)) return c;
  const LandmarkGeometry& g = scene.geometry;
  std::mt19937_64 r(
      splitmix64(o.degradation_seed ^ 0x51c0'7e12ULL ^ (static_cast<std::uint64_t>(id) << 24)));
  std::uniform_int_distribution<int> pick(0, 3), colour(0, 2);
  const double s = g.qr_side_mm(), u = g.qr_u0_mm(), v = g.qr_v0_mm();
  const int shape = pick(r) % 3, where = pick(r);
  if (shape == 0) {
    const double a = std::sqrt(f) * s;
    c.u0 = where & 1 ? u + s - a : u;
    c.v0 = where & 2 ? v + s - a : v;
    c.u1 = c.u0 + a;
    c.v1 = c.v0 + a;
  } else if (shape == 1) {
    const double d = f * s;
    c.u0 = where == 1 ? u + s - d : u;
    c.v0 = where == 3 ? v + s - d : v;
    c.u1 = where == 0 ? u + d : u + s;
    c.v1 = where == 2 ? v + d : v + s;
  } else {
    const double a = std::sqrt(f) * s;
    std::uniform_real_distribution<double> shift(-s / 25.0, s / 25.0);
    c.u0 = u + 0.5 * (s - a) + shift(r);
    c.v0 = v + 0.5 * (s - a) + shift(r);
    c.u1 = c.u0 + a;
    c.v1 = c.v0 + a;
  }
  const int k = colour(r);
  c.grey = k == 0 ? scene.floor.mean : k == 1 ? scene.ink_black : scene.paper_white;
  c.on = true;
  return c;
}

LandmarkDegradation make_degradation(const RenderOptions& o, const LandmarkGeometry& g,
                                     std::uint32_t id) {
  LandmarkDegradation d;
  std::mt19937_64 r(splitmix64(o.degradation_seed ^ (static_cast<std::uint64_t>(id) << 20)));
  std::uniform_real_distribution<double> pos(-g.outer_half_mm(), g.outer_half_mm());
  for (int i = 0; i < o.scratches_per_landmark; ++i) {
    d.scratches.push_back({{pos(r), pos(r)}, {pos(r), pos(r)}, 0.15 * g.k()});
  }
  if (o.dirt_spots_per_landmark > 0.0) {
    std::poisson_distribution<int> count(o.dirt_spots_per_landmark);
    std::uniform_real_distribution<double> rad(0.8 * g.k(), 3.0 * g.k()), dark(0.3, 0.7);
    const int n = count(r);
    for (int i = 0; i < n; ++i) d.spots.push_back({{pos(r), pos(r)}, rad(r), dark(r)});
  }
  return d;
}

double seg_dist(Vec2 p, Vec2 a, Vec2 b) {
  const double dx = b.x - a.x, dy = b.y - a.y;
  const double l2 = dx * dx + dy * dy;
  double t = l2 > 0 ? ((p.x - a.x) * dx + (p.y - a.y) * dy) / l2 : 0.0;
  t = std::clamp(t, 0.0, 1.0);
  return std::hypot(p.x - a.x - t * dx, p.y - a.y - t * dy);
}

// Everything about one visible landmark that a pixel evaluation needs.
struct ActiveLandmark {
  const SceneLandmark* lm;
  Pose2 landmark_from_vehicle;
  LandmarkDegradation deg;
  double reach_mm;  // page half-extent that can differ from the bare floor
};

struct Sample {
  int key;       // discrete class: equal keys at all probe points => pixel needs no supersampling
  double value;  // reflectance grey (8-bit units at full illumination); <0 = bare floor
};

class Evaluator {
 public:
  Evaluator(const Scene& scene, const RenderOptions& o) : scene_(scene), o_(o) {
    const LandmarkGeometry& g = scene.geometry;
    occ_band_lo_ = g.inner_half_mm();
    occ_band_hi_ =
        g.outer_half_mm() + (o.occluder_overhang_mm >= 0.0 ? o.occluder_overhang_mm : 3.0 * g.k());
    // Border midline square: perimeter parameter runs over 8 * mid half-sides.
    mid_half_ = 0.5 * (g.inner_half_mm() + g.outer_half_mm());
    occ_len_ = std::clamp(o.occluder_border_fraction, 0.0, 1.0) * 8.0 * mid_half_;
  }

  double reach(const LandmarkGeometry& g) const {
    return occ_len_ > 0.0 ? occ_band_hi_ : g.outer_half_mm();
  }

  // Perimeter parameter of a page point projected on the border's midline square, starting at
  // the front-left (top-left on the page) corner and going down the left edge.
  double perimeter_param(Vec2 uv) const {
    const double h = mid_half_;
    const double au = std::abs(uv.x), av = std::abs(uv.y);
    if (au >= av) {
      if (uv.x < 0) return std::clamp(uv.y + h, 0.0, 2 * h);  // left edge, down
      return 4 * h + std::clamp(h - uv.y, 0.0, 2 * h);        // right edge, up
    }
    if (uv.y > 0) return 2 * h + std::clamp(uv.x + h, 0.0, 2 * h);  // bottom edge, right
    return 6 * h + std::clamp(h - uv.x, 0.0, 2 * h);                // top edge, left
  }

  Sample eval(const ActiveLandmark& a, Vec2 uv) const {
    const double m = std::max(std::abs(uv.x), std::abs(uv.y));
    if (occ_len_ > 0.0 && a.deg.occluded && m >= occ_band_lo_ && m < occ_band_hi_ &&
        perimeter_param(uv) < occ_len_) {
      return {8, o_.occluder_grey};
    }
    const QrCover& qc = a.deg.cover;
    if (qc.on && uv.x >= qc.u0 && uv.x < qc.u1 && uv.y >= qc.v0 && uv.y < qc.v1) {
      return {32, qc.grey};
    }
    const PageInk ink = a.lm->pattern.at(uv);
    if (ink == PageInk::kOutside) return {0, -1.0};
    int key = static_cast<int>(ink);
    double v = ink == PageInk::kBlack ? scene_.ink_black : scene_.paper_white;
    if (ink == PageInk::kBlack) {
      for (const Scuff& sc : a.deg.scuffs) {
        if (in_scuff(sc, scene_.geometry, uv)) {
          key = 24;
          v = scene_.paper_white;
          break;
        }
      }
    }
    if (a.deg.ink_lift > 0.0) {
      if (v == scene_.ink_black) {
        const double t = 0.5 * (1.0 + (a.deg.ramp.x * uv.x + a.deg.ramp.y * uv.y) /
                                          scene_.geometry.outer_half_mm());
        v += a.deg.ink_lift * (scene_.paper_white - scene_.ink_black) * std::clamp(t, 0.0, 1.0);
      } else {
        v *= a.deg.paper_factor;
      }
    }
    for (const Scratch& s : a.deg.scratches) {
      if (seg_dist(uv, s.a, s.b) < s.half_width) {
        key = 16;
        v = std::max(v, 0.9 * scene_.paper_white);
        break;
      }
    }
    for (const Spot& sp : a.deg.spots) {
      const double r = std::hypot(uv.x - sp.c.x, uv.y - sp.c.y) / sp.radius;
      if (r < 1.0) v *= 1.0 - sp.darkness * (1.0 - r * r);  // soft smudge, no hard edge
    }
    return {key, v};
  }

 private:
  const Scene& scene_;
  const RenderOptions& o_;
  double occ_band_lo_ = 0, occ_band_hi_ = 0, mid_half_ = 0, occ_len_ = 0;
};

}  // namespace

FrameRenderer::FrameRenderer(const Scene& scene, const CameraModel& camera)
    : scene_(&scene), camera_(camera) {
  w_ = std::max(0, camera.intrinsics.width_px);
  h_ = std::max(0, camera.intrinsics.height_px);
  corner_v_.resize(static_cast<size_t>((w_ + 1) * (h_ + 1)));
  corner_ok_.resize(corner_v_.size());
  centre_v_.resize(static_cast<size_t>(w_ * h_));
  centre_ok_.resize(centre_v_.size());
  bbox_min_ = {1e300, 1e300};
  bbox_max_ = {-1e300, -1e300};
  for (int y = 0; y <= h_; ++y) {
    for (int x = 0; x <= w_; ++x) {
      const size_t i = static_cast<size_t>(y * (w_ + 1) + x);
      Vec2 p;
      corner_ok_[i] = camera_.pixel_to_vehicle({x - 0.5, y - 0.5}, &p) ? 1 : 0;
      corner_v_[i] = p;
      if (corner_ok_[i]) {
        bbox_min_ = {std::min(bbox_min_.x, p.x), std::min(bbox_min_.y, p.y)};
        bbox_max_ = {std::max(bbox_max_.x, p.x), std::max(bbox_max_.y, p.y)};
      }
    }
  }
  for (int y = 0; y < h_; ++y) {
    for (int x = 0; x < w_; ++x) {
      const size_t i = static_cast<size_t>(y * w_ + x);
      Vec2 p;
      centre_ok_[i] =
          camera_.pixel_to_vehicle({static_cast<double>(x), static_cast<double>(y)}, &p) ? 1 : 0;
      centre_v_[i] = p;
    }
  }
}

std::vector<std::uint32_t> FrameRenderer::visible_landmarks(const Pose2& pose) const {
  std::vector<std::uint32_t> ids;
  const Pose2 v_from_w = inverse(pose);
  for (const SceneLandmark& l : scene_->landmarks) {
    const Pose2 v_from_l = compose(v_from_w, l.world_pose);
    std::vector<Vec2> pts = scene_->geometry.outer_corners_landmark_mm();
    pts.push_back({0.0, 0.0});
    for (const Vec2& q : pts) {
      Vec2 px;
      if (camera_.vehicle_to_pixel(transform(v_from_l, q), &px) && px.x >= -0.5 && px.y >= -0.5 &&
          px.x < w_ - 0.5 && px.y < h_ - 0.5) {
        ids.push_back(l.id);
        break;
      }
    }
  }
  return ids;
}

namespace {

// Landmarks that can touch the image: centre within the footprint box grown by their reach.
std::vector<ActiveLandmark> active_landmarks(const Scene& scene, const RenderOptions& o,
                                             const Pose2& v_from_w, double reach, Vec2 bbox_min,
                                             Vec2 bbox_max) {
  std::vector<ActiveLandmark> active;
  for (const SceneLandmark& l : scene.landmarks) {
    const Pose2 v_from_l = compose(v_from_w, l.world_pose);
    // Tags print a white margin beyond their black square.
    const double reach_l = std::max(reach, l.pattern.reach_mm());
    const double r = reach_l * std::sqrt(2.0) + 1.0;
    if (v_from_l.x_mm < bbox_min.x - r || v_from_l.x_mm > bbox_max.x + r ||
        v_from_l.y_mm < bbox_min.y - r || v_from_l.y_mm > bbox_max.y + r) {
      continue;
    }
    if (is_worn(o, l.id)) {
      active.push_back({&l, inverse(v_from_l), make_degradation(o, scene.geometry, l.id), reach_l});
      active.back().deg.cover = make_qr_cover(o, scene, l.id);
      add_print_wear(o, scene.geometry, l.id, &active.back().deg);
      active.back().deg.occluded = true;
    } else {
      active.push_back({&l, inverse(v_from_l), LandmarkDegradation{}, reach_l});
    }
  }
  return active;
}

// Exact per-sub-sample back-projection of pixel (x, y), so edges and corners land exactly where
// the camera model puts them.
double supersampled_value(const FloorProjector& camera, const Evaluator& ev,
                          const ActiveLandmark& a, int x, int y, int n_sub, double floor_grey,
                          double centre_value) {
  double sum = 0.0;
  int cnt = 0;
  for (int j = 0; j < n_sub; ++j) {
    for (int i = 0; i < n_sub; ++i) {
      Vec2 pv;
      if (!camera.pixel_to_vehicle({x - 0.5 + (i + 0.5) / n_sub, y - 0.5 + (j + 0.5) / n_sub},
                                   &pv)) {
        continue;
      }
      const Sample s = ev.eval(a, landmark_to_page(transform(a.landmark_from_vehicle, pv)));
      sum += s.value < 0.0 ? floor_grey : s.value;
      ++cnt;
    }
  }
  return cnt > 0 ? sum / cnt : centre_value;
}

}  // namespace

cv::Mat FrameRenderer::render(const Pose2& pose, const RenderOptions& o,
                              std::mt19937_64& rng) const {
  cv::Mat img(h_, w_, CV_32FC1);
  if (w_ == 0 || h_ == 0) return cv::Mat(h_, w_, CV_8UC1);
  const Scene& scene = *scene_;
  const Evaluator ev(scene, o);
  const Pose2 v_from_w = inverse(pose);
  const std::vector<ActiveLandmark> active =
      active_landmarks(scene, o, v_from_w, ev.reach(scene.geometry), bbox_min_, bbox_max_);

  const int n_sub = std::max(1, o.supersample);
  for (int y = 0; y < h_; ++y) {
    float* row = img.ptr<float>(y);
    for (int x = 0; x < w_; ++x) {
      const size_t ic = static_cast<size_t>(y * w_ + x);
      if (!centre_ok_[ic]) {
        row[x] = 0.0f;  // outside the lens model's valid field
        continue;
      }
      const Vec2 pc = centre_v_[ic];
      const double floor_grey = floor_texture(scene.floor, transform(pose, pc));
      double value = floor_grey;
      for (const ActiveLandmark& a : active) {
        const Vec2 uvc = landmark_to_page(transform(a.landmark_from_vehicle, pc));
        // Pixels are < 2 mm wide for any sensible camera; skip landmarks clearly away.
        if (std::abs(uvc.x) > a.reach_mm + 3.0 || std::abs(uvc.y) > a.reach_mm + 3.0) continue;
        const Sample sc = ev.eval(a, uvc);
        bool uniform = true;
        const size_t i00 = static_cast<size_t>(y * (w_ + 1) + x);
        const size_t corners[4] = {i00, i00 + 1, i00 + static_cast<size_t>(w_ + 1),
                                   i00 + static_cast<size_t>(w_ + 2)};
        for (size_t ci : corners) {
          if (!corner_ok_[ci] ||
              ev.eval(a, landmark_to_page(transform(a.landmark_from_vehicle, corner_v_[ci]))).key !=
                  sc.key) {
            uniform = false;
            break;
          }
        }
        if (uniform || n_sub == 1) {
          value = sc.value < 0.0 ? floor_grey : sc.value;
        } else {
          value = supersampled_value(camera_, ev, a, x, y, n_sub, floor_grey, sc.value);
        }
        break;
      }
      row[x] = static_cast<float>(value);
    }
  }

  apply_illumination(o, &img);
  if (o.defocus_sigma_px > 0.0) {
    cv::GaussianBlur(img, img, cv::Size(0, 0), o.defocus_sigma_px, o.defocus_sigma_px,
                     cv::BORDER_REFLECT);
  }
  const size_t ic = static_cast<size_t>((h_ / 2) * w_ + w_ / 2);
  apply_motion_blur(o, camera_, centre_v_[ic], centre_ok_[ic] != 0, &img);
  return quantise_with_noise(img, o.read_noise_sigma, o.shot_noise_gain, rng);
}

cv::Mat render_frame(const Scene& scene, const CameraModel& camera, const Pose2& vehicle_pose_world,
                     const RenderOptions& options, std::mt19937_64& rng) {
  return FrameRenderer(scene, camera).render(vehicle_pose_world, options, rng);
}

}  // namespace agv::sim
