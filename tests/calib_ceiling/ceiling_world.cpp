#include "ceiling_world.hpp"

#include <string>

namespace agv::desk::test {

// The true pose: 4.5 m up, turned and tilted a little, so no angle is a special value.
ccal::CameraPose true_pose() {
  return {1000.0, 500.0, 4500.0, 20.0 * kDeg, 3.0 * kDeg, -2.0 * kDeg};
}

CameraIntrinsics intrinsics() {
  return {.width_px = 1280,
          .height_px = 720,
          .fx = 1000.0,
          .fy = 1002.0,
          .cx = 641.0,
          .cy = 358.0,
          .k1 = -0.06,
          .k2 = 0.012,
          .p1 = 0.0004,
          .p2 = -0.0003};
}

// Seven vehicles standing in view: the top row's three (tags 1..3) on one image row at one tray
// height, so on one line of the site; the others at other heights, turned every way.
// A tray exactly at the floor ties with it along every ray and the floor is drawn; 1 mm above it
// the tag shows (and sits 1 mm above its surveyed floor position).
constexpr double kOnFloorTrayMm = 1.0;

static World make_world(bool on_floor, int frames) {
  World w;
  site::Site& s = w.site;
  s.name = "calib-ceiling-test";
  s.outline.vertices_mm = {{-6000, -6000}, {8000, -6000}, {8000, 7000}, {-6000, 7000}};
  site::CeilingCamera cam;
  cam.id = "cam-1";
  cam.intrinsics = intrinsics();
  ccal::set_pose(true_pose(), &cam);
  s.cameras.push_back(cam);
  const double px[7][2] = {{260, 170}, {640, 165},  {1020, 175}, {300, 540},
                           {700, 560}, {1040, 520}, {470, 360}};
  const double tray_mm[7] = {400, 400, 400, 350, 450, 380, 420};
  for (int i = 0; i < 7; ++i) {
    site::FleetAgv a;
    a.id = "agv-" + std::to_string(i + 1);
    a.tag_id = static_cast<std::uint32_t>(i + 1);
    a.tag_size_mm = 200.0;
    a.tray_height_mm = on_floor ? kOnFloorTrayMm : tray_mm[i];
    a.footprint.vertices_mm = {{300, 200}, {-300, 200}, {-300, -200}, {300, -200}};
    a.radius_mm = 400.0;
    s.fleet.push_back(a);
    const Vec2 p = on_plane(cam, px[i][0], px[i][1], a.tray_height_mm);
    w.scene.agvs.push_back({{p.x, p.y, -2.5 + 0.9 * i}, 0.0, 0.0});
  }
  w.scene.site = s;
  w.scene.floor.amplitude = 30.0;
  const sim::SiteFrameRenderer renderer(cam.intrinsics);
  const sim::SiteRenderParams params = sim::realistic_site_params();
  for (int f = 0; f < frames; ++f) {
    const std::uint64_t seed = 11u + static_cast<std::uint64_t>(f);
    w.truth.push_back(renderer.render(w.scene, sim::RenderCamera::from_ceiling(cam), params, seed));
    w.frames.push_back(w.truth.back().image);
  }
  return w;
}

const World& world() {
  static const World w = make_world(false, 2);
  return w;
}

std::map<std::uint32_t, ccal::SurveyedTag> survey_of(const World& w, int first, int n) {
  std::map<std::uint32_t, ccal::SurveyedTag> out;
  for (int i = first; i < first + n; ++i) {
    const auto& a = w.site.fleet[static_cast<std::size_t>(i)];
    const Pose2& p = w.scene.agvs[static_cast<std::size_t>(i)].pose;
    out[a.tag_id] = {a.tag_id, p.x_mm, p.y_mm, a.tray_height_mm, p.theta_rad, a.tag_size_mm};
  }
  return out;
}

}  // namespace agv::desk::test

namespace agv::desk::test {

const World& floor_world() {
  static const World w = make_world(true, 1);
  return w;
}

}  // namespace agv::desk::test
