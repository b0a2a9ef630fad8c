// Tag family (VisionConfig::family = kTag36h11): libapriltag finds and decodes the tag (Debian's
// libapriltag 3.3, not rewritten), its homography gives the start of this project's pose stage
// (pose.cpp, outer edge of the black square only: the inner edge is broken by the data cells),
// the decoded rotation gives the heading quadrant and the map gives the id's world pose.
#include <apriltag/apriltag.h>
#include <apriltag/common/homography.h>
#include <apriltag/tag36h11.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <vector>

#include "localizer_impl.hpp"

namespace agv::vision {

namespace {

// Detector settings. Decimation 2 keeps the quad search cheap: the pose does not come from the
// detector's corners but from the edge fits, so its coarser quads cost no accuracy (the edge bands
// are +-band_rel border widths wide, several pixels, and the detector's corners are within a
// pixel or two). Two corrected bits: tag36h11's minimum Hamming distance is 11, so a 2-bit
// correction cannot turn one printed id into another, and it keeps dirty or scratched data cells
// readable.
constexpr float kQuadDecimate = 2.0f;
constexpr int kBitsCorrected = 2;
constexpr double kDecodeSharpening = 0.25;  // apriltag_detector_t::decode_sharpening is a double
// Tag coordinates of the detector's homography: +-1 is the outer edge of the black square, the
// border midline is one half module (1/8 of the half side) inside, the white margin one half
// module outside; the contrast samples stay this far from the corners (tag units).
constexpr double kBorderMid = 1.0 - 0.5 / 4.0;
constexpr double kMarginMid = 1.0 + 0.5 / 4.0;
constexpr double kContrastSpan = 0.75;
constexpr int kContrastSamplesPerSide = 9;
// Tag coordinates of the point that gives the forward axis (page up = tag -y, the row order of
// apriltag_to_image): far enough from the centre for a stable angle, inside the black square.
constexpr double kForwardProbe = 0.5;
// Side consistency of the outer-only fit: a side whose points sit, in the median, further than
// this from the fitted square (mm; about one pixel at the default 0.26 mm/px, ten times the clean
// edge noise) follows another edge of the same polarity, e.g. an occluder's end in the white
// margin. Without the inner edge the per-line fit cannot tell them apart, the square can.
constexpr double kMaxSideOffsetMm = 0.25;
// Size gate: the fitted outer half size (free when an axis has both sides, pose.cpp) against
// landmark.size_mm. The metric frame's scale follows the configured camera height, so a height
// off by dH of H shows the square dH / H larger or smaller (5 mm of 200 mm: 2.5 %) and moves the
// fix by that fraction of the tag's distance from the optical axis, as for the QR landmark. 3 %
// lets a tape-measured mount through (6 mm at 200 mm) and refuses a tag printed at another size,
// which the map cannot catch (the id is all a tag says). With the size fixed, as before, a 2 mm
// height error put every side 0.3 mm off and no tag gave a fix.
constexpr double kMaxSizeErrorRel = 0.03;
// apriltag_to_image() of tag36h11: 10 x 10 cells (a white ring, the black border ring, 6 x 6 data
// cells); the data cells start two cells in. In the black square's 8 x 8 cells they are 1..6.
constexpr int kTagImageCells = 10;
constexpr int kFirstDataCell = 2;
constexpr int kDataCells = 6;
constexpr int kSquareCells = 8;
static_assert(kDataCells * kDataCells == 36, "localizer_impl.hpp's read_tag_cells array");
// Predicted path: a cell's grey is the mean of its centre and four points this share of a cell
// away (inside it under a pixel of blur), and the code read there may differ from the predicted
// tag's in at most kBitsCorrected cells, as libapriltag's decode: with tag36h11's distance of 11
// between codes (and their turns) a neighbour's tag cannot pass, and noise matching 34 of 36
// cells by chance is a 1e-8 event.
constexpr double kCellSampleOffset = 0.25;
// The fitted centre must lie within this share of the pose stage's band of where the square was
// placed: a fit further away found other edges.
constexpr double kPlacedCentreBandShare = 1.0;

Vec2 project(const matd_t* h, double x, double y) {
  double px = 0, py = 0;
  homography_project(h, x, y, &px, &py);
  return {px, py};
}

}  // namespace

struct TagDetector {
  apriltag_family_t* family = nullptr;
  apriltag_detector_t* detector = nullptr;
  // Data cells of every tag36h11 id (6 x 6, row-major, 1 = black), from libapriltag's own
  // renderer as the simulator and the generator print them. Made once with the detector (587 ids,
  // 21 kB, well under a millisecond): the predicted path then neither allocates nor writes on a
  // frame. Empty when the renderer does not give the expected 10 x 10 cells.
  std::vector<std::array<std::uint8_t, kDataCells * kDataCells>> cells;
  const std::array<std::uint8_t, kDataCells * kDataCells>* data_cells(std::uint32_t id) const {
    return id < cells.size() ? &cells[id] : nullptr;
  }
  void render_cells() {
    cells.resize(family->ncodes);
    for (std::uint32_t id = 0; id < family->ncodes; ++id) {
      image_u8_t* im = apriltag_to_image(family, static_cast<int>(id));
      const bool ok = im && im->width == kTagImageCells && im->height == kTagImageCells;
      for (int r = 0; ok && r < kDataCells; ++r) {
        for (int k = 0; k < kDataCells; ++k) {
          const int ir = r + kFirstDataCell, ik = k + kFirstDataCell;
          cells[id][static_cast<size_t>(r * kDataCells + k)] =
              im->buf[ir * im->stride + ik] < 128 ? 1 : 0;
        }
      }
      // image_u8_destroy() is exported by libapriltag-utils only: the image is two calloc blocks.
      if (im) {
        std::free(im->buf);
        std::free(im);
      }
      if (!ok) {
        cells.clear();
        return;
      }
    }
  }
  TagDetector() {
    family = tag36h11_create();
    detector = apriltag_detector_create();
    apriltag_detector_add_family_bits(detector, family, kBitsCorrected);
    detector->quad_decimate = kQuadDecimate;
    detector->nthreads = 1;
    detector->refine_edges = 1;
    detector->decode_sharpening = kDecodeSharpening;
    render_cells();
  }
  ~TagDetector() {
    apriltag_detector_destroy(detector);
    tag36h11_destroy(family);
  }
  TagDetector(const TagDetector&) = delete;
  TagDetector& operator=(const TagDetector&) = delete;
};

std::shared_ptr<TagDetector> make_tag_detector() { return std::make_shared<TagDetector>(); }

// Median offset (mm) of the side's points from side k of the square (c, beta, half side h).
double LandmarkLocalizer::Impl::side_offset_mm(const EdgePoints& pts, int k, Vec2 c, double beta,
                                               double h) {
  const double a = beta - k * kPi / 2.0;
  const Vec2 n{std::cos(a), std::sin(a)};
  scratch_buf.clear();
  for (const Vec2& p : pts.mm[static_cast<size_t>(k * 2)]) {
    scratch_buf.push_back(n.x * (p.x - c.x) + n.y * (p.y - c.y) - h);
  }
  if (scratch_buf.empty()) return 0.0;
  const auto mid = scratch_buf.begin() + static_cast<std::ptrdiff_t>(scratch_buf.size() / 2);
  std::nth_element(scratch_buf.begin(), mid, scratch_buf.end());
  return std::abs(*mid);
}

// Outer-only fits: the worst side, when it disagrees with the square, is dropped and the square
// refitted from the other three (each axis must keep a side); a square that still disagrees
// with one of its sides gives no fix. The square has the size pose() fitted (out->outer_half_mm)
// when it could, else the printed one.
FixStatus LandmarkLocalizer::Impl::drop_inconsistent_side(EdgePoints* pts, Vec2* c_mm, double* beta,
                                                          Eigen::Matrix3d* cov, LandmarkFix* out) {
  const double h_printed = geom.outer_half_mm();
  auto& line_ok = pts->line_ok;
  auto worst = [&](Vec2 c, double b, double h, double* off) {
    int wk = -1;
    *off = 0.0;
    for (int k = 0; k < 4; ++k) {
      if (!line_ok[static_cast<size_t>(k * 2)]) continue;
      const double o = side_offset_mm(*pts, k, c, b, h);
      if (o > *off) *off = o, wk = k;
    }
    return wk;
  };
  const double h = out->outer_half_mm > 0.0 ? out->outer_half_mm : h_printed;
  double off = 0.0;
  const int k = worst(*c_mm, *beta, h, &off);
  if (off <= kMaxSideOffsetMm) return FixStatus::kOk;
  line_ok[static_cast<size_t>(k * 2)] = false;
  if (!line_ok[static_cast<size_t>(((k + 2) % 4) * 2)]) return FixStatus::kTooFewEdgePoints;
  // The size stays free while an axis keeps both sides; when the dropped side was half of the only
  // opposite pair, the size it helped fit is not trusted and the printed one is used.
  const bool pair = (line_ok[0] && line_ok[4]) || (line_ok[2] && line_ok[6]);
  SquareModel m;
  m.c = *c_mm;
  m.beta = *beta;
  m.h_out = pair ? h : h_printed;
  m.h_in = geom.inner_half_mm();
  for (auto& w : pts->weights) std::fill(w.begin(), w.end(), 1.0);
  NormalEquations ne;
  const int n_params = pair ? 4 : 3;
  if (!joint_fit(PoseMethod::kJointSquareFit, n_params, pts, &m, &ne)) {
    return FixStatus::kTooFewEdgePoints;
  }
  worst(m.c, m.beta, m.h_out, &off);
  if (off > kMaxSideOffsetMm) return FixStatus::kTooFewEdgePoints;
  *cov = fit_covariance(ne, n_params, cfg);
  out->residual_rms_mm = ne.sum_w > 0 ? std::sqrt(ne.ssr / ne.sum_w) : 0.0;
  out->sides_used -= 1;
  out->outer_half_mm = pair ? m.h_out : 0.0;
  *c_mm = m.c;
  *beta = m.beta;
  keep_overlay_geometry(m);
  return FixStatus::kOk;
}

// libapriltag first; when it finds no tag, or its quad gives no fix, the prediction and the map
// place the predicted tag's square as the QR family's tracking does, and the tag's code is read
// at the fitted square (docs/design/landmark.md "AprilTag landmark"). libapriltag needs the whole
// quad with white around it: an occluder over the border, or floor dirt joining it, breaks it.
FixStatus LandmarkLocalizer::Impl::run_tag(const cv::Mat& img, const Prediction& pred,
                                           LandmarkFix* out) {
  if (!tag) tag = make_tag_detector();  // made at start-up (Impl's constructor)
  outer_only = true;
  const double t0 = now_ms();
  const FixStatus st = tag_from_detector(img, out);
  if (st == FixStatus::kOk || !map) return st;
  if (cfg.tracking.detect_from_prediction) {
    planner.plan(pred, &windows);
    LandmarkFix tried;
    if (!windows.empty() && tag_from_prediction(img, &tried) == FixStatus::kOk) {
      tried.timings = out->timings;
      *out = tried;
      return FixStatus::kOk;
    }
  }
  if (st != FixStatus::kNoLandmark || !cfg.tag_corner_search) return st;
  LandmarkFix found;
  found.timings = out->timings;
  const FixStatus cs = tag_from_corners(img, t0, &found);
  if (cs == FixStatus::kNoLandmark) return st;
  *out = found;
  return cs;
}

FixStatus LandmarkLocalizer::Impl::tag_from_detector(const cv::Mat& img, LandmarkFix* out) {
  const double t0 = now_ms();
  // libapriltag reads the caller's pixels through its own view type; it does not write them.
  image_u8_t view{img.cols, img.rows, static_cast<std::int32_t>(img.step[0]),
                  const_cast<std::uint8_t*>(img.ptr<std::uint8_t>(0))};
  zarray_t* dets = apriltag_detector_detect(tag->detector, &view);
  // The strongest decode (one tag per frame on a surveyed floor; a second one is a worse view).
  apriltag_detection_t* best = nullptr;
  for (int i = 0; i < zarray_size(dets); ++i) {
    apriltag_detection_t* d = nullptr;
    zarray_get(dets, i, &d);
    if (!best || d->decision_margin > best->decision_margin) best = d;
  }
  if (!best) {
    apriltag_detections_destroy(dets);
    if (cfg.now_ns) out->timings.detect_ms = now_ms() - t0;
    return FixStatus::kNoLandmark;
  }
  const std::uint32_t id = static_cast<std::uint32_t>(best->id);
  const matd_t* hm = best->H;
  const Vec2 c_px = project(hm, 0.0, 0.0);
  const Vec2 side_px = project(hm, 1.0, 0.0);
  const Vec2 fwd_px = project(hm, 0.0, -kForwardProbe);
  const double up = std::atan2(side_px.y - c_px.y, side_px.x - c_px.x);
  double dark = 0, white = 0;
  int n_dark = 0, n_white = 0;
  for (int k = 0; k < 4; ++k) {
    for (int i = 0; i < kContrastSamplesPerSide; ++i) {
      const double t = kContrastSpan * (2.0 * i / (kContrastSamplesPerSide - 1) - 1.0);
      const double sx = (k == 0) - (k == 2), sy = (k == 1) - (k == 3);
      double v;
      const Vec2 pd = project(hm, sx * kBorderMid + sy * t, sy * kBorderMid + sx * t);
      if (sample(img, pd.x, pd.y, &v)) dark += v, ++n_dark;
      const Vec2 pw = project(hm, sx * kMarginMid + sy * t, sy * kMarginMid + sx * t);
      if (sample(img, pw.x, pw.y, &v)) white += v, ++n_white;
    }
  }
  apriltag_detections_destroy(dets);
  const double t1 = now_ms();
  if (cfg.now_ns) out->timings.detect_ms = t1 - t0;
  if (n_dark == 0 || n_white == 0) return FixStatus::kNoLandmark;
  const double contrast = white / n_white - dark / n_dark;
  if (contrast < kMinContrastGrey) return FixStatus::kNoLandmark;
  out->corner_score = contrast;
  out->detect_x_px = c_px.x;
  out->detect_y_px = c_px.y;
  out->detect_angle_deg = rad_to_deg(up);
  out->partly_outside = partly_outside(img, c_px, up);
  if (out->partly_outside && !cfg.allow_partly_outside) return FixStatus::kPartlyOutside;
  out->landmark_id = id;
  std::snprintf(out->payload, sizeof out->payload, "tag36h11/%u", static_cast<unsigned>(id));

  Vec2 c_mm;
  double beta = 0;
  Eigen::Matrix3d cov;
  FixStatus st = pose(img, c_px, up, contrast, &edge_points, out, &c_mm, &beta, &cov);
  if (cfg.now_ns) out->timings.pose_ms = now_ms() - t1;
  if (st == FixStatus::kTooFewEdgePoints && out->partly_outside) st = FixStatus::kPartlyOutside;
  if (st != FixStatus::kOk) return st;
  have_overlay = true;

  st = consistent_square(&edge_points, &c_mm, &beta, &cov, out);
  if (st != FixStatus::kOk) return st;

  // Heading quadrant from the decoded rotation: the fitted border normal beta is only known modulo
  // 90 degrees, the detector's homography says which side is the tag's top.
  const FloorProjector& mc = metric_floor;
  Vec2 a0, a1;
  if (!mc.pixel_to_vehicle(c_px, &a0) || !mc.pixel_to_vehicle(fwd_px, &a1)) {
    return FixStatus::kDirectionAmbiguous;
  }
  const double fwd0 = std::atan2(a1.y - a0.y, a1.x - a0.x);
  const int q = static_cast<int>(std::lround(wrap_angle_rad(beta - fwd0) / (kPi / 2.0)) + 4) % 4;
  quadrant = q;

  const LandmarkMapEntry* e = map ? map->find(id) : nullptr;
  if (!e) return FixStatus::kUnknownLandmark;
  out->map_verified = true;
  fill_result(e->pose, c_mm, beta, q, cov, out);
  out->identity = FixIdentity::kAprilTag;
  return FixStatus::kOk;
}

// The outer-only square's checks after the pose stage: sides that disagree, and the size gate.
FixStatus LandmarkLocalizer::Impl::consistent_square(EdgePoints* pts, Vec2* c_mm, double* beta,
                                                     Eigen::Matrix3d* cov, LandmarkFix* out) {
  const FixStatus st = drop_inconsistent_side(pts, c_mm, beta, cov, out);
  if (st != FixStatus::kOk) return st;
  if (out->outer_half_mm > 0.0 &&
      std::abs(out->outer_half_mm / geom.outer_half_mm() - 1.0) > kMaxSizeErrorRel) {
    return FixStatus::kTooFewEdgePoints;
  }
  return FixStatus::kOk;
}

// Cells of the black square (row r, column k of 8, page orientation: row 0 at the top) that
// differ from tag id's code at turn q of the fitted square; -1 when a cell leaves the image. The
// threshold is halfway between the border ring's and the white margin's medians, so an occluder
// over part of the border or the margin does not move it.
bool LandmarkLocalizer::Impl::read_tag_cells(const cv::Mat& img, Vec2 c_mm, double beta, int q,
                                             double half_mm, std::array<std::uint8_t, 36>* cells) {
  const PlaneProjector pp = page_projector(c_mm, wrap_angle_rad(beta - q * kPi / 2.0));
  const double m = 2.0 * half_mm / kSquareCells;
  auto cell_grey = [&](int r, int k, double* g) {
    double sum = 0;
    int n = 0;
    const double u = -half_mm + (k + 0.5) * m, v = -half_mm + (r + 0.5) * m;
    const double o = kCellSampleOffset * m;
    for (const Vec2& d : {Vec2{0, 0}, Vec2{o, 0}, Vec2{-o, 0}, Vec2{0, o}, Vec2{0, -o}}) {
      Vec2 px;
      double val;
      if (!pp.to_pixel({u + d.x, v + d.y}, &px) || !sample(img, px.x, px.y, &val)) return false;
      sum += val;
      ++n;
    }
    *g = sum / n;
    return true;
  };
  auto median = [](std::vector<double>* v) {
    const auto mid = v->begin() + static_cast<std::ptrdiff_t>(v->size() / 2);
    std::nth_element(v->begin(), mid, v->end());
    return *mid;
  };
  std::vector<double>& ring = scratch_buf;
  ring.clear();
  tag_margin.clear();
  double g = 0;
  for (int i = 0; i < kSquareCells; ++i) {
    for (const auto& [r, k] : {std::pair{0, i}, std::pair{kSquareCells - 1, i}, std::pair{i, 0},
                               std::pair{i, kSquareCells - 1}}) {
      if (cell_grey(r, k, &g)) ring.push_back(g);
    }
    for (const auto& [r, k] : {std::pair{-1, i}, std::pair{kSquareCells, i}, std::pair{i, -1},
                               std::pair{i, kSquareCells}}) {
      if (cell_grey(r, k, &g)) tag_margin.push_back(g);
    }
  }
  if (ring.empty() || tag_margin.empty()) return false;
  const double threshold = 0.5 * (median(&ring) + median(&tag_margin));
  for (int r = 0; r < kDataCells; ++r) {
    for (int k = 0; k < kDataCells; ++k) {
      if (!cell_grey(r + 1, k + 1, &g)) return false;
      (*cells)[static_cast<size_t>(r * kDataCells + k)] = g < threshold ? 1 : 0;
    }
  }
  return true;
}

int LandmarkLocalizer::Impl::tag_code_distance(const cv::Mat& img, Vec2 c_mm, double beta, int q,
                                               double half_mm, std::uint32_t id) {
  const auto* want = tag->data_cells(id);
  std::array<std::uint8_t, kDataCells * kDataCells> got{};
  if (!want || !read_tag_cells(img, c_mm, beta, q, half_mm, &got)) return -1;
  int differ = 0;
  for (size_t i = 0; i < got.size(); ++i) differ += got[i] != (*want)[i];
  return differ;
}

// No quad from libapriltag and none placed by the prediction (none trusted: the first fix, or
// after a long leg): the QR family's full search (detect.cpp) finds the black square from its
// outer corners, which a border broken on one side keeps three of, the pose stage fits the outer
// square, and the code read at the fitted square is looked up among all tag36h11 codes at the
// four turns, accepted within kBitsCorrected cells as libapriltag's decode. Only the full search
// costs anything on a frame without a tag (the QR family's every frame does the same).
FixStatus LandmarkLocalizer::Impl::tag_from_corners(const cv::Mat& img, double t0_ms,
                                                    LandmarkFix* out) {
  Detection det;
  bool found_corner = false;
  double corner_score = 0;
  if (!detect(img, &det, &found_corner, &corner_score)) return FixStatus::kNoLandmark;
  Vec2 c_mm;
  double beta = 0;
  Eigen::Matrix3d cov;
  FixStatus st = measure(img, det, corner_score, t0_ms, out, &c_mm, &beta, &cov);
  if (st == FixStatus::kOk) st = consistent_square(&edge_points, &c_mm, &beta, &cov, out);
  if (st != FixStatus::kOk) return st;
  have_overlay = true;
  const double half = out->outer_half_mm > 0.0 ? out->outer_half_mm : geom.outer_half_mm();
  std::array<std::array<std::uint8_t, kDataCells * kDataCells>, 4> read{};
  bool readable[4] = {};
  for (int q = 0; q < 4; ++q) readable[q] = read_tag_cells(img, c_mm, beta, q, half, &read[q]);
  int best_q = -1, best_d = kDataCells * kDataCells + 1;
  std::uint32_t best_id = 0;
  for (std::uint32_t id = 0; id < tag->cells.size(); ++id) {
    const auto& want = tag->cells[id];
    for (int q = 0; q < 4; ++q) {
      if (!readable[q]) continue;
      int d = 0;
      for (size_t i = 0; i < want.size(); ++i) d += read[q][i] != want[i];
      if (d < best_d) best_d = d, best_q = q, best_id = id;
    }
  }
  // A dark square without a tag's code (a floor feature, another print) is not a tag.
  if (best_q < 0 || best_d > kBitsCorrected) return FixStatus::kNoLandmark;
  quadrant = best_q;
  out->landmark_id = best_id;
  std::snprintf(out->payload, sizeof out->payload, "tag36h11/%u", static_cast<unsigned>(best_id));
  out->search = SearchMode::kFull;
  const LandmarkMapEntry* e = map->find(best_id);
  if (!e) return FixStatus::kUnknownLandmark;
  out->map_verified = true;
  fill_result(e->pose, c_mm, beta, best_q, cov, out);
  out->identity = FixIdentity::kAprilTag;
  return FixStatus::kOk;
}

// The QR family's tracking for a tag (landmark_localizer.cpp, predicted_detect.cpp,
// edge_probe.cpp): each predicted mapped tag in view is placed by the prediction itself when it is
// precise enough, else by the edge probes (outer edge only; one side may be lost to an occluder),
// its outer square fitted by the pose stage, and accepted when its code, read at the fitted
// square, is the predicted tag's at one of the four turns. The id is read, not assumed: the fix
// is the detector's (identity tag, map-verified), found where libapriltag's quad search was not.
FixStatus LandmarkLocalizer::Impl::tag_from_prediction(const cv::Mat& img, LandmarkFix* out) {
  FixStatus best_st = FixStatus::kNoLandmark;
  for (const SearchWindow& w : windows) {
    const LandmarkMapEntry* e = map->find(w.landmark_id);
    if (!e || w.landmark_id > kTag36h11MaxId) continue;
    Vec2 c_px;
    double up = 0, dark = 0, white = 0;
    bool placed = false, probed = false;
    if (prediction_places_bands(w)) {
      int n_dark = 0, n_samples = 0;
      placed =
          ring_check_full(img, w.centre_px, w.up_angle_rad, &dark, &white, &n_dark, &n_samples);
      c_px = w.centre_px;
      up = w.up_angle_rad;
    }
    if (!placed && cfg.tracking.probe_edges) {
      ProbedSquare sq;
      placed = probed = probe_prediction(img, w, &sq);
      c_px = sq.centre_px;
      up = sq.up_rad;
      dark = sq.dark_grey;
      white = sq.white_grey;
    }
    if (!placed) continue;
    const double contrast = white - dark;
    if (contrast < kMinContrastGrey) continue;
    LandmarkFix f;
    f.corner_score = contrast;
    f.detect_x_px = c_px.x;
    f.detect_y_px = c_px.y;
    f.detect_angle_deg = rad_to_deg(up);
    f.search = SearchMode::kWindow;
    f.detection_predicted = true;
    f.detection_probed = probed;
    f.partly_outside = partly_outside(img, c_px, up);
    if (f.partly_outside && !cfg.allow_partly_outside) continue;
    Vec2 c_mm;
    double beta = 0;
    Eigen::Matrix3d cov;
    FixStatus st = pose(img, c_px, up, contrast, &edge_points, &f, &c_mm, &beta, &cov);
    const double band_px = cfg.band_rel * geom.border_width_mm() / mm_per_px;
    if (st == FixStatus::kOk &&
        std::hypot(centre_px.x - c_px.x, centre_px.y - c_px.y) > kPlacedCentreBandShare * band_px) {
      st = FixStatus::kNoLandmark;
    }
    if (st == FixStatus::kOk) st = consistent_square(&edge_points, &c_mm, &beta, &cov, &f);
    if (st != FixStatus::kOk) {
      best_st = st;
      continue;
    }
    const double half = f.outer_half_mm > 0.0 ? f.outer_half_mm : geom.outer_half_mm();
    int best_q = -1, best_d = kDataCells * kDataCells + 1;
    for (int q = 0; q < 4; ++q) {
      const int d = tag_code_distance(img, c_mm, beta, q, half, w.landmark_id);
      if (d >= 0 && d < best_d) best_d = d, best_q = q;
    }
    if (best_q < 0 || best_d > kBitsCorrected) {
      best_st = FixStatus::kUnknownLandmark;
      continue;
    }
    have_overlay = true;
    quadrant = best_q;
    f.landmark_id = w.landmark_id;
    std::snprintf(f.payload, sizeof f.payload, "tag36h11/%u", static_cast<unsigned>(w.landmark_id));
    f.map_verified = true;
    fill_result(e->pose, c_mm, beta, best_q, cov, &f);
    f.identity = FixIdentity::kAprilTag;
    f.status = FixStatus::kOk;
    *out = f;
    return FixStatus::kOk;
  }
  return best_st;
}

}  // namespace agv::vision
