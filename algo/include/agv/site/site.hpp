// The site model: one warehouse described in the site frame (the floor-landmark map's frame,
// millimetres, z up, x/y on the floor). Shared by the desk tool (planner, fleet simulator,
// renderer), the overhead tracker and the vehicle's rack-landmark aid. Pure data; the file format
// is docs/guide/site.md, the design docs/design/site.md.
#pragma once

#include <array>
#include <cstdint>
#include <string>
#include <vector>

#include "agv/common/camera_model.hpp"
#include "agv/common/geometry.hpp"
#include "agv/common/landmark.hpp"

namespace agv::site {

// A simple polygon on the floor, counter-clockwise after validation (the parser reorients a
// clockwise one), no repeated closing vertex.
struct Polygon {
  std::vector<Vec2> vertices_mm;
};

enum class ObstacleKind : std::uint8_t { kRack, kPillar, kConveyor, kWall, kOther };
const char* to_string(ObstacleKind k);
bool parse_obstacle_kind(const std::string& name, ObstacleKind* out);

// Something vehicles cannot drive through, extruded from the floor to height_mm.
struct Obstacle {
  std::string id;
  ObstacleKind kind = ObstacleKind::kRack;
  Polygon outline;
  double height_mm = 2000.0;
};

enum class LandmarkFamily : std::uint8_t { kTag36h11, kAgvloc };
const char* to_string(LandmarkFamily f);
bool parse_landmark_family(const std::string& name, LandmarkFamily* out);

// A landmark printed on a vertical face (rack upright, pillar, wall). Its plane is vertical; the
// normal points horizontally along facing_rad (site frame, counter-clockwise from +x) out of the
// face, towards whoever can read it. Page "up" is +z.
struct WallLandmark {
  std::uint32_t id = 0;
  LandmarkFamily family = LandmarkFamily::kTag36h11;
  double x_mm = 0.0, y_mm = 0.0, z_mm = 0.0;  // centre of the black square
  double facing_rad = 0.0;
  double size_mm = 150.0;  // outer side of the black square
};

// A camera fixed in the site (on the ceiling, looking down). Pose: camera frame (x image right,
// y image down, z optical axis) in the site frame: p_site = R_site_cam * p_cam + t_site_cam.
struct CeilingCamera {
  std::string id;
  CameraIntrinsics intrinsics;
  std::array<double, 9> r_site_cam{1, 0, 0, 0, -1, 0, 0, 0, -1};  // row-major; default looks down
  std::array<double, 3> t_site_cam_mm{0, 0, 6000};
  // 1-sigma of the calibrated pose (agvloc-desk calibrate ceiling): the optical centre's x, y, z
  // (mm) and the roll, pitch, yaw of docs/guide/site.md's angles (rad), taken as independent.
  // Zero: the pose is taken as exact. The overhead tracker adds it to every fix's covariance.
  std::array<double, 3> position_sigma_mm{0, 0, 0};
  std::array<double, 3> angle_sigma_rad{0, 0, 0};  // roll, pitch, yaw
  // Correlation coefficients between those six (x, y, z, roll, pitch, yaw), the upper triangle row
  // by row: (x,y), (x,z), (x,roll), (x,pitch), (x,yaw), (y,z), ..., (pitch,yaw). Tags seen on
  // about one plane hardly tell a sideways shift from a tilt, and the two cancel where the tags
  // lie: without the correlation the pose's error on the floor is overstated. All 0: independent.
  std::array<double, 15> pose_correlation{};
  // 1-sigma per axis (mm) of what a fix is off on the floor beyond the pose's sigma: the
  // calibration tags' own floor residuals (the lens's residual error, the survey's), which no
  // pose error explains. The tracker adds it to every fix of the camera as a bias. 0: none.
  double floor_sigma_mm = 0.0;
};

// pose_correlation's entry for parameters p and q (0..5, the order above); 1 for p == q.
double pose_correlation_at(const CeilingCamera& cam, int p, int q);

// One vehicle of the fleet. Tray: a horizontal rectangle centred on the vehicle's reference
// point at tray_height_mm, carrying a tag36h11 (tag_id) of tag_size_mm centred on it, the tag's
// "up" along the vehicle's +x. Footprint: the vehicle's outline in its own frame (x forward,
// y left); radius_mm bounds it (the planner inflates obstacles by it).
struct FleetAgv {
  std::string id;
  std::uint32_t tag_id = 0;
  double tag_size_mm = 160.0;
  double tray_length_mm = 600.0;  // along vehicle x
  double tray_width_mm = 400.0;   // along vehicle y
  double tray_height_mm = 400.0;
  // The tray top's surveyed tilt about its centre: roll about the vehicle's x, then pitch about
  // its y (positive pitch lowers the front). The overhead tracker casts the tag's corners onto the
  // tilted plane; 0: level.
  double tray_roll_rad = 0.0, tray_pitch_rad = 0.0;
  Polygon footprint;  // vehicle frame
  double radius_mm = 400.0;
};

struct Site {
  std::string name;
  Polygon outline;  // the drivable area's boundary (walls), counter-clockwise
  std::vector<Obstacle> obstacles;
  LandmarkMap floor_map;       // floor landmarks (the vehicle map file's entries)
  std::string floor_map_file;  // as written in the site file (resolved by the caller)
  std::vector<WallLandmark> wall_landmarks;
  std::vector<CeilingCamera> cameras;
  std::vector<FleetAgv> fleet;
  double clearance_mm = 100.0;  // planner: kept beyond the vehicle radius
};

}  // namespace agv::site
