// Building blocks of the pose stage (Li et al. eq. 1-7, Yang et al. eq. 9-11), exposed so each
// stage can be tested on its own. Image coordinates: x right, y down, pixel centres at integers.
#pragma once

#include <cmath>
#include <cstddef>
#include <cstdint>
#include <span>
#include <vector>

#include "agv/common/geometry.hpp"

namespace cv {
class Mat;
template <typename T>
class Rect_;
using Rect = Rect_<int>;
}  // namespace cv

namespace agv::vision {

// Prewitt gradient (Li et al. eq. 2-3) of the interior pixel at p in an 8-bit image whose rows are
// `step` bytes apart: gx = right column minus left column, gy = bottom row minus top row (sums of
// three). The one kernel every gradient of the pipeline goes through.
inline void prewitt_at(const std::uint8_t* p, std::ptrdiff_t step, int* gx, int* gy) {
  *gx = (p[1 - step] + p[1] + p[1 + step]) - (p[-1 - step] + p[-1] + p[-1 + step]);
  *gy = (p[step - 1] + p[step] + p[step + 1]) - (p[-step - 1] + p[-step] + p[-step + 1]);
}

// Prewitt gradients along one strip of pixels (the pose stage's edge bands, pose.cpp), with which
// of them reach a squared magnitude. The strip's pixel q (0 <= q < n) is at p + (q + 1) * dj; its
// neighbours across the strip are di away. g_j is the gradient along the strip (the pixel after
// minus the pixel before, summed across), g_i the one across it: for a strip along a row (dj = 1,
// di = step) g_j = gx and g_i = gy of prewitt_at, along a column (dj = step, di = 1) the reverse.
// strong[q] is 1 where g_j^2 + g_i^2 >= thr2, else 0. The same integers as prewitt_at, from
// per-pixel sums and differences across the strip that three neighbouring pixels share, in
// vectors of 16 lanes: most of a band's pixels are below the threshold, so this screen is most of
// the band's work. Entries past n are scratch. With dj = 1 and read_past_end, each of the strip's
// three lines is read in whole 16-byte chunks, up to 15 bytes past its end: the caller promises
// those bytes are inside the image's buffer (a later row). The buffers only grow.
struct StripGradients {
  std::vector<std::int16_t> sum, diff;  // across the strip
  std::vector<std::int16_t> g_j, g_i;
  std::vector<std::uint8_t> strong;  // 0 or 1, in whole groups of 8
};
void strip_gradients(const std::uint8_t* p, std::ptrdiff_t dj, std::ptrdiff_t di, int n, int thr2,
                     bool read_past_end, StripGradients* s);

// Prewitt gradients (Li et al. eq. 1-3) of gray8 inside roi, written to CV_16SC1 images of the
// roi's size: gx = right column minus left column, gy = bottom row minus top row (sums of three).
// Pixels on the image border get 0. roi is clipped to the image.
void prewitt(const cv::Mat& gray8, const cv::Rect& roi, cv::Mat* gx, cv::Mat* gy);

// Side of the border a gradient belongs to, by gradient direction (Li et al. figure 7). The
// landmark's page-up axis points along image angle up_angle_rad = atan2(dy, dx) (y down); side k
// has its outward normal at up_angle_rad + k * 90 degrees: 0 up, 1 right, 2 down, 3 left
// (as seen on the page). A dark-to-bright gradient points outward on the outer edge of side k and
// inward (class k+2) on its inner edge.
enum class EdgeClass : std::int8_t { kUp = 0, kRight = 1, kDown = 2, kLeft = 3, kNone = -1 };

// True when the gradient (gx, gy) points within atan(tan_tol) of the unit direction dir: the
// class test of the pipeline's edge strips (a tangent instead of an angle: no atan2 per pixel).
inline bool gradient_within(double gx, double gy, Vec2 dir, double tan_tol) {
  const double along = gx * dir.x + gy * dir.y;
  return along > 0 && std::abs(-gx * dir.y + gy * dir.x) <= tan_tol * along;
}

// Returns the class whose direction is within tol_rad (< 45 degrees) of the gradient direction,
// else kNone; the same test as gradient_within. A zero gradient is kNone.
EdgeClass classify_gradient(double gx, double gy, double up_angle_rad, double tol_rad);

// Line n . p = d with |n| = 1.
struct Line2 {
  double nx = 0.0, ny = 1.0, d = 0.0;
  double angle_rad() const;  // direction of the line, atan2(-nx, ny), in (-pi, pi]
};

// Weighted total-least-squares line with its uncertainty from the residuals.
struct LineFit {
  Line2 line;
  int n = 0;
  double sum_w = 0.0;
  double rms = 0.0;         // weighted rms of the normal residuals
  double var_angle = 0.0;   // variance of the line direction (rad^2)
  double var_offset = 0.0;  // variance of d at the centroid (length^2)
  Vec2 centroid;
  double extent = 0.0;  // spread of the points along the line (max - min projection)
};

// weights may be empty (all 1). Returns false for fewer than 2 points or degenerate input.
bool fit_line_tls(std::span<const Vec2> pts, std::span<const double> weights, LineFit* out);

// Li et al. eq. 5-6: ordinary least squares y = k x + b; returns false when all x are equal.
bool fit_line_ols(std::span<const Vec2> pts, double* k, double* b);

// Tukey-biweight IRLS on top of fit_line_tls: weights are recomputed from the residuals with the
// scale sigma = 1.4826 * MAD (floored at min_sigma). With ransac_iterations > 0 the start is the
// two-point line with the most points within ransac_tol (deterministic sampling), so that up to
// about half of the points may be outliers (an occluder's edge parallel to the border). w_out
// (same size as pts) receives the final weights. Returns false when the fit fails.
bool fit_line_robust(std::span<const Vec2> pts, double tukey_c, double min_sigma, int iterations,
                     std::span<double> w_out, LineFit* out, int ransac_iterations = 0,
                     double ransac_tol = 0.0);

// Li et al. eq. 7: mean of the four dip angles after removing the 90-degree offsets; here with
// any number of angles already reduced to a common axis (radians).
double mean_angle(std::span<const double> angles_rad);
// Yang et al. eq. 10-11: weighted mean with k_i = sum y^2 / (sum y^2 - sum (y - Y)^2).
double weighted_angle_000(std::span<const double> angles_rad, std::span<const double> k_weights);
// Yang et al. eq. 11 weight for one edge: sum_y2 = sum of y_j^2, ssr = sum of (y_j - Y_j)^2.
double weight_000(double sum_y2, double ssr);

// Reduces a line angle to the representative within +-45 degrees of ref_rad modulo 90 degrees.
double reduce_angle_90(double angle_rad, double ref_rad);

}  // namespace agv::vision
