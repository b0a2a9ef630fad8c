// From a tag's corner pixels in a ceiling camera to the vehicle's pose on the floor
// (docs/design/overhead.md): every corner's ray meets the tray plane (known height above the
// floor); the square of known size fitted to the four points gives the centre and heading (paper
// 000 eq. 9-12 in the image; here in the site frame, free of perspective), and its covariance:
// the errors of the four edge lines the corners are the meeting points of (each line's offset
// and angle, recovered from the detector's corner pixel sigma; two corners on a line move
// together, which is where the heading's error comes from), carried through the rays, plus the
// camera's calibrated pose sigma (CeilingCamera::position_sigma_mm, angle_sigma_rad) and the
// tray's tilt and height sigma (TrayPlaneSigma). Pure.
#pragma once

#include <array>
#include <cstdint>

#include "agv/common/geometry.hpp"
#include "agv/site/site.hpp"

namespace agv::overhead {

struct TagFix {
  Pose2 pose;  // the tag's centre and page-up direction in the site frame = the vehicle's pose
  // Covariance of (x_mm, y_mm, theta_rad), row-major.
  std::array<double, 9> cov{};
  // The part of cov common to consecutive fixes (a bias, which averaging fixes does not reduce,
  // as the tracker treats it): a tag fix's camera pose sigma, a tray box's shared side offsets
  // (TrayFitParams::side_offset_bias_share).
  std::array<double, 9> cov_camera{};
  double size_error_rel = 0.0;  // fitted side / tag_size_mm - 1 (calibration or height error)
  double residual_mm = 0.0;     // RMS distance of the four corners from the fitted square
  // The camera (its index) that made the fix: fixes of one camera share its bias, fixes of two
  // differ by both biases (FleetTracker). -1: unknown, taken as the previous fix's camera.
  std::int32_t source = -1;
};

// How far a real tray's top departs from the level plane at its nominal height that the fix
// assumes (a bent tray, a load off centre, worn wheels, a floor step). Seen off the camera's
// axis, a tilt turns the tag's image (up to tan(view angle) * tilt / 2 of heading) and a height
// error moves it (tan(view angle) * error); both stay while the vehicle drives, so they go into
// TagFix::cov_camera, the part the tracker does not average down. 0: a level tray at its height.
struct TrayPlaneSigma {
  double tilt_rad = 0.0;   // per axis (the plane's slope along the site's x and along its y)
  double height_mm = 0.0;  // the tag's centre above or below FleetAgv::tray_height_mm
};

// A fitted square this far off the tag's size is not the tag (a wrong height, a wrong camera).
constexpr double kDefaultMaxSizeErrorRel = 0.08;

// The fix on a level plane taken as exact. False when a corner's ray does not meet the plane in
// front of the camera, the intrinsics are invalid, or the fitted square is more than
// max_size_error_rel off tag_size_mm.
bool tag_fix_on_plane(const site::CeilingCamera& cam, const std::array<Vec2, 4>& corners_px,
                      double corner_sigma_px, double plane_height_mm, double tag_size_mm,
                      TagFix* out, double max_size_error_rel = kDefaultMaxSizeErrorRel);

// The fix of fleet vehicle `agv`'s tag: its tray height and tag size, its tray's surveyed tilt
// (FleetAgv::tray_roll_rad, tray_pitch_rad: the corners' rays meet the tilted plane, turned with
// the fitted heading) and what the tray may still depart from that (sigma). False as
// tag_fix_on_plane, and for a sigma that is negative or not finite.
bool tag_fix_on_tray(const site::CeilingCamera& cam, const std::array<Vec2, 4>& corners_px,
                     double corner_sigma_px, const site::FleetAgv& agv, const TrayPlaneSigma& sigma,
                     TagFix* out);

// Site-frame point -> distorted pixel of the camera; false behind it or for non-finite input.
bool site_to_pixel(const site::CeilingCamera& cam, double x_mm, double y_mm, double z_mm, Vec2* px);
// Distorted pixel -> the point where its ray meets the plane z = plane_height_mm.
bool pixel_to_plane(const site::CeilingCamera& cam, Vec2 px, double plane_height_mm, Vec2* xy_mm);

}  // namespace agv::overhead
