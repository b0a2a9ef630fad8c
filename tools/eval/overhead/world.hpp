// The simulated site of eval_overhead: a square floor under a 2 x 2 grid of ceiling cameras, a
// fleet driven by the fleet simulator, and the cameras' frames rendered region by region around
// the vehicles over a background rendered once (docs/design/overhead.md, "Evaluation").
#pragma once

#include <array>
#include <cstdint>
#include <random>
#include <string>
#include <vector>

#include "agv/sim/fleet.hpp"
#include "agv/sim/site_render.hpp"
#include "agv/site/site.hpp"

namespace agv::eval {

struct WorldOptions {
  double site_mm = 12000.0;
  double camera_height_mm = 6000.0;
  int width_px = 3840, height_px = 2160;
  double tag_px = 60.0;          // side of a 160 mm tag seen straight below at tray height
  int cameras = 4;               // 1 (centred) or 4 (2 x 2)
  double k1 = -0.05, k2 = 0.01;  // barrel distortion of every lens
  int agvs = 20;
  double duration_s = 60.0;
  double parcels = 0.0;  // fraction of loaded trays
  // >= 0: a loaded tray gets its parcels during the run, at a time drawn from [load_from_s,
  // load_from_s + duration_s / 2] (as at a pick station: the tag is read first, then covered);
  // < 0: loaded from the start.
  double load_from_s = -1.0;
  // The first parcel of a loaded tray lies over the whole tag (the target's case).
  bool cover_tags = false;
  int clutter = 0;  // people and pallets on the floor
  // Each vehicle's tray top tilted by this much in a random direction, and its tag up to this far
  // above or below the tray height the tracker is told (uniform), fixed for the run.
  double tray_tilt_deg = 0.0, tray_height_error_mm = 0.0;
  std::uint64_t seed = 1;
};

// Rendering of a camera's frame as a background (floor, clutter: rendered once) plus the region
// around each vehicle rendered anew every frame (through a camera of the region's size whose
// principal point is moved: the same rays). Vignetting and the light gradient are applied here
// as one gain map over the whole image: the renderer would apply them per region.
class RegionRenderer {
 public:
  static constexpr int kMargin = 8;
  RegionRenderer(const CameraIntrinsics& k, const sim::SiteRenderParams& params);
  // Renders camera `camera`'s background (a scene without vehicles) once.
  void set_background(std::size_t camera, const sim::SiteScene& empty_scene,
                      const sim::RenderCamera& cam, std::uint64_t seed);
  // The frame with the region of every vehicle that projects into it rendered anew.
  cv::Mat render(std::size_t camera, const sim::SiteScene& scene, const sim::RenderCamera& cam,
                 std::uint64_t seed);
  std::size_t pixels_rendered() const { return pixels_rendered_; }

 private:
  // Pixel box of vehicle i's body, tray and parcels; empty outside the image.
  cv::Rect vehicle_box(const sim::SiteScene& scene, std::size_t i,
                       const sim::RenderCamera& cam) const;
  CameraIntrinsics k_;
  sim::SiteRenderParams params_;     // without the image-wide effects
  cv::Mat gain_;                     // CV_32F
  std::vector<cv::Mat> background_;  // per camera
  std::size_t pixels_rendered_ = 0;
};

// A route the simulator gave a vehicle (as a fleet manager's order would): from t_ns on.
struct RouteEvent {
  std::int64_t t_ns = 0;
  std::size_t agv = 0;
  std::vector<Vec2> waypoints_mm;
};

class World {
 public:
  // False with *error when the fleet cannot be placed or simulated.
  bool build(const WorldOptions& o, std::string* error);
  const site::Site& site() const { return site_; }
  const sim::FleetResult& fleet() const { return fleet_; }
  // Every vehicle's truth at t_ns (interpolated between the simulator's 10 ms samples).
  std::vector<sim::AgvState> states_at(std::int64_t t_ns) const;
  sim::SiteScene scene_at(std::int64_t t_ns) const;
  // Tag corners of every vehicle in camera `cam` (page order); ok = all in front of it.
  std::vector<std::array<Vec2, 4>> tag_corners(const sim::RenderCamera& cam,
                                               const std::vector<sim::AgvState>& states,
                                               std::vector<std::uint8_t>* ok) const;
  // Per vehicle at t_ns: a parcel loaded by then hides every corner of its tag.
  std::vector<std::uint8_t> tags_covered_at(std::int64_t t_ns) const;
  // Every task leg's route in time order: planned again, as the simulator planned it, from the
  // vehicle's position when the leg started (to the pick point, after the pick dwell to the drop
  // point). A leg driven aside to resolve a blockage is not among them (its vehicle is then off
  // the route it was given).
  std::vector<RouteEvent> route_events() const;
  std::vector<sim::Parcel> parcels;
  std::vector<std::int64_t> parcel_load_ns;  // per parcel: on its tray from this time
  std::vector<sim::Clutter> clutter;
  // Per vehicle: its tray's roll and pitch and its tag's height error (WorldOptions).
  std::vector<double> tray_roll_rad, tray_pitch_rad, tray_dz_mm;

 private:
  void draw_tray_planes(const WorldOptions& o, std::size_t n);
  site::Site site_;
  sim::FleetResult fleet_;
  site::RoutePlanner planner_;
};

// Overwrites n data cells of the tag at corners_px (page order, outer black square) with the
// opposite shade, read from the image itself. Returns the cells flipped.
int flip_tag_cells(cv::Mat* gray, const std::array<Vec2, 4>& corners_px, int n,
                   std::mt19937_64* rng);

// A site camera moved by a calibration error: translation of error_mm in a random direction and
// a rotation of error_deg about a random axis.
site::CeilingCamera perturbed(const site::CeilingCamera& cam, double error_mm, double error_deg,
                              std::mt19937_64* rng);

}  // namespace agv::eval
