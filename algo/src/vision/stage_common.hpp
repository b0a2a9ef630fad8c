// Private to algo/src/vision: what the stages share. The constants and value types that pass
// between stages (a stage's result is its return value or an argument), the inline sampling
// helpers, and VisionSetup, the read-only configuration every stage holds a reference to.
#pragma once

#include <Eigen/Core>
#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <memory>
#include <opencv2/core.hpp>
#include <string>
#include <vector>

#include "agv/common/camera_model.hpp"
#include "agv/common/geometry.hpp"
#include "agv/common/landmark.hpp"
#include "agv/vision/bilinear.hpp"
#include "agv/vision/edges.hpp"
#include "agv/vision/landmark_localizer.hpp"
#include "agv/vision/qr_grid.hpp"

namespace agv::vision {

constexpr int kNumLines = 8;       // line index = side * 2 + (inner ? 1 : 0)
constexpr int kMaxTemplates = 32;  // upper bound of VisionConfig::corner_rotations

// A version-2 code (38-character payload, ECC M) has 25 modules a side; a version-1 code (id-only
// payloads) has 21. The guided reader tries the larger first because full payloads are the norm.
constexpr int kQrModulesV2 = 25;
constexpr int kQrModulesV1 = 21;

// Corner peaks whose predicted landmark centres are closer than this (in border widths;
// neighbouring landmarks are a grid apart) vote for the same landmark: the full search merges
// them (detect.cpp), the tracked detection requires its corners to agree (track_detect.cpp).
constexpr double kMergeDistanceBorderWidths = 1.5;

// Image angles measured on the metric model are taken from the centre and a point this far along
// the direction: far enough that pixel rounding in the camera model is negligible (< 0.05 deg),
// near enough to stay inside the landmark's footprint for the distortion to be the local one.
constexpr double kAngleProbePx = 20.0;

// Ring check (detect.cpp, and on the full image predicted_detect.cpp): the outside ring runs at
// 0.9 border widths beyond the outer edge, on the paper margin, clear of the border's blurred
// edge; the paper is taken as white when no outside sample is in the image.
constexpr double kOutsideRingBorderWidths = 0.9;
constexpr double kWhiteGrey = 255.0;

// Border-to-paper contrast (grey levels, coarse image) below which a detection is not measured:
// the edge threshold (edge_threshold_rel * 3 * contrast = 11 at 15) would sink to the Prewitt
// noise of the read noise the evaluation covers (sigma 4 -> 4 * sqrt(6) = 10), and a ring that
// faint is more likely a shadow or stain than printed ink.
constexpr double kMinContrastGrey = 15.0;
// Pixel centres are at integer coordinates, so the image covers -0.5 .. size - 0.5.
constexpr double kHalfPixel = 0.5;

// The tracked detection's refined angle (track_detect.cpp) and the edge probes' (edge_probe.cpp)
// may differ from the prediction by window_sigmas heading sigmas plus this: the prediction's angle
// is that of a probe along one axis at the centre, while the refinement averages the gradients of
// all four sides, which a tilted camera's perspective turns by up to ~2.5 degrees against each
// other (measured, tests/vision/test_tracking.cpp); the gradient estimate on the coarse image
// scatters by a fraction of a degree more. A wrong prediction a template step (30 degrees) off is
// still rejected.
constexpr double kTrackedAngleSlackDeg = 5.0;

// Edge probes (edge_probe.cpp): one probe's border edge, and the square from all of them.
struct ProbeEdge {
  double s = 0;  // subpixel position of the outer edge along the probe
  double t = 0;  // the probe's place along the side (px from the predicted side's middle)
  double light_grey = 0, dark_grey = 0;
  double ramp_px = 0;  // from the step's start to the edge: half a blurred edge's width
};
struct ProbedSquare {
  Vec2 centre_px;
  double up_rad = 0;
  // Mean grey levels outside the border and on it over the probes on the lines: the ring
  // check's levels, which scale the edge threshold.
  double dark_grey = 0, white_grey = 0;
  // Probes on the four lines / probes (a precise prediction: dark ring samples / samples).
  double on_line_share = 0;
};

struct CornerPeak {
  double x = 0, y = 0;  // coarse pixels (template centre)
  double score = 0;
  int rot = 0;
};

struct Hypothesis {
  double cx = 0, cy = 0;  // landmark centre, coarse pixels
  double up_angle = 0;    // image angle of one border normal (mod 90 deg)
  double score_sum = 0, score_max = 0;
  double sum_w = 0;
  double c4 = 0, s4 = 0;          // accumulated 4*angle vector
  std::array<int, 8> peak_idx{};  // supporting corner peaks
  int n_peaks = 0;
};

// Accepted detection: the hypothesis and the grey levels its ring check measured.
struct Detection {
  Hypothesis h;
  double dark_grey = 0.0;   // mean grey of the dark border ring samples (coarse image)
  double white_grey = 0.0;  // mean grey just outside the border
};

// The joint square model of pose.cpp: centre and outward normal angle of side 0 in the metric
// (vehicle) frame, and the half sizes of the outer and inner border edges.
struct SquareModel {
  Vec2 c;
  double beta = 0.0;
  double h_out = 0.0, h_in = 0.0;
};

// Stage 3's edge points of one square (pose.cpp): collected in pixels (collect), projected to the
// metric frame with a weight each (fit_lines; the joint fit re-weights them), and which of the
// eight lines count (line_ok; the tag family's side check drops one). Stage 3 and the tag family's
// square check take it as an argument; the overlay draws the last frame's pixels.
struct EdgePoints {
  std::array<std::vector<Vec2>, kNumLines> px, mm;
  std::array<std::vector<double>, kNumLines> weights;
  std::array<bool, kNumLines> line_ok{};
};

// Normal equations of the joint fit (c_x, c_y, beta, h_out, h_in) at the final iterate, with the
// weighted sum of squared residuals and the sum of weights: what the covariance needs.
struct NormalEquations {
  Eigen::Matrix<double, 5, 5> jtj;
  Eigen::Matrix<double, 5, 1> jtr;
  double ssr = 0.0, sum_w = 0.0;
};

// One frame's code read (qr_decode.cpp): what the read expects from the tracking and what it
// read. The stage's functions take it as an argument; CodeReader keeps one (read()) only for its
// storage, so that a frame allocates nothing. decode_qr resets every field; read_at_predicted_turn,
// whose result goes to the fix directly, only the code and the text.
struct QrRead {
  // The tracked landmark's codes (pointing into the CodeCache) and the turn its
  // predicted heading points to: empty and -1 without a trusted prediction.
  std::vector<QrExpected> expected;
  int predicted_turn = -1;
  std::string text;          // the payload read; empty when none was
  int search_attempts = 0;   // zxing search attempts (read_qr_search)
  bool centre_only = false;  // decode_guided's read came from the module centres alone
};

// Logo scores at the four 90-degree turns (turn q: forward axis = beta - q * 90 deg).
struct LogoScores {
  // -1 at a turn where the logo leaves the image, and at the turns not scored (logo_one_turn)
  std::array<double, 4> ncc{};
  int best_q = 0;
  double best = 0.0, margin = 0.0;  // best NCC, best minus second best
  bool clear = false;               // best above threshold and ahead of the second by the margin
};

// Shared helpers, inline: the logo and QR sampling call sample() thousands of times per frame
// (kept inlinable as when they shared one file; out of line the direction stage took 8 % longer).
inline Vec2 rot(Vec2 v, double a) {
  const double c = std::cos(a), s = std::sin(a);
  return {c * v.x - s * v.y, s * v.x + c * v.y};
}

inline double ncc(const std::vector<double>& a, const std::vector<double>& b) {
  const size_t n = std::min(a.size(), b.size());
  if (n < 2) return 0.0;
  double ma = 0, mb = 0;
  for (size_t i = 0; i < n; ++i) {
    ma += a[i];
    mb += b[i];
  }
  ma /= static_cast<double>(n);
  mb /= static_cast<double>(n);
  double sab = 0, saa = 0, sbb = 0;
  for (size_t i = 0; i < n; ++i) {
    sab += (a[i] - ma) * (b[i] - mb);
    saa += (a[i] - ma) * (a[i] - ma);
    sbb += (b[i] - mb) * (b[i] - mb);
  }
  // A flat sample set (no contrast) correlates with nothing.
  return saa > 1e-9 && sbb > 1e-9 ? sab / std::sqrt(saa * sbb) : 0.0;
}

// Fit covariance of (c_x, c_y, beta) from the joint fit's normal equations (covariance.cpp).
Eigen::Matrix3d fit_covariance(const NormalEquations& ne, int n_params, const VisionConfig& cfg);

// libapriltag's detector and family (apriltag.cpp), created with the localizer when the family is
// tag36h11: its tables take 0.1-0.35 s to build, which the first tag frame would otherwise pay.
struct TagDetector;
std::shared_ptr<TagDetector> make_tag_detector();

// What every stage reads and none writes: the configuration and the models the localizer was
// built with, and the scales derived from them once. Stages keep a const reference to it and own
// only their scratch storage, so a stage cannot change what another stage sees.
struct VisionSetup {
  VisionSetup(const VisionConfig& c, const CameraModel& m, const LandmarkGeometry& g,
              const LandmarkMap* mp);

  VisionConfig cfg;
  CameraModel cam;
  CameraModel cam_linear;  // same mount, one mm/px ratio, no distortion (Li et al.)
  LandmarkGeometry geom;
  const LandmarkMap* map = nullptr;
  double mm_per_px = 0.26;
  // Coarse level of the detection: factor, and border width, outer half and anchor in its pixels.
  int coarse_factor = 8;
  double coarse_w = 0, coarse_h = 0, coarse_anchor = 0;
  // Tag family: the pose stage fits only the outer edge of the border, whose inner edge is broken
  // by the data cells.
  bool outer_only = false;
  // metric_cam()'s floor mapping for the per-point loops.
  FloorProjector metric_floor{CameraModel{}};

  double now_ms() const { return cfg.now_ns ? static_cast<double>(cfg.now_ns()) * 1e-6 : 0.0; }
  Vec2 coarse_to_full(Vec2 c) const {
    const double f = coarse_factor;
    return {(c.x + 0.5) * f - 0.5, (c.y + 0.5) * f - 0.5};
  }
  Vec2 full_to_coarse(Vec2 p) const {
    const double f = coarse_factor;
    return {(p.x + 0.5) / f - 0.5, (p.y + 0.5) / f - 0.5};
  }
  const CameraModel& metric_cam() const {
    return cfg.metric == MetricMode::kCameraModel ? cam : cam_linear;
  }
  // Pixels of the landmark's page (LandmarkGeometry's u, v in mm) for the landmark at c_mm with
  // forward angle fwd: metric_floor.vehicle_to_pixel(transform({c_mm, fwd},
  // page_to_landmark(uv))), to rounding, with fewer operations per point (PlaneProjector).
  PlaneProjector page_projector(Vec2 c_mm, double fwd) const {
    const double co = std::cos(fwd), si = std::sin(fwd);
    // page_to_landmark(u, v) = (-v, -u), then the rotation by fwd.
    return metric_floor.plane(c_mm, {si, -co}, {-co, -si});
  }
  // Any predicted outer corner beyond the image (plus VisionConfig::outside_margin_mm).
  bool partly_outside(const cv::Mat& img, Vec2 c_px, double up) const;
  // The ring check's acceptance, shared by the coarse check (detect.cpp) and the full-image one
  // (predicted_detect.cpp).
  bool ring_accepted(int total, int ring_in, int ring_dark, int out_in, int out_dark) const;
  // Edge points as pixel rows covered (each collected point stands for edge_row_step rows): the
  // unit of min_points_per_line and min_points_total.
  int rows_covered(int points) const { return points * std::max(1, cfg.edge_row_step); }
};

}  // namespace agv::vision
