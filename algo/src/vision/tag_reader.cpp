// The tag family's own stage (tag_reader.hpp): libapriltag's detector and its quad, the data
// cells read at a fitted square, and the outer-only square's side and size checks.
#include "tag_reader.hpp"

#include <apriltag/apriltag.h>
#include <apriltag/common/homography.h>
#include <apriltag/tag36h11.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdlib>
#include <vector>

namespace agv::vision {

namespace {

// Detector settings. Decimation 2 keeps the quad search cheap: the pose does not come from the
// detector's corners but from the edge fits, so its coarser quads cost no accuracy (the edge bands
// are +-band_rel border widths wide, several pixels, and the detector's corners are within a
// pixel or two). Two corrected bits: tag36h11's minimum Hamming distance is 11, so a 2-bit
// correction cannot turn one printed id into another, and it keeps dirty or scratched data cells
// readable.
constexpr float kQuadDecimate = 2.0f;
constexpr int kBitsCorrected = TagReader::kBitsCorrected;
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
constexpr int kDataCells = TagReader::kDataCells;
constexpr int kSquareCells = 8;
// Predicted path: a cell's grey is the mean of its centre and four points this share of a cell
// away (inside it under a pixel of blur), and the code read there may differ from the predicted
// tag's in at most kBitsCorrected cells, as libapriltag's decode: with tag36h11's distance of 11
// between codes (and their turns) a neighbour's tag cannot pass, and noise matching 34 of 36
// cells by chance is a 1e-8 event.
constexpr double kCellSampleOffset = 0.25;
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

TagReader::TagReader(const VisionSetup& s, SquareFit& fit) : setup(s), square(fit) {
  if (setup.cfg.family == LandmarkFamily::kTag36h11) tag = make_tag_detector();
}

bool TagReader::strongest_quad(const cv::Mat& img, TagQuad* quad) {
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
    return false;
  }
  quad->id = static_cast<std::uint32_t>(best->id);
  const matd_t* hm = best->H;
  const Vec2 c_px = project(hm, 0.0, 0.0);
  const Vec2 side_px = project(hm, 1.0, 0.0);
  quad->c_px = c_px;
  quad->fwd_px = project(hm, 0.0, -kForwardProbe);
  quad->up = std::atan2(side_px.y - c_px.y, side_px.x - c_px.x);
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
  quad->sampled = n_dark != 0 && n_white != 0;
  if (quad->sampled) quad->contrast = white / n_white - dark / n_dark;
  return true;
}

// Median offset (mm) of the side's points from side k of the square (c, beta, half side h).
double TagReader::side_offset_mm(const EdgePoints& pts, int k, Vec2 c, double beta, double h) {
  const double a = beta - k * kPi / 2.0;
  const Vec2 n{std::cos(a), std::sin(a)};
  side_offsets.clear();
  for (const Vec2& p : pts.mm[static_cast<size_t>(k * 2)]) {
    side_offsets.push_back(n.x * (p.x - c.x) + n.y * (p.y - c.y) - h);
  }
  if (side_offsets.empty()) return 0.0;
  const auto mid = side_offsets.begin() + static_cast<std::ptrdiff_t>(side_offsets.size() / 2);
  std::nth_element(side_offsets.begin(), mid, side_offsets.end());
  return std::abs(*mid);
}

// Outer-only fits: the worst side, when it disagrees with the square, is dropped and the square
// refitted from the other three (each axis must keep a side); a square that still disagrees
// with one of its sides gives no fix. The square has the size pose() fitted (out->outer_half_mm)
// when it could, else the printed one.
FixStatus TagReader::drop_inconsistent_side(EdgePoints* pts, Vec2* c_mm, double* beta,
                                            Eigen::Matrix3d* cov, LandmarkFix* out) {
  const double h_printed = setup.geom.outer_half_mm();
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
  m.h_in = setup.geom.inner_half_mm();
  for (auto& w : pts->weights) std::fill(w.begin(), w.end(), 1.0);
  NormalEquations ne;
  const int n_params = pair ? 4 : 3;
  if (!square.joint_fit(PoseMethod::kJointSquareFit, n_params, pts, &m, &ne)) {
    return FixStatus::kTooFewEdgePoints;
  }
  worst(m.c, m.beta, m.h_out, &off);
  if (off > kMaxSideOffsetMm) return FixStatus::kTooFewEdgePoints;
  *cov = fit_covariance(ne, n_params, setup.cfg);
  out->residual_rms_mm = ne.sum_w > 0 ? std::sqrt(ne.ssr / ne.sum_w) : 0.0;
  out->sides_used -= 1;
  out->outer_half_mm = pair ? m.h_out : 0.0;
  *c_mm = m.c;
  *beta = m.beta;
  square.keep_overlay_geometry(m);
  return FixStatus::kOk;
}

// The outer-only square's checks after the pose stage: sides that disagree, and the size gate.
FixStatus TagReader::consistent_square(EdgePoints* pts, Vec2* c_mm, double* beta,
                                       Eigen::Matrix3d* cov, LandmarkFix* out) {
  const FixStatus st = drop_inconsistent_side(pts, c_mm, beta, cov, out);
  if (st != FixStatus::kOk) return st;
  if (out->outer_half_mm > 0.0 &&
      std::abs(out->outer_half_mm / setup.geom.outer_half_mm() - 1.0) > kMaxSizeErrorRel) {
    return FixStatus::kTooFewEdgePoints;
  }
  return FixStatus::kOk;
}

// Cells of the black square (row r, column k of 8, page orientation: row 0 at the top) that
// differ from tag id's code at turn q of the fitted square; -1 when a cell leaves the image. The
// threshold is halfway between the border ring's and the white margin's medians, so an occluder
// over part of the border or the margin does not move it.
bool TagReader::read_tag_cells(const cv::Mat& img, Vec2 c_mm, double beta, int q, double half_mm,
                               Cells* cells) {
  const PlaneProjector pp = setup.page_projector(c_mm, wrap_angle_rad(beta - q * kPi / 2.0));
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
  std::vector<double>& ring = tag_ring;
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

int TagReader::tag_code_distance(const cv::Mat& img, Vec2 c_mm, double beta, int q, double half_mm,
                                 std::uint32_t id) {
  const auto* want = tag->data_cells(id);
  Cells got{};
  if (!want || !read_tag_cells(img, c_mm, beta, q, half_mm, &got)) return -1;
  int differ = 0;
  for (size_t i = 0; i < got.size(); ++i) differ += got[i] != (*want)[i];
  return differ;
}

void TagReader::nearest_code(const std::array<Cells, 4>& read, const bool readable[4], int* best_q,
                             int* best_d, std::uint32_t* best_id) const {
  for (std::uint32_t id = 0; id < tag->cells.size(); ++id) {
    const auto& want = tag->cells[id];
    for (int q = 0; q < 4; ++q) {
      if (!readable[q]) continue;
      int d = 0;
      for (size_t i = 0; i < want.size(); ++i) d += read[q][i] != want[i];
      if (d < *best_d) *best_d = d, *best_q = q, *best_id = id;
    }
  }
}

}  // namespace agv::vision
