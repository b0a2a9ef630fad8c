// Camera intrinsics calibration from views of a ChArUco board or a chessboard (agvloc-desk
// calibrate intrinsics; docs/guide/camera.md). Detection and estimation are OpenCV's (aruco
// detectMarkers + interpolateCornersCharuco, findChessboardCorners + cornerSubPix,
// calibrateCamera); this file adds what a commissioning tool needs around them: blurred views
// are rejected by name, the reprojection error is reported per view, the image coverage is
// checked and drawn, and no result is written from too few usable views.
#pragma once

#include <array>
#include <cstdint>
#include <opencv2/core.hpp>
#include <string>
#include <vector>

#include "agv/common/camera_model.hpp"
#include "agv/sim/calib_board.hpp"

namespace agv::desk::calib {

enum class BoardType { kCharuco, kChessboard };

// The printed board. Defaults fit the default 640x480 floor camera (166 x 125 mm of floor at
// 200 mm): an 11 x 8 ChArUco board of 10 mm squares with 7.5 mm 4x4 markers (110 x 80 mm,
// 70 inner corners), which fills half to most of the image at 150..280 mm.
struct BoardSpec {
  BoardType type = BoardType::kCharuco;
  int squares_x = 11;  // squares along the board's x axis
  int squares_y = 8;
  double square_mm = 10.0;
  double marker_mm = 7.5;                  // ChArUco only
  std::string dictionary = "DICT_4X4_50";  // ChArUco only: an OpenCV predefined dictionary name
};

// True when this build has OpenCV's aruco module (ChArUco boards); chessboards always work.
bool have_charuco();
// Checks the board description; false with *error naming the offending field.
bool validate_board(const BoardSpec& spec, std::string* error);
// The board for the simulator, from the same aruco board object the detector uses (marker
// positions and bit patterns), so simulated views match the detector's geometry exactly.
bool make_sim_board(const BoardSpec& spec, double margin_mm, sim::CalibBoard* out,
                    std::string* error);
// Board-frame coordinates (mm) of the corner with detector index id (ChArUco corner id, or the
// chessboard corner index row by row).
bool board_corner(const BoardSpec& spec, int id, cv::Point3f* out);

struct Options {
  int min_views = 10;                // fewer usable views: no result
  int min_corners = 8;               // per view
  double max_blur_px = 2.0;          // edge blur (Gaussian sigma estimate, px) above this: rejected
  double max_rms_px = 0.5;           // overall RMS reprojection error above this: no result
  double view_outlier_factor = 3.0;  // a view with RMS > factor x median RMS is named
  // calibrateCamera model: the default is the five-coefficient model agv::CameraModel uses.
  bool fix_k3 = false;
  bool zero_tangent = false;
  bool fix_aspect = false;           // fx = fy
  bool fix_principal_point = false;  // at the image centre
};

struct View {
  std::string name;
  cv::Size size;
  bool detected = false;
  bool used = false;
  std::string reject_reason;  // empty when used
  double blur_px = 0.0;       // edge blur estimate (Gaussian sigma, px); 0 when not measured
  int dropped = 0;            // corners dropped as not clean X-junctions (refine_saddle)
  std::vector<int> ids;       // corner ids (ChArUco id or chessboard index)
  std::vector<cv::Point2f> image_points;
  std::vector<cv::Point3f> object_points;
  double rms_px = 0.0;  // per-view RMS reprojection error, after calibration
};

struct Coverage {
  int cols = 8, rows = 6;             // counting grid over the image
  std::vector<int> counts;            // rows x cols, corners of the used views per cell
  double covered = 0.0;               // fraction of cells with at least one corner
  std::vector<std::string> warnings;  // empty quadrants and border bands, by name
};

struct Result {
  bool ok = false;
  std::string error;  // why there is no result (names the minimum, the views ...)
  CameraIntrinsics intrinsics;
  std::array<double, 9> stddev{};  // fx fy cx cy k1 k2 p1 p2 k3 (OpenCV's estimate)
  double rms_px = 0.0;
  int usable = 0;
  int corners = 0;
  std::vector<View> views;
  Coverage coverage;
  std::vector<std::string> warnings;
};

// Edge blur of a gray image inside the convex hull of `points` (the whole image when fewer than
// three): the Gaussian sigma (px) of a blurred step with the observed contrast (2nd..98th
// percentile) and peak gradient (mean of the strongest 1 % of gradients). A sharp,
// anti-aliased edge gives about 0.8 px; defocus raises it.
double edge_blur_px(const cv::Mat& gray, const std::vector<cv::Point2f>& points);

// Refines X-corners (chessboard saddle points) in place: the image is smoothed with a Gaussian
// of `sigma` px and a quadratic surface is fitted around each point over a (2 radius + 1)^2
// window, moving the point to the saddle until it settles. Points where no saddle is found keep
// their position; returns false when any did. With `asymmetry`, each point's RMS
// point-asymmetry of the smoothed image about the refined centre, relative to the local
// contrast (near 0 for a clean X-junction; 1 when not refined).
bool refine_saddle(const cv::Mat& gray, std::vector<cv::Point2f>* points, int radius, double sigma,
                   std::vector<double>* asymmetry = nullptr);

// Finds the board in one 8-bit gray image and measures its sharpness. The view is marked
// detected (points filled) or carries a reject_reason naming what failed.
View detect_view(const cv::Mat& gray, const std::string& name, const BoardSpec& spec,
                 const Options& options);

// Rejects blurred and sparse views, calibrates from the rest, fills per-view RMS and the
// coverage. ok = false with `error` when there are too few usable views, the views differ in
// size, or the RMS is above the limit.
Result calibrate(std::vector<View> views, const BoardSpec& spec, const Options& options);

// Coverage of the used views' corners over the image (also called by calibrate).
Coverage measure_coverage(const std::vector<View>& views, cv::Size size);
// SVG picture of the coverage: the image frame, the counting grid (empty cells shaded), every
// corner seen (one colour per view), quadrant and border-band lines.
std::string coverage_svg(const Result& result);
// Human-readable report: per-view table (corners, blur, RMS or reason), totals, warnings.
std::string report_text(const Result& result);
// The configuration snippet (docs/guide/config.md): `camera:` width/height and the `intrinsics:`
// section, with a comment header (source, views, RMS).
std::string config_snippet(const Result& result, const std::string& source);

// The board as SVG at exact physical scale (user units are millimetres; print at 100 %), with
// a caption naming the spec outside the margin.
std::string board_svg(const BoardSpec& spec, const sim::CalibBoard& board);

// Simulated board views for tests (agvloc-desk sim-board; implemented in cmd_sim_board.cpp).
struct SimBoardSet {
  CameraIntrinsics camera;        // the true camera (default_sim_board_set: with distortion)
  int views = 30;                 // views of normal sharpness
  int blurred = 3;                // additional deliberately blurred views, spread through
  double blurred_sigma_px = 3.0;  // their Gaussian blur
  double blur_sigma_px = 0.5;     // mild blur of the normal views
  double noise_sigma = 1.0;       // sensor noise, 8-bit units
  double bow_mm = 0.0;            // the board's bow at its centre (sim::BoardImageOptions)
  double max_tilt_deg = 35.0;
  double margin_mm = -1.0;  // paper margin; < 0: one square (chessboard), half (ChArUco)
  std::uint64_t seed = 1;
};
struct SimView {
  std::string name;  // view_NNN.png
  bool blurred = false;
  cv::Mat image;
};
// 640x480, fx 771.5, fy 768.2, cx 323.4, cy 236.8, k1 -0.12, k2 0.08, p1 0.0006, p2 -0.0004.
SimBoardSet default_sim_board_set();
// Renders the views; false with *error for a bad board or a board that cannot be kept in view.
bool simulate_board_views(const BoardSpec& spec, const SimBoardSet& set, std::vector<SimView>* out,
                          std::string* error);
// The lens `calibrate intrinsics` finds through `camera` from `views` simulated views (no
// deliberately blurred ones) of an 11 x 8 ChArUco board of 60 mm squares (660 x 480 mm, a board
// for cameras metres away) bowed bow_mm at its centre: what a site's calibration leaves, for the
// evaluations. ok false with the error when the views cannot be made or nothing calibrates.
Result calibrate_simulated_board(const CameraIntrinsics& camera, int views, double bow_mm,
                                 std::uint64_t seed);
// truth.yaml: the true camera as a configuration file (camera + intrinsics sections), with the
// blurred views named in a comment.
std::string truth_yaml(const SimBoardSet& set, const std::vector<SimView>& views);

}  // namespace agv::desk::calib
