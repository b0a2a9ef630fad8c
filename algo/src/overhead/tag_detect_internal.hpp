// The geometry under TagDetector (tag_detect.hpp): the outer edge of a tag's black square found
// along the normals of a guessed quadrilateral, least-squares lines, their corners and the 36
// cells read through the corners' homography. Private to algo/src/overhead.
#pragma once

#include <array>
#include <cstdint>
#include <opencv2/core.hpp>

#include "agv/common/geometry.hpp"

namespace agv::overhead::detect_detail {

struct Square {
  std::array<Vec2, 4> corners{};  // page order TL, TR, BR, BL
  double corner_sigma_px = 0.0;
  double edge_rms_px = 0.0;  // worst side's RMS distance of its edge points from its line
};

struct RefineParams {
  double band_px = 3.0;      // the edge is searched within +-band_px of the guessed side
  double min_step = 10.0;    // smallest dark-to-bright step of one edge point (8-bit units)
  double max_rms_px = 0.8;   // largest RMS of a side's points from its line
  double max_end_gap = 0.1;  // share of a side that may lack edge points at either end
  double spacing_px = 1.0;   // between edge points along a side
};

// Refines `guess` (page order, distorted pixels): each side's outer edge (dark inside, bright
// outside) searched along the side's normal, a line fitted to it, the corners where
// neighbouring lines meet. False when a side keeps too few edge points, they leave more than
// max_end_gap of the side without an edge at either end, a line's RMS exceeds max_rms_px or the
// corners leave the image.
bool refine_square(const cv::Mat& gray, const std::array<Vec2, 4>& guess, const RefineParams& rp,
                   Square* out);

struct Cells {
  std::uint64_t code = 0;  // row-major from the page's top-left data cell, 1 = white
  double contrast = 0.0;   // median white margin minus median black border (8-bit units)
};
// Reads the 6 x 6 data cells of the square (page order corners); false when a sample leaves the
// image or the corners are degenerate.
bool read_cells(const cv::Mat& gray, const std::array<Vec2, 4>& corners, Cells* out);

// Bilinear sample at (x, y) (pixel centres at integers); false outside the image.
bool sample_bilinear(const cv::Mat& gray, double x, double y, double* v);

}  // namespace agv::overhead::detect_detail
