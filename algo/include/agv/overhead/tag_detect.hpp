// Finding the vehicles' tags in a ceiling camera's image (docs/design/overhead.md). Two paths:
//  - search: libapriltag (tag36h11) on an image window (a track's window, an area, the whole
//    image), its corners refined by least-squares lines on the outer edge of the black square,
//    the ids decoded against the whole family with few corrected bits (a new track must be sure);
//  - predicted: where a track predicts its tag, the square placed at the predicted corners,
//    refined the same way, its 36 cells read and decoded against the area's ids only
//    (tag_code.hpp), so a tag with more bit errors than libapriltag corrects is still read.
// Pure (no I/O, no clocks); a detector is thread-compatible (one per thread).
#pragma once

#include <array>
#include <cstdint>
#include <memory>
#include <opencv2/core.hpp>
#include <vector>

#include "agv/common/geometry.hpp"

namespace agv::overhead {

struct TagDetectParams {
  // libapriltag's quad_decimate: 1 keeps 40 px tags findable; 2 halves the search cost when tags
  // are large.
  double quad_decimate = 1.0;
  // libapriltag's min_white_black_diff (8-bit units): its 4 x 4 tiles with less spread are not
  // searched. A printed tag under a ceiling camera spans 100 and more; at libapriltag's default
  // (5) the floor's texture was clustered too, most of a window's cost (5x on 256 x 256 windows
  // of rendered 60 px tags, the same tags found).
  int quad_min_white_black_diff = 40;
  // Bits libapriltag may correct on the search path (global decode, new tracks): 2 keeps a wrong
  // id out (tag36h11's distance of 11 leaves 9 bits between a corrected code and any other id).
  int global_bits_corrected = 2;
  // Half width of the band around each predicted or detected side searched for the edge (px).
  double edge_band_px = 3.0;
  // Predicted path: how far the real square may be from the predicted corners (px).
  double predicted_search_px = 8.0;
  // Smallest black-to-white contrast along the border (8-bit units) for a square to count.
  double min_contrast = 20.0;
  // Largest RMS distance of edge points from their fitted line (px).
  double max_edge_rms_px = 0.8;
};

// One tag found in one image.
struct TagObservation {
  // Outer corners of the black square, distorted pixels, page order: top-left, top-right,
  // bottom-right, bottom-left (page up = the vehicle's +x).
  std::array<Vec2, 4> corners_px{};
  double corner_sigma_px = 0.0;  // 1-sigma per corner coordinate, from the edge fits' residuals
  std::uint64_t code = 0;        // the 36 cells as read, in page orientation
  std::uint32_t id = 0;
  int hamming = 0;
  int margin = 0;           // DecodeResult::margin
  bool restricted = false;  // decoded on the predicted path against an area's ids
  double contrast = 0.0;    // mean border contrast (8-bit units)
};

class TagDetector {
 public:
  explicit TagDetector(const TagDetectParams& params = {});
  ~TagDetector();
  TagDetector(const TagDetector&) = delete;
  TagDetector& operator=(const TagDetector&) = delete;

  // Search path on `window` (clipped to the image) of an 8-bit gray image.
  std::vector<TagObservation> detect(const cv::Mat& gray, const cv::Rect& window) const;
  // The same on `window` shrunk `decimation` times (area averaging): libapriltag's cost goes
  // with the pixels, and a large tag is found as well at a fraction of its size. Each tag found
  // is refined and read at full resolution from its scaled corners, and kept only when that read
  // decodes to the same id against the whole family within global_bits_corrected (as the search
  // path's own). decimation <= 1, or a window that would shrink under a few cells: detect().
  std::vector<TagObservation> detect(const cv::Mat& gray, const cv::Rect& window,
                                     int decimation) const;
  // Predicted path: the tag expected at predicted_corners_px (page order). False when no square
  // of enough contrast and straight edges lies there or the cells decode to none of allowed_ids.
  bool detect_predicted(const cv::Mat& gray, const std::array<Vec2, 4>& predicted_corners_px,
                        const std::vector<std::uint32_t>& allowed_ids, TagObservation* out) const;
  const TagDetectParams& params() const { return p_; }

 private:
  struct Impl;
  TagDetectParams p_;
  std::unique_ptr<Impl> impl_;
};

// The shortest side of a tag's four corners (px, page order).
double shortest_side_px(const std::array<Vec2, 4>& corners_px);

// The shrink factor for a window whose smallest tag has this shortest side: floor(side /
// decimated_side_px), clamped to [1, max_decimation] (1 for a side that is not positive).
int search_decimation(double side_px, double decimated_side_px, int max_decimation);

// A tag's own window: its corners' bounding box grown by max(16 px, half its side), clipped to
// the image (where the search path looks again for a tag placed from elsewhere).
cv::Rect own_window(const std::array<Vec2, 4>& corners_px, const cv::Size& image);

}  // namespace agv::overhead
