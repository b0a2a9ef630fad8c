// Search windows of a ceiling camera's frame from the tracker's predictions (Yang et al.
// Algorithm 1, lines 11-18: the track's box, then the area, then the whole image).
#include "agv/overhead/search.hpp"

#include <algorithm>
#include <cmath>
#include <optional>

#include "agv/overhead/tag_detect.hpp"
#include "agv/overhead/tag_fix.hpp"

namespace agv::overhead {

// Helpers in a namespace of their own: the library may be built as a unity batch.
namespace search_detail {
namespace {

// A vehicle's predicted tag in one camera's image.
struct TagPrediction {
  Vec2 centre_px{};
  std::array<Vec2, 4> corners_px{};  // page order
  // Half extents (u, v) in pixels of the position's n-sigma ellipse, and of the corners' swing
  // by n sigma of heading.
  double pos_u_px = 0.0, pos_v_px = 0.0, turn_u_px = 0.0, turn_v_px = 0.0;
};

// Projects the point and checks that its pixel maps back to it: far outside the calibrated field
// a lens polynomial folds back, and a point there would seem to be in the image.
bool project_checked(const site::CeilingCamera& cam, Vec2 xy_mm, double z_mm, Vec2* px) {
  Vec2 back;
  return site_to_pixel(cam, xy_mm.x, xy_mm.y, z_mm, px) && pixel_to_plane(cam, *px, z_mm, &back) &&
         std::hypot(back.x - xy_mm.x, back.y - xy_mm.y) <=
             1.0 + 1e-3 * std::hypot(xy_mm.x, xy_mm.y);
}

// The output's prediction of the vehicle's tag seen by cam; false when it is behind the camera
// or beyond the lens model. `sigmas` scales the uncertainty terms.
bool predict_tag(const site::CeilingCamera& cam, const site::FleetAgv& agv, const TrackOutput& o,
                 double sigmas, TagPrediction* out) {
  const double z = agv.tray_height_mm;
  const Vec2 c{o.pose.x_mm, o.pose.y_mm};
  const double h = std::isfinite(agv.tag_size_mm) ? 0.5 * std::max(0.0, agv.tag_size_mm) : 0.0;
  if (!project_checked(cam, c, z, &out->centre_px)) return false;
  // Pixels per millimetre on the plane at the prediction (the lens's local scale).
  constexpr double kStepMm = 10.0;
  Vec2 pu, pv;
  if (!site_to_pixel(cam, c.x + kStepMm, c.y, z, &pu) ||
      !site_to_pixel(cam, c.x, c.y + kStepMm, z, &pv)) {
    return false;
  }
  const double j[4] = {(pu.x - out->centre_px.x) / kStepMm, (pv.x - out->centre_px.x) / kStepMm,
                       (pu.y - out->centre_px.y) / kStepMm, (pv.y - out->centre_px.y) / kStepMm};
  const std::array<Vec2, 4> page = {Vec2{h, h}, Vec2{h, -h}, Vec2{-h, -h}, Vec2{-h, h}};
  for (std::size_t i = 0; i < 4; ++i) {
    const Vec2 p = transform(o.pose, page[i]);
    if (!site_to_pixel(cam, p.x, p.y, z, &out->corners_px[i])) return false;
  }
  // Position: J P J^T's diagonal. Heading: a corner at h*sqrt(2) from the centre moves by that
  // times the angle, in any direction on the plane.
  const double pxx = o.cov[0], pxy = 0.5 * (o.cov[1] + o.cov[3]), pyy = o.cov[4];
  const double var_u = j[0] * j[0] * pxx + 2.0 * j[0] * j[1] * pxy + j[1] * j[1] * pyy;
  const double var_v = j[2] * j[2] * pxx + 2.0 * j[2] * j[3] * pxy + j[3] * j[3] * pyy;
  out->pos_u_px = sigmas * std::sqrt(std::max(0.0, var_u));
  out->pos_v_px = sigmas * std::sqrt(std::max(0.0, var_v));
  const double swing_mm = sigmas * o.sigma_theta_rad * h * std::sqrt(2.0);
  out->turn_u_px = swing_mm * std::hypot(j[0], j[1]);
  out->turn_v_px = swing_mm * std::hypot(j[2], j[3]);
  return std::isfinite(out->pos_u_px + out->pos_v_px + out->turn_u_px + out->turn_v_px);
}

// Smallest integer rectangle holding [x0, x1] x [y0, y1] (pixel centres at integers), clipped
// to the image; empty when it misses it.
cv::Rect clipped_box(double x0, double y0, double x1, double y1, const cv::Rect& image) {
  // Far beyond the image the doubles would overflow int: clamp first.
  const auto clamp = [](double v, int lo, int hi) {
    return static_cast<int>(std::clamp(v, static_cast<double>(lo), static_cast<double>(hi)));
  };
  const int l = clamp(std::floor(x0), -1, image.width + 1);
  const int t = clamp(std::floor(y0), -1, image.height + 1);
  const int r = clamp(std::ceil(x1) + 1, -1, image.width + 1);
  const int b = clamp(std::ceil(y1) + 1, -1, image.height + 1);
  return cv::Rect(l, t, std::max(0, r - l), std::max(0, b - t)) & image;
}

// The kTrack window's rectangle: the corners' box widened by the uncertainty and the margin.
cv::Rect track_rect(const TagPrediction& p, double margin_px, const cv::Rect& image) {
  double x0 = p.corners_px[0].x, x1 = x0, y0 = p.corners_px[0].y, y1 = y0;
  for (const Vec2& q : p.corners_px) {
    x0 = std::min(x0, q.x);
    x1 = std::max(x1, q.x);
    y0 = std::min(y0, q.y);
    y1 = std::max(y1, q.y);
  }
  const double wu = p.pos_u_px + p.turn_u_px + margin_px;
  const double wv = p.pos_v_px + p.turn_v_px + margin_px;
  return clipped_box(x0 - wu, y0 - wv, x1 + wu, y1 + wv, image);
}

// Tile boundary i of n over a side of `size` pixels.
int tile_edge(int i, int n, int size) {
  return static_cast<int>(static_cast<long long>(i) * size / n);
}

// The tile holding the pixel (clamped into the grid: a prediction just off the image is searched
// in the border tiles) and the eight around it, clipped to the grid.
cv::Rect area_rect(Vec2 px, const SearchParams& sp, const cv::Rect& image) {
  const auto tile_of = [](double v, int n, int size) {
    const double f = std::floor(v * n / size);
    return static_cast<int>(std::clamp(f, 0.0, static_cast<double>(n - 1)));
  };
  const int c = tile_of(px.x, sp.area_cols, image.width);
  const int r = tile_of(px.y, sp.area_rows, image.height);
  const int c0 = std::max(0, c - 1), c1 = std::min(sp.area_cols, c + 2);
  const int r0 = std::max(0, r - 1), r1 = std::min(sp.area_rows, r + 2);
  const int x0 = tile_edge(c0, sp.area_cols, image.width);
  const int y0 = tile_edge(r0, sp.area_rows, image.height);
  return cv::Rect(x0, y0, tile_edge(c1, sp.area_cols, image.width) - x0,
                  tile_edge(r1, sp.area_rows, image.height) - y0);
}

bool has_track(TrackState s) {
  return s == TrackState::kTentative || s == TrackState::kConfirmed || s == TrackState::kCoasting;
}

// The shrink factor for a window whose smallest tag has this shortest side (SearchParams).
int decimation_for_side(double side_px, const SearchParams& sp) {
  return search_decimation(side_px, sp.decimated_side_px, sp.max_decimation);
}

// An area shared by several vehicles is shrunk for the smallest of their tags.
void add_area(std::size_t agv, const cv::Rect& rect, int decimation,
              std::vector<SearchWindow>* out) {
  for (SearchWindow& w : *out) {
    if (w.level == SearchLevel::kArea && w.rect == rect) {
      w.agvs.push_back(agv);
      w.decimation = std::min(w.decimation, decimation);
      return;
    }
  }
  SearchWindow w;
  w.level = SearchLevel::kArea;
  w.rect = rect;
  w.agvs.push_back(agv);
  w.decimation = decimation;
  out->push_back(std::move(w));
}

// Singular values of the 2 x 2 matrix [a b; c d].
void singular_values(double a, double b, double c, double d, double* lo, double* hi) {
  const double s1 = a * a + b * b + c * c + d * d;
  const double det = a * d - b * c;
  const double root = std::sqrt(std::max(0.0, s1 * s1 - 4.0 * det * det));
  *hi = std::sqrt(0.5 * (s1 + root));
  *lo = std::sqrt(std::max(0.0, 0.5 * (s1 - root)));
}

// Strip j of n of the image (rows), grown by overlap_px on both sides, clipped.
cv::Rect sweep_strip(const cv::Rect& image, int j, int n, double overlap_px) {
  const int grow = static_cast<int>(std::ceil(0.5 * overlap_px));
  const int y0 = std::max(0, tile_edge(j, n, image.height) - grow);
  const int y1 = std::min(image.height, tile_edge(j + 1, n, image.height) + grow);
  return cv::Rect(0, y0, image.width, std::max(0, y1 - y0));
}

// How many horizontal strips a search of this many pixels is cut into
// (SearchParams::sweep_max_pixels); 1: searched at once.
int strips_for(long long pixels, const SearchParams& sp) {
  if (sp.sweep_max_pixels <= 0 || pixels <= sp.sweep_max_pixels) return 1;
  return static_cast<int>(
      std::min<long long>(1 << 16, (pixels + sp.sweep_max_pixels - 1) / sp.sweep_max_pixels));
}

long long pixels_of(const cv::Rect& r, int decimation) {
  const long long d = std::max(1, decimation);
  return static_cast<long long>(r.width) * r.height / (d * d);
}

// How many strips the interval's sweep of the image takes: never more than the frames between
// sweeps, so each sweep ends before the next begins.
int sweep_strips(const cv::Rect& image, const SearchParams& sp) {
  return std::min(std::max(1, sp.full_sweep_every_frames), strips_for(pixels_of(image, 1), sp));
}

// The strip of an n-strip image (sweep_strip) holding the row.
int strip_of_row(double y_px, int n, const cv::Rect& image) {
  const double f = std::floor(y_px * n / std::max(1, image.height));
  return static_cast<int>(std::clamp(f, 0.0, static_cast<double>(n - 1)));
}

// An area too large to search in one frame (sweep_max_pixels, after its decimation): the part of
// it in one strip of the image, the strip of the prediction first, then the others nearest first,
// one more per frame of misses in a row. The strips overlap by a tag's largest extent, so a tag
// standing still lies wholly in one of them.
cv::Rect area_strip(const cv::Rect& area, Vec2 centre_px, int decimation, int missed,
                    double overlap_px, const SearchParams& sp, const cv::Rect& image) {
  const int n = strips_for(pixels_of(area, decimation), sp);
  if (n <= 1) return area;
  const int per_image =
      std::max(n, static_cast<int>(std::ceil(static_cast<double>(n) * image.height / area.height)));
  const int home = strip_of_row(centre_px.y, per_image, image);
  std::vector<cv::Rect> parts;
  for (int d = 0; d < per_image; ++d) {
    for (int b : {home - d, home + d}) {
      if (b < 0 || b >= per_image) continue;
      const cv::Rect part = sweep_strip(image, b, per_image, overlap_px) & area;
      // A strip that only grazes the area lies in its neighbour's overlap.
      const auto holds = [&part](const cv::Rect& q) { return (q & part) == part; };
      if (!part.empty() && std::none_of(parts.begin(), parts.end(), holds)) parts.push_back(part);
      if (d == 0) break;
    }
  }
  if (parts.empty()) return area;
  return parts[static_cast<std::size_t>(std::max(0, missed - 1)) % parts.size()];
}

// The interval's whole-image window for frame j of the interval (j < sweep_strips): the whole
// image, or strip j of it; whole when the tags' extent in view is unknown.
cv::Rect interval_sweep(const cv::Rect& image, const SearchParams& sp, const ViewTagSizes& sizes,
                        int j) {
  const int strips = sweep_strips(image, sp);
  if (strips == 1 || !sizes.ok) return image;
  return sweep_strip(image, j, strips, sizes.max_extent_px + 2.0 * sp.window_margin_px);
}

}  // namespace
}  // namespace search_detail

namespace sd = search_detail;

std::string validate(const SearchParams& p) {
  if (!(std::isfinite(p.window_sigmas) && p.window_sigmas >= 0.0 && p.window_sigmas <= 100.0)) {
    return "window_sigmas must be in [0, 100]";
  }
  if (!(std::isfinite(p.window_margin_px) && p.window_margin_px >= 0.0 &&
        p.window_margin_px <= 10000.0)) {
    return "window_margin_px must be in [0, 10000]";
  }
  if (p.max_window_px < 1) return "max_window_px must be >= 1";
  if (!(std::isfinite(p.decimated_side_px) && p.decimated_side_px >= 8.0 &&
        p.decimated_side_px <= 4096.0)) {
    return "decimated_side_px must be in [8, 4096]";
  }
  if (p.max_decimation < 1 || p.max_decimation > 8) return "max_decimation must be in [1, 8]";
  if (p.full_sweep_every_frames < 0) return "full_sweep_every_frames must be >= 0";
  if (p.sweep_max_pixels < 0) return "sweep_max_pixels must be >= 0";
  if (p.area_cols < 1 || p.area_cols > 64) return "area_cols must be in [1, 64]";
  if (p.area_rows < 1 || p.area_rows > 64) return "area_rows must be in [1, 64]";
  return {};
}

std::vector<SearchWindow> plan_search(const site::CeilingCamera& cam,
                                      const std::vector<site::FleetAgv>& fleet,
                                      const FleetTracker& tracker, std::int64_t t_ns,
                                      const SearchParams& params, const CameraSearchState& state) {
  std::vector<SearchWindow> out;
  const cv::Rect image(0, 0, cam.intrinsics.width_px, cam.intrinsics.height_px);
  if (image.width <= 0 || image.height <= 0) return out;
  SearchWindow full;
  full.level = SearchLevel::kFull;
  full.rect = image;
  if (!validate(params).empty()) {
    out.push_back(full);
    return out;
  }
  // The tags' sizes in view, computed only for a frame that needs them (a strip's overlap, a
  // whole-image window's decimation).
  std::optional<ViewTagSizes> sizes_memo;
  const auto sizes = [&]() -> const ViewTagSizes& {
    if (!sizes_memo) sizes_memo = view_tag_sizes(cam, fleet);
    return *sizes_memo;
  };
  const auto overlap_px = [&] { return sizes().max_extent_px + 2.0 * params.window_margin_px; };
  const std::size_t tracked = std::min(fleet.size(), tracker.size());
  bool untracked = fleet.size() > tracked, lost_in_area = false;
  for (std::size_t i = 0; i < tracked; ++i) {
    const TrackOutput o = tracker.output(i, t_ns);
    if (!sd::has_track(o.state)) {
      untracked = true;
      continue;
    }
    sd::TagPrediction p;
    if (!sd::predict_tag(cam, fleet[i], o, params.window_sigmas, &p)) continue;
    const cv::Rect rect = sd::track_rect(p, params.window_margin_px, image);
    if (rect.empty()) continue;  // not in this camera's view
    const int missed = i < state.missed.size() ? state.missed[i] : 0;
    // The whole image only for a vehicle no camera has seen for a while: one that another camera
    // sees (at this one's border, in a hand-over) keeps its track fresh.
    lost_in_area = lost_in_area || (missed >= 2 && o.state == TrackState::kCoasting);
    const int dec = sd::decimation_for_side(shortest_side_px(p.corners_px), params);
    const int max_px = params.max_window_px;
    if (missed > 0 || rect.width / dec > max_px || rect.height / dec > max_px) {
      cv::Rect area = sd::area_rect(p.centre_px, params, image);
      // A window too large but not missed yet holds the tag at window_sigmas: no need to look
      // beyond it.
      if (missed == 0) area &= rect;
      if (sizes().ok) {
        area = sd::area_strip(area, p.centre_px, dec, missed, overlap_px(), params, image);
      }
      sd::add_area(i, area, dec, &out);
      continue;
    }
    SearchWindow w;
    w.level = SearchLevel::kTrack;
    w.rect = rect;
    w.decimation = dec;
    w.agvs.push_back(i);
    w.predicted_corners_px = p.corners_px;
    out.push_back(std::move(w));
  }
  const int every = params.full_sweep_every_frames;
  const std::int64_t j = every > 0 ? state.frames % every : 0;
  const bool strip_due = untracked && every > 0 && j < sd::sweep_strips(image, params);
  if (state.frames != 0 && !lost_in_area && !strip_due) return out;
  if (sizes().ok) full.decimation = sd::decimation_for_side(sizes().min_side_px, params);
  if (state.frames == 0 || !sizes().ok) {
    // Without the tags' extent the strips' overlap is unknown: the whole image, for the
    // interval on its first frame only.
    if (state.frames == 0 || lost_in_area || j == 0) out.push_back(full);
    return out;
  }
  if (strip_due) {
    full.rect = sd::interval_sweep(image, params, sizes(), static_cast<int>(j));
  } else {
    // A vehicle lost in view: the image's strips in turn, one per frame.
    const int n = sd::strips_for(sd::pixels_of(image, 1), params);
    full.rect = sd::sweep_strip(image, static_cast<int>(state.frames % n), n, overlap_px());
  }
  out.push_back(full);
  return out;
}

ViewTagSizes view_tag_sizes(const site::CeilingCamera& cam,
                            const std::vector<site::FleetAgv>& fleet) {
  ViewTagSizes out;
  out.min_side_px = INFINITY;
  constexpr double kStepMm = 10.0;
  const double w = cam.intrinsics.width_px - 1.0, h = cam.intrinsics.height_px - 1.0;
  for (std::size_t k = 0; k < fleet.size(); ++k) {
    const site::FleetAgv& a = fleet[k];
    if (!(std::isfinite(a.tag_size_mm) && a.tag_size_mm > 0.0)) continue;
    // A fleet of one kind of vehicle is one computation.
    const auto same = [&a](const site::FleetAgv& b) {
      return b.tag_size_mm == a.tag_size_mm && b.tray_height_mm == a.tray_height_mm;
    };
    if (std::any_of(fleet.begin(), fleet.begin() + static_cast<std::ptrdiff_t>(k), same)) continue;
    for (int i = 0; i < 9; ++i) {
      const Vec2 px{0.5 * (i % 3) * w, 0.5 * (i / 3) * h};
      Vec2 c, p0, pu, pv;
      const double z = a.tray_height_mm;
      if (!pixel_to_plane(cam, px, z, &c) || !site_to_pixel(cam, c.x, c.y, z, &p0) ||
          !site_to_pixel(cam, c.x + kStepMm, c.y, z, &pu) ||
          !site_to_pixel(cam, c.x, c.y + kStepMm, z, &pv)) {
        continue;
      }
      double lo = 0.0, hi = 0.0;
      sd::singular_values((pu.x - p0.x) / kStepMm, (pv.x - p0.x) / kStepMm, (pu.y - p0.y) / kStepMm,
                          (pv.y - p0.y) / kStepMm, &lo, &hi);
      if (!std::isfinite(lo) || !std::isfinite(hi)) continue;
      out.ok = true;
      out.min_side_px = std::min(out.min_side_px, lo * a.tag_size_mm);
      out.max_extent_px = std::max(out.max_extent_px, hi * a.tag_size_mm * std::sqrt(2.0));
    }
  }
  if (!out.ok) out = ViewTagSizes{};
  return out;
}

std::vector<std::uint32_t> ids_in_area(const site::CeilingCamera& cam,
                                       const std::vector<site::FleetAgv>& fleet,
                                       const FleetTracker& tracker, std::int64_t t_ns,
                                       const cv::Rect& rect) {
  std::vector<std::uint32_t> ids;
  const cv::Rect image(0, 0, std::max(0, cam.intrinsics.width_px),
                       std::max(0, cam.intrinsics.height_px));
  for (std::size_t i = 0; i < fleet.size(); ++i) {
    const TrackOutput o = i < tracker.size() ? tracker.output(i, t_ns) : TrackOutput{};
    if (!o.valid()) {
      ids.push_back(fleet[i].tag_id);
      continue;
    }
    sd::TagPrediction p;
    if (!sd::predict_tag(cam, fleet[i], o, 3.0, &p)) continue;
    // The centre's reach: the position's 3-sigma box and the tag's half diagonal in pixels, at
    // any heading (a window holding any part of the tag may hold its id).
    double diag = 0.0;
    for (const Vec2& q : p.corners_px) {
      diag = std::max(diag, std::hypot(q.x - p.centre_px.x, q.y - p.centre_px.y));
    }
    const double wu = p.pos_u_px + diag, wv = p.pos_v_px + diag;
    const cv::Rect box = sd::clipped_box(p.centre_px.x - wu, p.centre_px.y - wv, p.centre_px.x + wu,
                                         p.centre_px.y + wv, image);
    if (!(box & rect).empty()) ids.push_back(fleet[i].tag_id);
  }
  return ids;
}

}  // namespace agv::overhead
