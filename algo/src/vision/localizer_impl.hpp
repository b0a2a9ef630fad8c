// Private to algo/src/vision: the state LandmarkLocalizer keeps between frames and the stage
// functions that share it. One file per stage (numbers: docs/design/vision.md "Pipeline"):
//   detect.cpp      1-2 pyramid, adaptive binarization, corner templates, hypotheses, ring check
//   pose.cpp        3   Prewitt edge bands and classes, robust line fits, centre and heading
//   direction.cpp   4-5 logo template at the four turns, cross-check with the QR orientation
//   qr_decode.cpp   5   guided module sampling, zxing fallback, payload and map check
//   apriltag.cpp    tag36h11 family: libapriltag detection and id, then the pose stage above
//   covariance.cpp  6   fit covariance from the normal equations, vehicle-in-world propagation
//   track_detect.cpp    1-2 with a trusted prediction: the predicted landmark's corners only
//   predicted_detect.cpp 1-2 with a precise prediction: none, the prediction places the bands
//   edge_probe.cpp      1-2 with a looser one: 1-D edge searches across the predicted sides
//   landmark_localizer.cpp  run(): the stages in order, the public class, the debug overlay
// What Impl's members are: the configuration and the models it was built with, storage reused from
// frame to frame (a frame allocates nothing), the tracking windows planned for the frame, and the
// last frame's geometry for the overlay. A stage's result is its return value or an argument:
// the fitted square, the logo scores, the code read (QrRead), the edge points (EdgePoints) and the
// map-guided identity are not members, so what each stage reads and writes shows in its signature.
// QrRead and EdgePoints have one instance in Impl only to keep their buffers' storage.
#pragma once

#include <Eigen/Core>
#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <map>
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
#include "agv/vision/map_identity.hpp"
#include "agv/vision/qr_grid.hpp"
#include "agv/vision/tracking.hpp"

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
// read. The stage's functions take it as an argument; run() keeps one (LandmarkLocalizer::Impl::
// qr_read) only for its storage, so that a frame allocates nothing. decode_qr resets every field;
// read_at_predicted_turn, whose result goes to the fix directly, only the code and the text.
struct QrRead {
  // The tracked landmark's codes (pointing into the localizer's map_codes) and the turn its
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

struct LandmarkLocalizer::Impl {
  VisionConfig cfg;
  CameraModel cam;
  CameraModel cam_linear;  // same mount, one mm/px ratio, no distortion (paper 001)
  LandmarkGeometry geom;
  const LandmarkMap* map = nullptr;

  // Detection.
  int coarse_factor = 8;
  double coarse_w = 0, coarse_h = 0, coarse_anchor = 0;  // border width, outer half, anchor
  std::vector<cv::Mat> templates;                        // CV_32F corner templates
  std::vector<double> template_angles;
  cv::Mat coarse, binary, isum, isq, best_score, best_rot;
  std::vector<std::vector<float>> templates_zm;  // zero-mean, unit-norm
  std::vector<float> templates_t;
  int template_lanes = 16;
  cv::Mat coarse_f;  // CV_32F copy of `coarse` for the NCC kernel
  cv::Mat orient4;   // CV_32FC2 per coarse pixel: |g|^2-weighted (cos 4a, sin 4a) of the gradient
  std::vector<std::uint32_t> row_sums;
  std::vector<std::uint16_t> threshold_sums;
  std::vector<std::vector<float>> fine_templates;  // 1-degree steps
  std::vector<CornerPeak> peaks;
  std::vector<Hypothesis> hyps;

  // QR.
  cv::Mat qr_small, qr_blur, qr_sharp;
  QrSamples qr_samples;
  // decode_guided's grids at an unclear logo: four turns, two sizes, and each grid's turn.
  std::array<QrSamples, 8> qr_grids;
  std::array<int, 8> qr_grid_turns{};
  std::vector<float> qr_fill;
  QrGridScratch qr_scratch;
  QrRead qr_read;  // storage only: the stages take it as an argument (QrRead)

  // Pose.
  EdgePoints edge_points;  // storage only: stage 3 takes it as an argument (EdgePoints)
  std::vector<double> logo_template, logo_samples, residual_buf, scratch_buf;
  std::vector<Vec2> logo_page_pts;
  StripGradients strip;

  // Kept for the overlay.
  bool have_overlay = false;
  std::array<Vec2, 8> corners_px{};  // outer 0..3, inner 4..7
  Vec2 centre_px;
  int quadrant = 0;
  double up_angle_px = 0;

  double mm_per_px = 0.26;

  // Tag family (apriltag.cpp): the pose stage fits only the outer edge of the border, whose inner
  // edge is broken by the data cells.
  bool outer_only = false;
  std::shared_ptr<TagDetector> tag;

  // Tracking (docs/design/tracking.md): windows of the last frame's prediction.
  WindowPlanner planner;
  std::vector<SearchWindow> windows;
  // Grey levels of the full-image ring check (predicted_detect.cpp), kept to reuse their storage.
  std::vector<int> ring_grey, outside_grey;
  // The edge probes' grey levels, edge points and line weights (edge_probe.cpp), likewise.
  std::vector<std::uint8_t> probe_grey;
  std::vector<Vec2> probe_pts;
  std::vector<ProbeEdge> probe_hits;
  std::vector<double> probe_w;

  Impl(const VisionConfig& c, const CameraModel& m, const LandmarkGeometry& g,
       const LandmarkMap* mp);

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
  // metric_cam()'s floor mapping for the per-point loops (set by the constructor).
  FloorProjector metric_floor{CameraModel{}};
  // Pixels of the landmark's page (LandmarkGeometry's u, v in mm) for the landmark at c_mm with
  // forward angle fwd: metric_floor.vehicle_to_pixel(transform({c_mm, fwd},
  // page_to_landmark(uv))), to rounding, with fewer operations per point (PlaneProjector).
  PlaneProjector page_projector(Vec2 c_mm, double fwd) const {
    const double co = std::cos(fwd), si = std::sin(fwd);
    // page_to_landmark(u, v) = (-v, -u), then the rotation by fwd.
    return metric_floor.plane(c_mm, {si, -co}, {-co, -si});
  }

  // run(): the stages in order (landmark_localizer.cpp).
  FixStatus run(const cv::Mat& img, const Prediction& pred, LandmarkFix* out);
  FixStatus measure(const cv::Mat& img, const Detection& det, double corner_score, double t0,
                    LandmarkFix* out, Vec2* c_mm, double* beta, Eigen::Matrix3d* cov);
  bool partly_outside(const cv::Mat& img, Vec2 c_px, double up) const;
  bool detect_in_windows(const cv::Mat& img, Detection* best, bool* found_corner,
                         double* corner_score, bool* whole_frame);
  // Tracked detection from the windows' predicted centre and angle (track_detect.cpp).
  bool detect_tracked(const cv::Mat& img, Detection* best, double* corner_score);
  bool detect_tracked_in(const cv::Mat& img, const SearchWindow& w, Detection* best,
                         double* corner_score, int* n_dark);
  void compute_orient4_in(int x0, int y0, int x1, int y1);
  // Detection from a precise prediction (predicted_detect.cpp).
  bool prediction_places_bands(const SearchWindow& w) const;
  bool detect_predicted(const cv::Mat& img, Detection* best, Vec2* predicted_px, bool* probed);
  bool ring_check_full(const cv::Mat& img, Vec2 c, double up, double* dark_level,
                       double* white_level, int* n_dark, int* n_samples);
  bool fit_agrees_with_prediction(Vec2 predicted_px) const;
  // Edge probes across the predicted sides (edge_probe.cpp).
  bool probe_prediction(const cv::Mat& img, const SearchWindow& w, ProbedSquare* out);
  bool probe_edge(const cv::Mat& img, Vec2 start, Vec2 step, int n, double border_px, int s_lo,
                  int s_hi, bool whole, ProbeEdge* edge);
  void fill_result(const Pose2& world_landmark, Vec2 c_mm, double beta, int q_final,
                   const Eigen::Matrix3d& cov, LandmarkFix* out) const;

  // Stages 1-2, binarization and detection (detect.cpp).
  void build_templates();
  void render_corner(double a, int r, cv::Mat* t) const;
  double ncc_at(const std::vector<float>& tz, int tsz, int x, int y) const;
  bool detect(const cv::Mat& img, Detection* best, bool* found_corner, double* corner_score);
  bool make_coarse(const cv::Mat& img);
  void score_corner_templates();
  void find_corner_peaks();
  void merge_peaks();
  bool select_hypothesis(Detection* best, double* corner_score);
  void refine_hypothesis(Hypothesis* h) const;
  Vec2 rematch_corner(const CornerPeak& p, double a, double* weight) const;
  void compute_orient4();
  void refine_coarse_angle(Hypothesis* h) const;
  bool ring_check(const Hypothesis& h, double* dark_level, double* white_level, int* n_dark);
  bool ring_accepted(int total, int ring_in, int ring_dark, int out_in, int out_dark) const;

  // Stage 3, pose (pose.cpp; its covariance, stage 6, in covariance.cpp).
  FixStatus pose(const cv::Mat& img, Vec2 centre_px, double up_angle, double contrast,
                 EdgePoints* pts, LandmarkFix* out, Vec2* c_mm, double* beta, Eigen::Matrix3d* cov);
  int collect(const cv::Mat& img, Vec2 centre_px, double up_angle, double band_px, double thr,
              EdgePoints* pts);
  // Edge points as pixel rows covered (each collected point stands for edge_row_step rows): the
  // unit of min_points_per_line and min_points_total.
  int rows_covered(int points) const { return points * std::max(1, cfg.edge_row_step); }
  int collect_line(const cv::Mat& img, Vec2 c, Vec2 nk, double h, Vec2 g_dir, double band,
                   int thr2_int, double tan_tol, std::vector<Vec2>* dst);
  int fit_lines(EdgePoints* pts, std::array<LineFit, kNumLines>* fits);
  double line_heading(const EdgePoints& pts, const std::array<LineFit, kNumLines>& fits,
                      double beta0) const;
  Vec2 paper_corner_a_centre(const EdgePoints& pts, double beta) const;
  bool intersections_centre(const std::array<LineFit, kNumLines>& fits, Vec2* c) const;
  Vec2 joint_start_centre(const EdgePoints& pts, const std::array<LineFit, kNumLines>& fits,
                          const SquareModel& m) const;
  void reweight_joint(const SquareModel& m, EdgePoints* pts);
  void accumulate_normal_equations(const EdgePoints& pts, const SquareModel& m,
                                   NormalEquations* ne) const;
  // n_params: 3 (centre and heading, sizes as printed), 4 (and the outer half size: the tag
  // family's outer-only fit), 5 (and both half sizes).
  bool joint_fit(PoseMethod method, int n_params, EdgePoints* pts, SquareModel* m,
                 NormalEquations* ne);
  void keep_overlay_geometry(const SquareModel& m);

  // Tag family: detection and id by libapriltag, pose by the stage above (apriltag.cpp).
  FixStatus run_tag(const cv::Mat& img, const Prediction& pred, LandmarkFix* out);
  FixStatus tag_from_detector(const cv::Mat& img, LandmarkFix* out);
  FixStatus tag_from_prediction(const cv::Mat& img, LandmarkFix* out);
  FixStatus tag_from_corners(const cv::Mat& img, double t0_ms, LandmarkFix* out);
  FixStatus consistent_square(EdgePoints* pts, Vec2* c_mm, double* beta, Eigen::Matrix3d* cov,
                              LandmarkFix* out);
  // The 6 x 6 data cells read at turn q of the fitted square (row-major, 1 = black); false when
  // a cell leaves the image.
  bool read_tag_cells(const cv::Mat& img, Vec2 c_mm, double beta, int q, double half_mm,
                      std::array<std::uint8_t, 36>* cells);
  int tag_code_distance(const cv::Mat& img, Vec2 c_mm, double beta, int q, double half_mm,
                        std::uint32_t id);
  std::vector<double> tag_margin;  // read_tag_cells' margin samples, kept for their storage
  double side_offset_mm(const EdgePoints& pts, int k, Vec2 c, double beta, double h);
  FixStatus drop_inconsistent_side(EdgePoints* pts, Vec2* c_mm, double* beta, Eigen::Matrix3d* cov,
                                   LandmarkFix* out);

  // Stage 4, logo, and the direction decision of stage 5 (direction.cpp).
  void build_logo();
  LogoScores logo_scores(const cv::Mat& img, Vec2 c_mm, double beta);
  double logo_ncc(const cv::Mat& img, Vec2 c_mm, double beta, int q);
  int logo_and_code(const cv::Mat& img, const Prediction& pred, Vec2 c_px, double up, Vec2 c_mm,
                    double beta, LogoScores* logo, double* logo_ms, QrRead* rd, LandmarkFix* out);
  int decide_direction(const LogoScores& logo, int qr_q) const;

  // Stage 5, QR decode (qr_decode.cpp).
  int decode_qr(const cv::Mat& img, const Prediction& pred, Vec2 c_px, double up, Vec2 c_mm,
                double beta, const LogoScores& logo, QrRead* rd, LandmarkFix* out);
  int read_code(const cv::Mat& img, Vec2 c_px, double up, Vec2 c_mm, double beta,
                const LogoScores& logo, QrRead* rd, LandmarkFix* out);
  void expect_tracked_code(const Prediction& pred, Vec2 c_mm, double beta, QrRead* rd);
  int read_at_predicted_turn(const cv::Mat& img, const Prediction& pred, Vec2 c_mm, double beta,
                             QrRead* rd, LandmarkFix* out);
  bool read_centres(const cv::Mat& img, Vec2 c_mm, double beta, int q, QrCodeBook* book,
                    QrRead* rd);
  bool code_cut_at_every_turn(const cv::Mat& img, Vec2 c_mm, double beta,
                              const LogoScores& logo) const;
  int decode_guided(const cv::Mat& img, Vec2 c_mm, double beta, const LogoScores& logo, QrRead* rd);
  bool read_qr_search(const cv::Mat& img, Vec2 centre_px, double up_angle, std::string* text,
                      double* qr_up_angle, bool* qr_ok, int* attempts_made);
  bool sample_qr(const cv::Mat& img, Vec2 c_mm, double fwd, int n, QrSamples* s,
                 bool centre_only = false);
  bool fill_missing_modules(QrSamples* s);
  FixStatus check_payload(const std::string& text, LandmarkFix* out, Pose2* world_landmark);

  // Stage 5c, map-guided identity of an unread code (map_identity_stage.cpp).
  // Both forms of a mapped landmark's code: [0] the full payload, [1] the id-only one.
  struct MapCodes {
    std::array<QrBits, 2> bits;
    std::array<std::string, 2> text;
    // zxing decodes the bits back to the text (qr_bits_decode_to): 0 not yet checked, 1 yes,
    // -1 no. Checked on first use as an expected code; only a 1 is offered to the verified read.
    std::array<int, 2> reads_back{0, 0};
  };
  // Encoded on first use (docs/design/large_maps.md): a site's map has tens of thousands of codes,
  // of which a frame needs a few. Emptied between frames once it holds kMaxCachedCodes landmarks.
  std::map<std::uint32_t, MapCodes> map_codes;
  MapCodes* codes_of(std::uint32_t id);
  // The mapped codes for the verified read (qr_grid.hpp QrCodeBook): every one of a small map
  // (built by the constructor), else those of the landmarks nearest the predicted vehicle (none
  // without a prediction; zxing reads those codes, to the same text). book_ids: whose codes.
  QrCodeBook map_book;
  std::vector<std::uint32_t> book_ids;
  bool full_book = false;
  void update_code_book(const Prediction& pred);
  QrCodeBook* code_book() { return map ? &map_book : nullptr; }
  void prune_map_codes();
  std::vector<std::uint8_t> identity_bits;
  std::vector<std::pair<std::uint32_t, const QrBits*>> identity_others;
  std::vector<const LandmarkMapEntry*> near_entries;
  bool map_identity(const cv::Mat& img, const Prediction& pred, Vec2 c_mm, double beta,
                    const Eigen::Matrix3d& cov, const LogoScores& logo, Pose2* world_landmark,
                    int* turn, std::uint32_t* id);
};

}  // namespace agv::vision
