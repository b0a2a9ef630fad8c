// Rendering of any camera in a site (docs/design/site_render.md): ceiling cameras looking down at
// the fleet (each vehicle's tray with its tag36h11, parcels on some trays, clutter on the floor)
// and cameras on a vehicle looking at landmarks printed on racks. The scene is planar polygons in
// 3-D (floor, extruded obstacles, vehicle bodies and trays, parcels, clutter, wall landmarks);
// every image sample takes the nearest surface along its ray, so parcels hide tags and racks hide
// landmarks. Pure: no file I/O, no clocks.
#pragma once

#include <array>
#include <cstdint>
#include <opencv2/core.hpp>
#include <string>
#include <vector>

#include "agv/common/camera_model.hpp"
#include "agv/common/geometry.hpp"
#include "agv/sim/render.hpp"
#include "agv/site/site.hpp"

namespace agv::sim {

struct Vec3 {
  double x = 0.0, y = 0.0, z = 0.0;
};

// Where a camera on a vehicle sits: optical centre in the vehicle frame (x forward, y left, z up,
// mm), looking along yaw_rad (counter-clockwise from the vehicle's +x) tilted down by pitch_rad
// and rolled by roll_rad about the optical axis (positive: image turns clockwise as seen).
struct VehicleCameraMount {
  double x_mm = 0.0, y_mm = 0.0, z_mm = 1000.0;
  double yaw_rad = 0.0;
  double pitch_rad = 0.0;
  double roll_rad = 0.0;
};

// A 6-DoF pinhole camera with OpenCV distortion. Pose: camera frame (x image right, y image down,
// z optical axis) in the site frame, p_site = R * p_cam + t.
struct RenderCamera {
  CameraIntrinsics intrinsics;
  std::array<double, 9> r_site_cam{1, 0, 0, 0, -1, 0, 0, 0, -1};  // row-major
  std::array<double, 3> t_site_cam_mm{0, 0, 6000};

  static RenderCamera from_ceiling(const site::CeilingCamera& cam);
  static RenderCamera on_vehicle(const CameraIntrinsics& intrinsics, const Pose2& vehicle_site,
                                 const VehicleCameraMount& mount);
};

// Site points -> distorted pixels (the renderer's own model: pinhole, then OpenCV's distortion).
// ok[i] = 0 where the point is not in front of the camera (z <= 1 mm) or not finite; its pixel is
// then (NaN, NaN). Image bounds are not checked.
std::vector<Vec2> project_points(const RenderCamera& cam, const std::vector<Vec3>& points_site,
                                 std::vector<std::uint8_t>* ok = nullptr);

// One vehicle's state at the frame's exposure mid-time: pose of its reference point, forward
// speed and yaw rate (the motion blur moves it along a circular arc during the exposure).
struct AgvState {
  Pose2 pose;
  double v_mps = 0.0;
  double omega_radps = 0.0;
  // The tray top (and its tag) tilted about its centre, which stays at the tray's height: roll
  // about the vehicle's x, then pitch about its y (a bent tray, a load off centre, a floor step),
  // beyond the site file's surveyed tilt (FleetAgv::tray_roll_rad, tray_pitch_rad; the two add).
  double tray_roll_rad = 0.0, tray_pitch_rad = 0.0;
};

// The vehicle's pose dt_s seconds later (circular arc at constant v and omega).
Pose2 advance_agv_pose(const AgvState& s, double dt_s);

// A box on a tray, in the vehicle frame (it moves with the vehicle).
struct Parcel {
  std::size_t agv = 0;            // index into the fleet
  double x_mm = 0.0, y_mm = 0.0;  // centre on the tray, vehicle frame
  double yaw_rad = 0.0;           // relative to the vehicle
  double length_mm = 300.0, width_mm = 300.0, height_mm = 200.0;
  double grey = 150.0;  // reflectance, 8-bit units at full illumination
};

enum class ClutterKind : std::uint8_t { kPerson, kPallet };
// Something standing on the floor: a person (an octagonal prism of the given size) or a pallet
// (a box).
struct Clutter {
  ClutterKind kind = ClutterKind::kPallet;
  double x_mm = 0.0, y_mm = 0.0, yaw_rad = 0.0;
  double length_mm = 1200.0, width_mm = 800.0, height_mm = 150.0;
  double grey = 120.0;
};

struct SiteScene {
  site::Site site;
  std::vector<AgvState> agvs;  // one per site.fleet entry, same order
  std::vector<Parcel> parcels;
  std::vector<Clutter> clutter;
  FloorTexture floor;
  double paper_white = 215.0;  // printed white at full illumination (8-bit)
  double ink_black = 30.0;
  double tray_grey = 95.0;        // tray outside the tag's page
  double body_grey = 70.0;        // vehicle body
  double background_grey = 40.0;  // rays that meet nothing (above the horizon)
};

// Parcels on about loaded_fraction of the vehicles (deterministic per seed): 1 or 2 boxes of
// 150..500 mm side and 80..400 mm height, random grey, somewhere on the tray (so some cover part
// of the tag, some all of it, some none). Replaces scene->parcels.
void add_random_parcels(SiteScene* scene, double loaded_fraction, std::uint64_t seed);
// People and pallets at random free floor positions (inside the outline, clear of obstacles and
// vehicles by 300 mm). Replaces scene->clutter. Fewer are placed when no free spot is found.
void add_random_clutter(SiteScene* scene, int people, int pallets, std::uint64_t seed);
// n vehicle poses at random free positions (inside the outline, clear of obstacles by radius_mm
// plus clearance, apart from each other by twice that), random headings. Fewer when the site is
// too full.
std::vector<Pose2> random_free_poses(const site::Site& site, int n, double radius_mm,
                                     std::uint64_t seed);

struct SiteRenderParams {
  // Sub-samples per axis on pixels where the surface or the print changes (n*n per pixel).
  int edge_supersample = 4;
  // Motion blur: vehicles move during exposure_s (centred on the frame time), seen at
  // blur_instants instants, on pixels whose surface changes during the exposure only.
  double exposure_s = 0.0;
  int blur_instants = 8;
  // Illumination: gain falls linearly from 1 to illumination_ratio across the image along
  // illumination_direction_deg (0 = image +x), times 1 - vignetting * (r / r_corner)^2.
  double illumination_ratio = 1.0;
  double illumination_direction_deg = 0.0;
  double vignetting = 0.0;
  double exposure_gain = 1.0;
  double defocus_sigma_px = 0.0;
  // Sensor noise in 8-bit units (Gaussian read noise, shot noise variance = gain * signal).
  double read_noise_sigma = 0.0;
  double shot_noise_gain = 0.0;
  // Samples per axis of a tag's black square for its visible fraction.
  int visibility_grid = 16;
};
// Effects that look like an industrial ceiling camera: blur of a 4 ms exposure, mild vignetting,
// a light gradient and noise.
SiteRenderParams realistic_site_params();

struct AgvTruth {
  std::size_t index = 0;
  std::string id;
  std::uint32_t tag_id = 0;
  Pose2 pose;
  // Black square corners, page order: top-left, top-right, bottom-right, bottom-left (the page's
  // "up" is the vehicle's +x; seen from above, "right" is the vehicle's -y).
  std::array<Vec2, 4> tag_corners_px{};
  std::array<Vec2, 4> tray_corners_px{};  // front-left, front-right, rear-right, rear-left
  bool projected = false;                 // every corner in front of the camera (pixels valid)
  // Fraction of the black square's sample points inside the image, facing the camera and not
  // hidden by anything nearer along their ray.
  double tag_visible_fraction = 0.0;
};

struct WallLandmarkTruth {
  std::uint32_t id = 0;
  std::array<Vec2, 4> corners_px{};  // black square, page order as above (page up = site +z)
  bool projected = false;
  double visible_fraction = 0.0;
};

struct BoxTruth {
  std::size_t index = 0;  // into scene.parcels / scene.clutter
  Vec3 centre_site;       // centre of the top face at the frame time
  Vec2 centre_px{};
  bool projected = false;
};

struct RenderResult {
  cv::Mat image;  // CV_8UC1
  std::vector<AgvTruth> agvs;
  std::vector<WallLandmarkTruth> wall_landmarks;
  std::vector<BoxTruth> parcels, clutter;
};

// Renders frames of cameras with one set of intrinsics. Precomputes every pixel corner's
// undistorted ray once (the expensive Newton iterations), so a sequence of frames, or a camera on
// a moving vehicle, pays it once. Thread-compatible.
class SiteFrameRenderer {
 public:
  explicit SiteFrameRenderer(const CameraIntrinsics& intrinsics);
  // Empty image and empty truth when the camera's intrinsics differ from the renderer's or the
  // scene's vehicle count differs from its fleet's. `seed` drives only the sensor noise.
  RenderResult render(const SiteScene& scene, const RenderCamera& cam,
                      const SiteRenderParams& params, std::uint64_t seed) const;
  const CameraIntrinsics& intrinsics() const { return k_; }

  // Normalised undistorted coordinates of pixel-corner (i, j) (pixel (x, y) spans corners
  // (x, y)..(x+1, y+1)); NaN where the lens model does not invert.
  int corner_cols() const { return k_.width_px + 1; }
  const float* corner_xy(int i, int j) const {
    return &rays_[2 * (static_cast<std::size_t>(j) * static_cast<std::size_t>(corner_cols()) +
                       static_cast<std::size_t>(i))];
  }
  static constexpr int kTile = 64;
  // Bounding box of a tile's normalised rays (min x, min y, max x, max y).
  const std::array<float, 4>& tile_box(int tx, int ty) const {
    return tile_box_[static_cast<std::size_t>(ty * tiles_x_ + tx)];
  }
  int tiles_x() const { return tiles_x_; }
  int tiles_y() const { return tiles_y_; }

 private:
  CameraIntrinsics k_;
  std::vector<float> rays_;  // (w+1)*(h+1) pairs
  std::vector<std::array<float, 4>> tile_box_;
  int tiles_x_ = 0, tiles_y_ = 0;
};

// Convenience (precomputes the rays each call; use SiteFrameRenderer for sequences).
RenderResult render_site_frame(const SiteScene& scene, const RenderCamera& cam,
                               const SiteRenderParams& params, std::uint64_t seed);

}  // namespace agv::sim
