// Stages 1-2 without a search (predicted_detect.cpp, edge_probe.cpp, docs/design/tracking.md):
// a precise prediction places the pose stage's edge bands itself, after a ring check on the full
// image; a looser one is made precise by 1-D edge probes across the predicted sides. Owns the
// ring's and the probes' samples.
#pragma once

#include <array>
#include <cstdint>
#include <vector>

#include "agv/vision/tracking.hpp"
#include "square_fit.hpp"
#include "stage_common.hpp"

namespace agv::vision {

class PredictedDetector {
 public:
  // square: where the pose stage put the fitted square, for fit_agrees_with_prediction.
  PredictedDetector(const VisionSetup& s, const SquareFit& square) : setup(s), square_fit(square) {}

  // Every predicted outer corner within the share of the band the prediction is admitted with.
  bool prediction_places_bands(const SearchWindow& w) const;
  // The window whose ring check (or probes) is most convincing, as a detection; predicted_px:
  // where its centre was placed; probed: by the edge probes.
  bool detect_predicted(const cv::Mat& img, const std::vector<SearchWindow>& windows,
                        Detection* best, Vec2* predicted_px, bool* probed);
  // The ring check on the full image around the square (c, up): its grey levels and counts.
  bool ring_check_full(const cv::Mat& img, Vec2 c, double up, double* dark_level,
                       double* white_level, int* n_dark, int* n_samples);
  // The fitted centre lies where the prediction put it.
  bool fit_agrees_with_prediction(Vec2 predicted_px) const;
  // Edge probes across the predicted sides (edge_probe.cpp).
  bool probe_prediction(const cv::Mat& img, const SearchWindow& w, ProbedSquare* out);

 private:
  // The probes' geometry for one window (px), fixed by the prediction's reach.
  struct ProbePlan {
    double border_px = 0, half_px = 0;
    double reach = 0;        // of the corners' positions (window_sigmas sigma)
    double t_max = 0;        // probes at -t_max .. t_max along a side, from its middle
    double angle_reach = 0;  // of the heading
    double range = 0;        // of a side's place along a probe
    int n = 0;               // samples per probe
  };
  // Grey levels and ramps summed over the probes on the sides' lines.
  struct ProbeSums {
    double light = 0, ramp = 0, dark = 0;
  };
  bool plan_probes(const cv::Mat& img, const SearchWindow& w, ProbePlan* plan) const;
  void probe_side(const cv::Mat& img, const SearchWindow& w, const ProbePlan& plan, int k);
  bool fit_side(Line2* line, int* on_line, ProbeSums* sums);
  bool square_from_lines(const SearchWindow& w, const ProbePlan& plan,
                         const std::array<Line2, 4>& lines, const std::array<bool, 4>& have,
                         int n_sides, double* up, Vec2* c) const;
  bool probe_edge(const cv::Mat& img, Vec2 start, Vec2 step, int n, double border_px, int s_lo,
                  int s_hi, bool whole, ProbeEdge* edge);

  const VisionSetup& setup;
  const SquareFit& square_fit;
  // Grey levels of the full-image ring check, kept to reuse their storage.
  std::vector<int> ring_grey, outside_grey;
  // The edge probes' grey levels, edge points and line weights, likewise.
  std::vector<std::uint8_t> probe_grey;
  std::vector<Vec2> probe_pts;
  std::vector<ProbeEdge> probe_hits;
  std::vector<double> probe_w;
};

}  // namespace agv::vision
