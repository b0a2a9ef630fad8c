// Stage 3 of the pipeline (pose.cpp; its covariance, stage 6, in covariance.cpp): the border's
// edge points in bands around the detected square, robust lines through them and the joint fit
// of the known square, whose normal equations give the covariance. Owns the edge points, the fit's
// buffers and the fitted square's pixels (for the overlay and the tracking's agreement check).
#pragma once

#include <array>
#include <vector>

#include "agv/vision/edges.hpp"
#include "stage_common.hpp"

namespace agv::vision {

// The last fitted square in pixels.
struct SquarePixels {
  std::array<Vec2, 8> corners_px{};  // outer 0..3, inner 4..7
  Vec2 centre_px;
  double up_angle_px = 0;  // image angle of one border normal, as detected
};

class SquareFit {
 public:
  explicit SquareFit(const VisionSetup& s) : setup(s) {}

  // Edge points, lines and joint fit around the detected square (centre c_px, border normal at
  // image angle up, border-to-paper contrast): the square's centre and side-0 normal angle in the
  // metric frame and the covariance of (c_x, c_y, beta).
  FixStatus pose(const cv::Mat& img, Vec2 centre_px, double up_angle, double contrast,
                 EdgePoints* pts, LandmarkFix* out, Vec2* c_mm, double* beta, Eigen::Matrix3d* cov);
  // n_params: 3 (centre and heading, sizes as printed), 4 (and the outer half size: the tag
  // family's outer-only fit), 5 (and both half sizes).
  bool joint_fit(PoseMethod method, int n_params, EdgePoints* pts, SquareModel* m,
                 NormalEquations* ne);
  void keep_overlay_geometry(const SquareModel& m);

  // The edge points' storage, reused from frame to frame: pose() takes it as an argument.
  EdgePoints& edge_points() { return points_; }
  const EdgePoints& edge_points() const { return points_; }
  const SquarePixels& pixels() const { return pixels_; }

 private:
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

  const VisionSetup& setup;
  EdgePoints points_;
  std::vector<double> residual_buf, scratch_buf;
  StripGradients strip;
  SquarePixels pixels_;
};

}  // namespace agv::vision
