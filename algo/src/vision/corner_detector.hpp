// Stages 1-2 of the pipeline (detect.cpp, track_detect.cpp): the coarse level,
// its adaptive binarization, the corner templates and the hypotheses they vote
// for, refined and ring-checked; over the whole frame, over the tracking
// windows' bounding box, or from the windows' predicted corners alone. Owns the
// templates and every per-frame image and list of the search.
#pragma once

#include <cstdint>
#include <vector>

#include "agv/vision/tracking.hpp"
#include "stage_common.hpp"

namespace agv::vision {

class CornerDetector {
 public:
  // Renders the corner templates for the configured rotations and coarse level.
  explicit CornerDetector(const VisionSetup& s);

  // The whole image (or a coarse-aligned part of it): the best ring-checked
  // hypothesis. found_corner: some corner template reached the threshold;
  // corner_score: the best NCC.
  bool detect(const cv::Mat& img, Detection* best, bool* found_corner, double* corner_score);
  // detect() on the bounding box of the windows, in frame coordinates;
  // whole_frame: that box was the whole frame (the full search need not
  // follow).
  bool detect_in_windows(const cv::Mat& img, const std::vector<SearchWindow>& windows,
                         Detection* best, bool* found_corner, double* corner_score,
                         bool* whole_frame);
  // Tracked detection from the windows' predicted centre and angle
  // (track_detect.cpp).
  bool detect_tracked(const cv::Mat& img, const std::vector<SearchWindow>& windows, Detection* best,
                      double* corner_score);

 private:
  bool detect_tracked_in(const cv::Mat& img, const SearchWindow& w, Detection* best,
                         double* corner_score, int* n_dark);
  void tracked_corner_peaks(const SearchWindow& w, double pcx, double pcy, int radius);
  bool tracked_hypothesis(const SearchWindow& w, Hypothesis* out);
  void compute_orient4_in(int x0, int y0, int x1, int y1);
  void build_templates();
  void render_corner(double a, int r, cv::Mat* t) const;
  double ncc_at(const std::vector<float>& tz, int tsz, int x, int y) const;
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

  const VisionSetup& setup;
  std::vector<cv::Mat> templates;  // CV_32F corner templates
  std::vector<double> template_angles;
  cv::Mat coarse, binary, isum, isq, best_score, best_rot;
  std::vector<std::vector<float>> templates_zm;  // zero-mean, unit-norm
  std::vector<float> templates_t;
  int template_lanes = 16;
  cv::Mat coarse_f;  // CV_32F copy of `coarse` for the NCC kernel
  cv::Mat orient4;   // CV_32FC2 per coarse pixel: |g|^2-weighted (cos 4a, sin 4a)
                     // of the gradient
  std::vector<std::uint32_t> row_sums;
  std::vector<std::uint16_t> threshold_sums;
  std::vector<std::vector<float>> fine_templates;  // 1-degree steps
  std::vector<CornerPeak> peaks;
  std::vector<Hypothesis> hyps;
};

}  // namespace agv::vision
