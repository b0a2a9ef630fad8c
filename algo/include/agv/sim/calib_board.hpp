// Simulated views of a planar calibration board (chessboard or ChArUco) through the project's
// camera model, for testing the intrinsics calibration (agvloc-desk calibrate intrinsics,
// agvloc-desk sim-board). Pure: no file I/O, no clocks, no dependency on OpenCV's aruco module
// (the desk tool fills the marker cells from the aruco dictionary).
#pragma once

#include <array>
#include <cstdint>
#include <opencv2/core.hpp>
#include <vector>

#include "agv/common/camera_model.hpp"
#include "agv/sim/render.hpp"

namespace agv::sim {

// A printed planar board in its own frame (mm, z = 0 on the printed face). Squares lie on a grid
// from the origin: square (i, j) covers [i*s, (i+1)*s) x [j*s, (j+1)*s). Markers (ChArUco) are
// squares of cells inside the white squares, described by their four corners exactly as the
// calibration library lists them, so the rendering is consistent with the detector's geometry.
struct CalibBoard {
  int squares_x = 0;
  int squares_y = 0;
  double square_mm = 0.0;
  std::vector<std::uint8_t> square_black;  // squares_y rows of squares_x, 1 = black square
  struct Marker {
    // Corner 0 = top-left of the marker image, 1 = top-right, 2 = bottom-right, 3 = bottom-left.
    std::array<Vec2, 4> corners;
    int cells = 0;                    // cells per side, including the black border
    std::vector<std::uint8_t> black;  // cells x cells, row 0 along corners 0-1, 1 = black
  };
  std::vector<Marker> markers;
  double margin_mm = 0.0;  // white paper around the squares

  // Ink at a board point: kOutside beyond the paper, else kWhite or kBlack.
  PageInk at(Vec2 p) const;
  // The paper outline (squares plus margin): min and max corner.
  Vec2 paper_min() const { return {-margin_mm, -margin_mm}; }
  Vec2 paper_max() const {
    return {squares_x * square_mm + margin_mm, squares_y * square_mm + margin_mm};
  }
  // True when the marker corners run clockwise in a frame with y down (seen non-mirrored by a
  // camera whose image axes follow the board's x and y), false when the board's y axis points up
  // (a board library whose frame has y up; Debian's OpenCV 4.6 CharucoBoard has y down). Boards
  // without markers: true.
  bool y_down() const;
};

// A plain chessboard of squares_x x squares_y squares ((squares_x-1) x (squares_y-1) inner
// corners), square (0, 0) black.
CalibBoard make_chessboard(int squares_x, int squares_y, double square_mm, double margin_mm);

// Board pose in the camera frame, OpenCV convention: X_cam = R * X_board + t (mm). The camera
// looks along +z, image x right, image y down.
struct BoardPose {
  cv::Matx33d R = cv::Matx33d::eye();
  cv::Vec3d t{0.0, 0.0, 200.0};
};

struct BoardImageOptions {
  // Sub-samples per axis on pixels that straddle an edge (n*n per pixel); others take one value.
  int supersample = 16;
  double paper_white = 215.0;  // 8-bit values at full illumination
  double ink_black = 30.0;
  double background = 90.0;    // what lies behind the board
  double blur_sigma_px = 0.0;  // Gaussian defocus blur after rendering (0 = none)
  double noise_sigma = 0.0;    // additive Gaussian sensor noise, 8-bit units (0 = none)
  // The board bowed off its plane by this much at its centre, its corners on the plane (a print
  // glued on foam board is rarely flatter than half a millimetre); the calibration takes it flat.
  double bow_mm = 0.0;
  std::uint64_t seed = 1;  // noise seed
};

// Renders the board through the camera (pinhole + the intrinsics' Brown-Conrady distortion;
// pixel (0,0) covers [-0.5, 0.5]^2) as an 8-bit gray image of the intrinsics' size. Empty Mat
// when the intrinsics are unusable (size or focal length not positive).
cv::Mat render_board_view(const CalibBoard& board, const CameraIntrinsics& intrinsics,
                          const BoardPose& pose, const BoardImageOptions& options);

struct BoardPoseOptions {
  double near_mm = 150.0;  // board centre distance range along the optical axis
  double far_mm = 300.0;
  double max_tilt_deg = 35.0;  // tilt about the board's x and y axes, uniform in +-max
  double min_visible = 1.0;    // fraction of inner corners that must be inside the image
  double border_px = 4.0;      // "inside" = at least this far from the image edge
};

// n deterministic poses for a seed: the board centre is placed over a 3x3 grid of image
// positions in turn (so the corners cover the whole image, borders included), at a distance
// drawn from [near, far], tilted and spun about its normal, always seen non-mirrored. A pose is
// kept when at least min_visible of the inner corners are imaged inside the image (with
// min_visible = 1 also the whole paper, as a chessboard detector needs); empty when no such pose
// is found for some view (board too large for the image at these distances).
std::vector<BoardPose> calib_view_poses(const CalibBoard& board, const CameraIntrinsics& intrinsics,
                                        int n, std::uint64_t seed, const BoardPoseOptions& options);

// The inner (chessboard) corners of the board in the board frame, row by row (x fastest).
std::vector<Vec2> board_inner_corners(const CalibBoard& board);

}  // namespace agv::sim
