// Stage 4 of the pipeline and the direction decision of stage 5 (direction.cpp): the logo
// template correlated at the turns of the fitted square, and the turn the logo and the code's
// orientation agree on. Owns the template and its sampling storage.
#pragma once

#include <vector>

#include "stage_common.hpp"

namespace agv::vision {

class DirectionStage {
 public:
  explicit DirectionStage(const VisionSetup& s);

  // Logo NCC at turn q of the fitted square (turn q's forward axis is side q's normal); -1 where
  // the logo leaves the image.
  double logo_ncc(const cv::Mat& img, Vec2 c_mm, double beta, int q);
  // Logo NCC at the four turns.
  LogoScores logo_scores(const cv::Mat& img, Vec2 c_mm, double beta);
  // The final turn, or -1 (kDirectionAmbiguous).
  int decide_direction(const LogoScores& logo, int qr_q) const;

 private:
  void build_logo();

  const VisionSetup& setup;
  std::vector<double> logo_template, logo_samples;
  std::vector<Vec2> logo_page_pts;
};

}  // namespace agv::vision
