// The tag family's own stage (tag_reader.cpp): libapriltag's quad search and id, the tag's data
// cells read at a fitted square, and the outer-only square's consistency checks. Owns the detector
// (its tables take 0.1-0.35 s to build: made with the localizer) and the reads' storage; the
// composition of these with detection and pose for a tag floor is apriltag.cpp.
#pragma once

#include <array>
#include <cstdint>
#include <memory>
#include <vector>

#include "square_fit.hpp"
#include "stage_common.hpp"

namespace agv::vision {

// libapriltag's strongest quad: its id, centre and forward probe in pixels, the image angle of one
// border normal, and the border-to-margin contrast (valid when sampled).
struct TagQuad {
  std::uint32_t id = 0;
  Vec2 c_px, fwd_px;
  double up = 0;
  bool sampled = false;  // some border and some margin samples were inside the image
  double contrast = 0;
};

class TagReader {
 public:
  // tag36h11: 6 x 6 data cells; two corrected bits (minimum Hamming distance 11, so a 2-bit
  // correction cannot turn one printed id into another).
  static constexpr int kDataCells = 6;
  static constexpr int kBitsCorrected = 2;
  using Cells = std::array<std::uint8_t, kDataCells * kDataCells>;

  // The detector is made only when the floor is a tag floor.
  TagReader(const VisionSetup& s, SquareFit& fit);

  // libapriltag on the whole frame; false when it found no tag.
  bool strongest_quad(const cv::Mat& img, TagQuad* quad);
  // The outer-only square's checks after the pose stage: sides that disagree, and the size gate.
  FixStatus consistent_square(EdgePoints* pts, Vec2* c_mm, double* beta, Eigen::Matrix3d* cov,
                              LandmarkFix* out);
  // The 6 x 6 data cells read at turn q of the fitted square (row-major, 1 = black); false when
  // a cell leaves the image.
  bool read_tag_cells(const cv::Mat& img, Vec2 c_mm, double beta, int q, double half_mm,
                      Cells* cells);
  // Cells that differ from tag id's code at turn q; -1 when unreadable or not an id.
  int tag_code_distance(const cv::Mat& img, Vec2 c_mm, double beta, int q, double half_mm,
                        std::uint32_t id);
  // The id and turn whose code is nearest the cells read at the four turns (best_q -1: none).
  void nearest_code(const std::array<Cells, 4>& read, const bool readable[4], int* best_q,
                    int* best_d, std::uint32_t* best_id) const;

 private:
  double side_offset_mm(const EdgePoints& pts, int k, Vec2 c, double beta, double h);
  FixStatus drop_inconsistent_side(EdgePoints* pts, Vec2* c_mm, double* beta, Eigen::Matrix3d* cov,
                                   LandmarkFix* out);

  const VisionSetup& setup;
  SquareFit& square;
  std::shared_ptr<TagDetector> tag;
  // Grey levels of the border ring and the margin (read_tag_cells), side offsets
  // (side_offset_mm): kept for their storage.
  std::vector<double> tag_ring, tag_margin, side_offsets;
};

}  // namespace agv::vision
