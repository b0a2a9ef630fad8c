// Geometry of the site model that the parser, the checks and the drawing share: the ceiling
// cameras' orientation angles (docs/guide/site.md, "Camera orientation") and where their image
// meets the floor, and simple polygon measures.
#pragma once

#include <array>
#include <span>
#include <vector>

#include "agv/site/site.hpp"

namespace agv::site {

// R_site_cam (row-major) of a camera turned by yaw, then tilted by pitch, then by roll (radians)
// from the straight-down camera whose image right is site +x and image up site +y:
//   R_site_cam = Rz(yaw) * R_down * Rx(pitch) * Ry(roll),  R_down = diag(1, -1, -1)
// Positive yaw turns the image counter-clockwise seen from above; positive pitch tilts the
// optical axis towards the top edge of the image, positive roll towards its right edge.
std::array<double, 9> camera_rotation_from_angles(double yaw_rad, double pitch_rad,
                                                  double roll_rad);
// The inverse for a rotation matrix: yaw, pitch, roll with pitch in [-pi/2, pi/2]. At
// pitch = +-pi/2 (camera looking at the horizon) yaw and roll are not unique; roll is then 0.
void camera_angles_from_rotation(const std::array<double, 9>& r_site_cam, double* yaw_rad,
                                 double* pitch_rad, double* roll_rad);

// The optical axis in the site frame (unit vector; z < 0 when looking down).
std::array<double, 3> camera_optical_axis(const CeilingCamera& cam);
// Angle between the optical axis and straight down (rad, 0..pi).
double camera_tilt_rad(const CeilingCamera& cam);

// Where the ray through a (distorted) pixel meets the floor z = 0. False when the pixel does not
// undistort (far outside the lens's field) or its ray does not go down to the floor.
bool camera_pixel_to_floor(const CeilingCamera& cam, Vec2 pixel, Vec2* floor_mm);
// The same for the horizontal plane z = z_mm below the camera (a tray, a tag on a stand).
bool camera_pixel_to_plane(const CeilingCamera& cam, Vec2 pixel, double z_mm, Vec2* at_mm);

// The floor area the image sees: the image border sampled samples_per_edge times per edge,
// counter-clockwise in the image. A ray that does not reach the floor (above the horizon) is cut
// at max_range_mm horizontally from the camera in its direction, so the polygon stays bounded.
std::vector<Vec2> camera_floor_footprint(const CeilingCamera& cam, int samples_per_edge,
                                         double max_range_mm);

// Shoelace area: positive for a counter-clockwise polygon.
double signed_area_mm2(const Polygon& p);

// Whether an obstacle (its outline extruded from the floor to its height, opaque) stands between
// two points (site frame, mm): the segment crosses an outline edge lower than the obstacle's
// height there. The segment stops end_clearance_mm (horizontally) short of `to`, so that a point
// on an obstacle's face, such as a landmark printed on it, is not hidden by its own face.
bool sight_line_blocked(const std::array<double, 3>& from_mm, const std::array<double, 3>& to_mm,
                        std::span<const Obstacle> obstacles, double end_clearance_mm = 20.0);

}  // namespace agv::site
