// The second camera's mount (ranging_camera.mount_*) from a drive past the site's rack landmarks
// while the floor camera localizes the vehicle (docs/guide/ranging.md, "Calibrating the mount").
// A mount error is the one error of the rack fixes that no rack landmark can show: a camera
// turned by 1 deg turns every bearing by 1 deg, and a fix from them moves the vehicle with it
// (docs/design/ranging.md, "Switched on"). The floor landmarks fix the vehicle's pose to a few
// tenths of a millimetre; the rack landmarks seen from those poses then fix the camera on it.
//
// Model: unknowns are the mount (x, y, z, roll, pitch, yaw; ranging::RangingMount) and, per
// frame, the vehicle pose (x, y, theta), tied to the floor localizer's pose at the frame's time by
// its covariance (the fused track is exact only at a floor fix; between fixes it is what the
// track's sigma says). Residual per landmark corner: its pinhole projection through the pose and
// the mount minus the observed undistorted corner, over corner_sigma_px, under a Huber loss; the
// mount also has a loose prior at the configured one (prior_sigma_*), so a drive that leaves an
// axis unobserved reports that axis's sigma near the prior's instead of failing to solve.
#pragma once

#include <array>
#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include "agv/common/camera_model.hpp"
#include "agv/common/geometry.hpp"
#include "agv/ranging/range_models.hpp"
#include "agv/site/site.hpp"

namespace agv::desk::rcal {

// One landmark read in one frame of the second camera, with the floor localizer's pose then.
struct MountSighting {
  std::int64_t t_ns = 0;                         // frames share a pose by t_ns
  Pose2 vehicle;                                 // site frame
  std::array<double, 3> vehicle_sigma{};         // x_mm, y_mm, theta_rad (1 sigma)
  std::size_t landmark_index = 0;                // into the walls given to the solve
  std::array<Vec2, 4> corners_undistorted_px{};  // page order TL TR BR BL
  double corner_sigma_px = 0.0;                  // the observer's; 0: Options::corner_sigma_px
};

enum class Error : std::uint8_t {
  kNone,
  kTooFewSightings,  // fewer than min_frames frames or min_landmarks landmarks
  kSolveFailed,      // no convergence or a singular covariance
  kPoorlyObserved,   // solved, but a sigma exceeds its limit (the drive did not show that axis)
};
const char* to_string(Error e);  // "too-few-sightings", ...

struct Options {
  double corner_sigma_px = 0.5;   // one corner coordinate, independent (the observer's corners)
  double robust_sigmas = 3.0;     // Huber scale in corner sigmas: further off counts linearly
  double prior_sigma_mm = 100.0;  // loose prior on each offset at the initial mount
  double prior_sigma_rad = 0.1;   // and on each angle
  // The lens calibration's doubt (1 sigma; ranging_camera.focal_sigma_rel and
  // calibration_sigma_px): the focal length's relative error and the principal point's shift,
  // solved as nuisance parameters with these priors so that the mount's sigma carries them (a
  // focal length off by 0.1 % reads every depth 0.1 % off, which the offset along the optical
  // axis would take up). 0: the lens is exact.
  double focal_sigma_rel = 0.0;
  double principal_sigma_px = 0.0;
  int min_frames = 10;
  int min_landmarks = 3;
  // Limits of the result's sigmas; above them the result is kPoorlyObserved (still filled).
  double max_sigma_mm = 3.0;
  double max_sigma_rad = 0.002;  // 0.11 deg
  // A landmark whose corner RMS exceeds both reject_min_px and reject_ratio times the median
  // landmark's is left out and the mount solved again, one at a time (surveyed wrong or moved).
  double reject_min_px = 2.0;
  double reject_ratio = 5.0;
};

struct LandmarkResidual {
  std::uint32_t id = 0;
  int sightings = 0;
  double rms_px = 0.0;  // corner reprojection RMS (pixel distance) at the solved mount
  bool rejected = false;
};

struct Result {
  Error error = Error::kNone;
  std::string message;
  ranging::RangingMount mount;
  // 1 sigma of x, y, z (mm), roll, pitch, yaw (rad): Ceres' covariance (the per-frame poses
  // marginalised), scaled by the residuals' reduced chi-square when above 1.
  std::array<double, 6> sigma{};
  double rms_px = 0.0;  // corner RMS over the sightings used
  double reduced_chi2 = 0.0;
  int frames_used = 0;
  int sightings_used = 0;
  std::vector<LandmarkResidual> landmarks;  // by first sighting
};

// Solves the mount. intrinsics: the camera's (fx, fy, cx, cy of the undistorted corners); walls:
// the site's wall landmarks (MountSighting::landmark_index indexes them).
Result solve_mount(const CameraIntrinsics& intrinsics, std::span<const site::WallLandmark> walls,
                   std::span<const MountSighting> sightings, const ranging::RangingMount& initial,
                   const Options& opt = {});

// A wall landmark's black-square corners in the site frame, page order TL TR BR BL (page up =
// site +z, page right = to the right of a viewer facing the printed face).
std::array<std::array<double, 3>, 4> wall_corners_site(const site::WallLandmark& w);

// The undistorted pixel of a site point seen from the vehicle pose through the mount (pinhole);
// false behind the camera. For tests and the residuals.
bool project_undistorted(const CameraIntrinsics& k, const ranging::RangingMount& mount,
                         const Pose2& vehicle, const std::array<double, 3>& p_site, Vec2* px);

}  // namespace agv::desk::rcal
