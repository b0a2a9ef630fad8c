// The rendered scene the ceiling calibration tests share: one ceiling camera at a known pose over
// seven fleet vehicles standing still (their tray tags are the surveyed tags), two frames.
#pragma once

#include <cmath>
#include <map>
#include <vector>

#include "agv/sim/site_render.hpp"
#include "agv/site/site_geometry.hpp"
#include "calib_ceiling.hpp"

namespace agv::desk::test {

constexpr double kPi = 3.14159265358979323846;
constexpr double kDeg = kPi / 180.0;

// Where the ray through pixel (u, v) of `cam` meets the plane z = z_mm; NaN when it does not.
inline Vec2 on_plane(const site::CeilingCamera& cam, double u, double v, double z_mm) {
  Vec2 p{std::nan(""), std::nan("")};
  site::camera_pixel_to_plane(cam, {u, v}, z_mm, &p);
  return p;
}

ccal::CameraPose true_pose();
CameraIntrinsics intrinsics();

struct World {
  site::Site site;  // the camera at true_pose()
  sim::SiteScene scene;
  std::vector<cv::Mat> frames;
  std::vector<sim::RenderResult> truth;
};
// Rendered once per test program.
const World& world();
// The same vehicles with their trays 1 mm up: tags lying on the floor, as floor landmarks
// would (the renderer draws no floor-map landmarks). One frame.
const World& floor_world();
// Fleet tags first .. first + n - 1 as surveyed tags (tags 1..3 lie on one line).
std::map<std::uint32_t, ccal::SurveyedTag> survey_of(const World& w, int first = 0, int n = 7);

}  // namespace agv::desk::test
