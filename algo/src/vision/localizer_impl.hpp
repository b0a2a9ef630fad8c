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
#include "code_cache.hpp"
#include "code_reader.hpp"
#include "direction_stage.hpp"
#include "map_identity_stage.hpp"
#include "stage_common.hpp"

namespace agv::vision {

struct LandmarkLocalizer::Impl : VisionSetup {
  // Detection.
  std::vector<cv::Mat> templates;  // CV_32F corner templates
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

  // Pose.
  EdgePoints edge_points;  // storage only: stage 3 takes it as an argument (EdgePoints)
  std::vector<double> residual_buf, scratch_buf;
  StripGradients strip;

  // Kept for the overlay.
  bool have_overlay = false;
  std::array<Vec2, 8> corners_px{};  // outer 0..3, inner 4..7
  Vec2 centre_px;
  int quadrant = 0;
  double up_angle_px = 0;

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

  // Stages 4 and 5a: the logo and the code read, composed (landmark_localizer.cpp).
  int logo_and_code(const cv::Mat& img, const Prediction& pred, Vec2 c_px, double up, Vec2 c_mm,
                    double beta, LogoScores* logo, double* logo_ms, QrRead* rd, LandmarkFix* out);

  // The stages that own their state (built after the members they reference).
  DirectionStage direction{*this};
  CodeCache codes{*this, planner.index()};
  CodeReader code_reader{*this, codes};
  MapIdentityStage identity{*this, planner.index(), codes, code_reader};
};

}  // namespace agv::vision
