// TagDetector (tag_detect.hpp): libapriltag on a window for the search path, the outer-edge
// refinement and cell reading of tag_detect_geometry.cpp for both paths.
#include "agv/overhead/tag_detect.hpp"

#include <apriltag/apriltag.h>
#include <apriltag/common/homography.h>
#include <apriltag/tag36h11.h>

#include <algorithm>
#include <cmath>
#include <opencv2/imgproc.hpp>

#include "agv/overhead/tag_code.hpp"
#include "tag_detect_internal.hpp"

namespace agv::overhead {

// Named, not anonymous: the library is built as one unity source.
namespace detector_detail {

// libapriltag's decode sharpening (its default): blur costs the data cells more contrast than
// the border, sharpening gives some back.
constexpr double kDecodeSharpening = 0.25;
// libapriltag needs a few cells of pixels to find a quad: smaller windows are not searched.
constexpr int kMinWindowPx = 16;
// An edge step counts when it is this share of min_contrast (the blurred step of one profile is
// smaller than the median contrast of the cells).
constexpr double kMinStepShare = 0.5;
// Refinement passes on the search path: the second starts from the first's corners, so its
// samples stay clear of the true corners.
constexpr int kSearchPasses = 2;
// Share of a side that may lack edge points at either end (a hidden corner is refused, not
// extrapolated); the predicted path's wide first pass has none, its samples may overhang.
constexpr double kMaxEndGap = 0.1;
constexpr double kNoEndCheck = 1.0;
// Edge points every pixel for the fits; the predicted path's wide pass only finds the square.
constexpr double kFitSpacingPx = 1.0;
constexpr double kWideSpacingPx = 2.0;

bool usable_image(const cv::Mat& gray) {
  return !gray.empty() && gray.dims == 2 && gray.type() == CV_8UC1 && gray.cols >= kMinWindowPx &&
         gray.rows >= kMinWindowPx;
}

bool finite_corners(const std::array<Vec2, 4>& c) {
  return std::all_of(c.begin(), c.end(),
                     [](const Vec2& p) { return std::isfinite(p.x) && std::isfinite(p.y); });
}

// Corners of the page turned by q quarter turns: the read code is the id's code turned q times
// (rotate90 moves the content a quarter turn counter-clockwise on the page), so the true
// top-left is the guessed corner 3q further on.
std::array<Vec2, 4> turn_corners(const std::array<Vec2, 4>& c, int q) {
  std::array<Vec2, 4> out{};
  for (int k = 0; k < 4; ++k) {
    out[static_cast<std::size_t>(k)] = c[static_cast<std::size_t>((k + 3 * q) % 4)];
  }
  return out;
}

}  // namespace detector_detail

struct TagDetector::Impl {
  apriltag_family_t* family = nullptr;
  apriltag_detector_t* td = nullptr;

  explicit Impl(const TagDetectParams& p) {
    family = tag36h11_create();
    td = apriltag_detector_create();
    apriltag_detector_add_family_bits(td, family, std::clamp(p.global_bits_corrected, 0, 3));
    td->quad_decimate = static_cast<float>(std::max(1.0, p.quad_decimate));
    td->nthreads = 1;
    td->refine_edges = 1;
    td->decode_sharpening = detector_detail::kDecodeSharpening;
    td->qtp.min_white_black_diff = std::clamp(p.quad_min_white_black_diff, 1, 255);
  }
  ~Impl() {
    apriltag_detector_destroy(td);
    tag36h11_destroy(family);
  }
  Impl(const Impl&) = delete;
  Impl& operator=(const Impl&) = delete;
};

TagDetector::TagDetector(const TagDetectParams& params)
    : p_(params), impl_(std::make_unique<Impl>(params)) {}

TagDetector::~TagDetector() = default;

std::vector<TagObservation> TagDetector::detect(const cv::Mat& gray, const cv::Rect& window) const {
  using namespace detector_detail;
  std::vector<TagObservation> found;
  if (!usable_image(gray)) return found;
  const cv::Rect w = window & cv::Rect(0, 0, gray.cols, gray.rows);
  if (w.width < kMinWindowPx || w.height < kMinWindowPx) return found;
  // libapriltag reads the window in place through its own view type; it does not write it.
  image_u8_t view{w.width, w.height, static_cast<std::int32_t>(gray.step[0]),
                  const_cast<std::uint8_t*>(gray.ptr<std::uint8_t>(w.y) + w.x)};
  zarray_t* dets = apriltag_detector_detect(impl_->td, &view);
  const detect_detail::RefineParams narrow{p_.edge_band_px, kMinStepShare * p_.min_contrast,
                                           p_.max_edge_rms_px, kMaxEndGap, kFitSpacingPx};
  for (int i = 0; i < zarray_size(dets); ++i) {
    apriltag_detection_t* d = nullptr;
    zarray_get(dets, i, &d);
    // The detection's homography maps page coordinates (x right, y down, +-1 at the black
    // square's outer edge) into the window, already turned to the decoded orientation.
    std::array<Vec2, 4> guess{};
    const double pu[4][2] = {{-1, -1}, {1, -1}, {1, 1}, {-1, 1}};
    for (std::size_t k = 0; k < 4; ++k) {
      double x = 0, y = 0;
      homography_project(d->H, pu[k][0], pu[k][1], &x, &y);
      guess[k] = {x + w.x, y + w.y};
    }
    detect_detail::Square sq;
    bool ok = true;
    for (int pass = 0; pass < kSearchPasses && ok; ++pass) {
      ok = detect_detail::refine_square(gray, guess, narrow, &sq);
      guess = sq.corners;
    }
    detect_detail::Cells cells;
    if (!ok || !detect_detail::read_cells(gray, sq.corners, &cells) ||
        cells.contrast < p_.min_contrast) {
      continue;
    }
    // Our own reading must agree with libapriltag's decode (same id, page orientation): a
    // refinement that followed another edge reads another code.
    const DecodeResult r = decode_global(cells.code, p_.global_bits_corrected);
    if (!r.ok || r.id != static_cast<std::uint32_t>(d->id) || r.rotation != 0) continue;
    TagObservation o;
    o.corners_px = sq.corners;
    o.corner_sigma_px = sq.corner_sigma_px;
    o.code = cells.code;
    o.id = r.id;
    o.hamming = r.hamming;
    o.margin = r.margin;
    o.restricted = false;
    o.contrast = cells.contrast;
    found.push_back(o);
  }
  apriltag_detections_destroy(dets);
  return found;
}

std::vector<TagObservation> TagDetector::detect(const cv::Mat& gray, const cv::Rect& window,
                                                int decimation) const {
  using namespace detector_detail;
  const cv::Rect r = window & cv::Rect(0, 0, gray.cols, gray.rows);
  if (decimation <= 1 || !usable_image(gray) || r.width / decimation < kMinWindowPx ||
      r.height / decimation < kMinWindowPx) {
    return detect(gray, window);
  }
  cv::Mat small;
  const double f = 1.0 / decimation;
  cv::resize(gray(r), small, cv::Size(), f, f, cv::INTER_AREA);
  std::vector<TagObservation> out;
  for (const TagObservation& d : detect(small, cv::Rect(0, 0, small.cols, small.rows))) {
    // Pixel centres: small (i, j) covers full [dec i, dec (i + 1)), its centre dec (i + 0.5) - 0.5.
    std::array<Vec2, 4> guess{};
    for (std::size_t c = 0; c < 4; ++c) {
      guess[c] = {r.x + decimation * (d.corners_px[c].x + 0.5) - 0.5,
                  r.y + decimation * (d.corners_px[c].y + 0.5) - 0.5};
    }
    TagObservation full;
    if (detect_predicted(gray, guess, {d.id}, &full) && full.id == d.id) {
      const DecodeResult g = decode_global(full.code, p_.global_bits_corrected);
      if (g.ok && g.id == d.id && g.rotation == 0) {
        full.hamming = g.hamming;
        full.margin = g.margin;
        full.restricted = false;
        out.push_back(full);
        continue;
      }
    }
    for (const TagObservation& o : detect(gray, own_window(guess, gray.size()))) {
      if (o.id == d.id) out.push_back(o);
    }
  }
  return out;
}

double shortest_side_px(const std::array<Vec2, 4>& c) {
  double s = std::hypot(c[3].x - c[0].x, c[3].y - c[0].y);
  for (std::size_t i = 0; i < 3; ++i) {
    s = std::min(s, std::hypot(c[i + 1].x - c[i].x, c[i + 1].y - c[i].y));
  }
  return s;
}

int search_decimation(double side_px, double decimated_side_px, int max_decimation) {
  if (!(side_px > 0.0) || !std::isfinite(side_px) || !(decimated_side_px > 0.0)) return 1;
  const double n = std::floor(side_px / decimated_side_px);
  return static_cast<int>(std::clamp(n, 1.0, static_cast<double>(std::max(1, max_decimation))));
}

cv::Rect own_window(const std::array<Vec2, 4>& corners_px, const cv::Size& image) {
  double x0 = corners_px[0].x, x1 = x0, y0 = corners_px[0].y, y1 = y0;
  for (const Vec2& c : corners_px) {
    x0 = std::min(x0, c.x);
    x1 = std::max(x1, c.x);
    y0 = std::min(y0, c.y);
    y1 = std::max(y1, c.y);
  }
  const double m = std::max(16.0, 0.5 * std::max(x1 - x0, y1 - y0));
  const cv::Rect r(
      cv::Point(static_cast<int>(std::floor(x0 - m)), static_cast<int>(std::floor(y0 - m))),
      cv::Point(static_cast<int>(std::ceil(x1 + m)) + 1, static_cast<int>(std::ceil(y1 + m)) + 1));
  return r & cv::Rect(cv::Point(0, 0), image);
}

bool TagDetector::detect_predicted(const cv::Mat& gray,
                                   const std::array<Vec2, 4>& predicted_corners_px,
                                   const std::vector<std::uint32_t>& allowed_ids,
                                   TagObservation* out) const {
  using namespace detector_detail;
  if (!out || !usable_image(gray) || allowed_ids.empty() || !finite_corners(predicted_corners_px)) {
    return false;
  }
  const double min_step = kMinStepShare * p_.min_contrast;
  const detect_detail::RefineParams wide_rp{p_.predicted_search_px, min_step, p_.max_edge_rms_px,
                                            kNoEndCheck, kWideSpacingPx};
  const detect_detail::RefineParams narrow{p_.edge_band_px, min_step, p_.max_edge_rms_px,
                                           kMaxEndGap, kFitSpacingPx};
  detect_detail::Square wide, sq;
  // The wide pass finds the square within predicted_search_px, the narrow one refines it with
  // samples placed along the found sides.
  if (!detect_detail::refine_square(gray, predicted_corners_px, wide_rp, &wide) ||
      !detect_detail::refine_square(gray, wide.corners, narrow, &sq)) {
    return false;
  }
  for (std::size_t k = 0; k < 4; ++k) {
    if (std::hypot(sq.corners[k].x - predicted_corners_px[k].x,
                   sq.corners[k].y - predicted_corners_px[k].y) > 2.0 * p_.predicted_search_px) {
      return false;
    }
  }
  detect_detail::Cells cells;
  if (!detect_detail::read_cells(gray, sq.corners, &cells) || cells.contrast < p_.min_contrast) {
    return false;
  }
  const DecodeResult r = decode_restricted(cells.code, allowed_ids);
  if (!r.ok) return false;
  TagObservation o;
  o.corners_px = turn_corners(sq.corners, r.rotation);
  o.corner_sigma_px = sq.corner_sigma_px;
  // The code in the tag's own page orientation: turned back by the decoded quarter turns.
  std::uint64_t code = cells.code;
  for (int q = r.rotation; q % 4 != 0; ++q) code = rotate90(code);
  o.code = code;
  o.id = r.id;
  o.hamming = r.hamming;
  o.margin = r.margin;
  o.restricted = true;
  o.contrast = cells.contrast;
  *out = o;
  return true;
}

}  // namespace agv::overhead
