// A vehicle's pose from its tray's outline when a parcel hides its tag (Yang et al. eq. 5-8: the
// tray's oriented box; here the box is fitted, not learned). In the window around the predicted
// tray, edge pixels (Prewitt, thinned along the gradient, sub-pixel) are carried onto the tray
// plane, where the tray is an exact rectangle of known length and width. The edges' directions
// give the candidate headings, a vote of both sides of each axis the candidate centres; each
// candidate is refined briefly and the one that explains most of the outline (and of the tray's
// side face, on the sides facing the camera) is refined by robust least squares of the centre and
// heading, with a covariance from the fit's residuals and a per-side line error. Parcels crossing
// an edge only remove that edge's points: two adjacent sides are enough with the known size. A
// rectangle looks the same turned half a turn, so the heading is taken nearest the prediction, and
// the fit is refused when the prediction's heading sigma cannot tell the two apart. Pure.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <opencv2/core.hpp>
#include <string>

#include "agv/common/geometry.hpp"
#include "agv/overhead/tag_fix.hpp"
#include "agv/site/site.hpp"

namespace agv::overhead {

struct TrayFitParams {
  // Edge pixels: magnitude floor of the Prewitt gradient (sums of three, 8-bit units).
  double min_gradient = 40.0;
  // The window covers the predicted tray widened by sigma_window times the prediction's sigma
  // plus margin_mm.
  double sigma_window = 3.0;
  double margin_mm = 40.0;
  // Refused when the prediction's position sigma exceeds this (the window would hold
  // neighbours), or its heading's sigma_window-sigma exceeds a third of the rectangle's symmetry
  // period (180 degrees, 90 for a square tray): the prediction could not resolve the ambiguity.
  double max_position_sigma_mm = 250.0;
  // An edge point joins a side when its gradient is within this of the side's normal.
  double class_tol_rad = 0.17;
  // A side counts as seen when its points within on_line_px of its line cover this fraction of
  // its length (a real edge's thinned points lie within a few tenths of a pixel of it; texture
  // or noise scatters over the band around it).
  double min_side_coverage = 0.3;
  double on_line_px = 0.5;
  // Sides that must be seen (2..4; one of front/rear and one of left/right always). Two adjacent
  // sides place the box with the known size, but a parcel's lifted outline stands in for one of
  // them far more often than for one of three (rendered random parcels: a fifth of the two-side
  // fits lay outside their covariance, 6 % of the three-side fits, none of the four-side ones).
  int min_sides_seen = 3;
  // Depth of the tray's side face below its top edge (the plate or rim; 0: none): on the sides
  // facing the camera the face ends in a second, parallel line further out, which a box fitted
  // to it would leave the real edge inside; the box that explains both lines wins.
  double rim_depth_mm = 30.0;
  // Refused when two opposite seen sides are further from the known size than this (mm, or
  // pixels on the plane when larger): parcel edges taken for the tray's.
  double max_size_error_mm = 12.0;
  double max_size_error_px = 1.5;
  // Covariance: each residual counts as one of edge_correlation neighbours (the gradient kernel
  // and the blur smear one step over a few pixels), and each side's line has an offset error of
  // side_offset_sigma_px (edge model, plate face, shading) and a turn that moves its ends by as
  // much, on top.
  double edge_correlation = 3.0;
  double side_offset_sigma_px = 0.25;
  // The share of the sides' offset and turn variance that the next frames share (the same plate
  // face, shading and edge model a few pixels on): the fix carries it as a bias
  // (TagFix::cov_camera), which the tracker adds to its output instead of averaging it down. 0:
  // every frame's independent (the tracker's sigma then falls below its error), 1: all bias (the
  // filter follows each box's frame-to-frame scatter). docs/design/overhead.md.
  double side_offset_bias_share = 0.25;
  int iterations = 8;
};

// Why a fit was refused, for the counters a site reads when covered vehicles coast: a parcel
// that hides the tray's outline (kSidesHidden, kNoOutline) needs another cue, a prediction too
// loose (kUncertain) a shorter gap between fixes.
enum class TrayRefusal : std::uint8_t {
  kNone,
  kBadInput,     // image, parameters, tray size, prediction not finite or not positive definite
  kUncertain,    // the prediction's position or heading sigma is beyond what a fit can resolve
  kOutOfView,    // the predicted tray is outside the image or behind the camera
  kNoOutline,    // no tray outline in the window, too few edge points, or beyond reach
  kSidesHidden,  // too few sides seen: the outline is mostly covered
  kSizeMismatch,
  kAmbiguous,  // the fitted heading is a third of the symmetry period from the prediction
};
inline constexpr std::size_t kTrayRefusalCount = 8;
// Stable names (metrics labels): none, bad_input, uncertain_prediction, out_of_view,
// no_outline, sides_hidden, size_mismatch, ambiguous_heading.
const char* to_string(TrayRefusal r);

struct TrayFix {
  TagFix fix;  // centre and heading in the site frame with their covariance: the tracker's input
  TrayRefusal refusal = TrayRefusal::kNone;  // why fit_tray returned false
  int sides_seen = 0;                        // sides with enough support (2..4)
  std::array<double, 4> coverage{};      // front, left, rear, right: fraction of the side covered
  std::array<int, 4> points{};           // edge points kept per side
  double residual_mm = 0.0;              // weighted RMS of the edge points' distances
  double size_error_mm[2] = {0.0, 0.0};  // length, width: fitted minus known (0 when unseen)
  double heading_from_prediction_rad = 0.0;  // |fitted - predicted|, after resolving
};

// Empty string when the parameters are usable, otherwise what is wrong (names the field).
std::string validate(const TrayFitParams& p);

// Fits vehicle `agv`'s tray in camera `cam`'s 8-bit gray frame around the predicted pose
// (predicted_cov: x_mm, y_mm, theta_rad, row-major). True with *out; false with the reason in
// *why (when not null) for bad input (image not 8-bit gray of the camera's size, non-finite or
// non-positive-definite prediction, bad sizes or parameters), a prediction too uncertain, a tray
// outside the image, too few sides seen (one of front/rear and one of left/right are needed), a
// size that does not match the known tray, or a heading more than a third of the symmetry period
// from the prediction. out->refusal names the reason (kNone on success).
bool fit_tray(const cv::Mat& gray, const site::CeilingCamera& cam, const site::FleetAgv& agv,
              const Pose2& predicted, const std::array<double, 9>& predicted_cov,
              const TrayFitParams& p, TrayFix* out, std::string* why = nullptr);

}  // namespace agv::overhead
