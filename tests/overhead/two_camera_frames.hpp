// Frames of the two-camera site's cameras (two_camera_site.hpp) as a fake camera delivers them:
// the site renderer's clean image of the vehicles, seed 1.
#pragma once

#include <cstddef>
#include <vector>

#include "agv/fakecamera/fake_camera.hpp"
#include "agv/sim/site_render.hpp"
#include "two_camera_site.hpp"

namespace agv::overhead_app::test {

// A scripted camera on `clock`: stalls take that clock's time, the end of the script ends the
// stream.
inline fakecamera::FakeCamera::Options scripted_camera(hal::Clock* clock) {
  fakecamera::FakeCamera::Options opt;
  opt.clock = clock;
  opt.end_of_stream_when_empty = true;
  return opt;
}

// Two vehicles, one under each camera.
inline std::vector<sim::AgvState> two_vehicles() {
  return {{{1350.0, 1250.0, 0.3}, 0.0, 0.0}, {{3600.0, 1000.0, -1.0}, 0.0, 0.0}};
}

inline fakecamera::FakeImage render_fake_frame(const site::Site& s, std::size_t cam,
                                               const std::vector<sim::AgvState>& agvs) {
  sim::SiteScene scene;
  scene.site = s;
  scene.agvs = agvs;
  const sim::SiteFrameRenderer r(s.cameras[cam].intrinsics);
  const sim::RenderResult res =
      r.render(scene, sim::RenderCamera::from_ceiling(s.cameras[cam]), sim::SiteRenderParams{}, 1);
  fakecamera::FakeImage img;
  img.width_px = res.image.cols;
  img.height_px = res.image.rows;
  img.gray.assign(res.image.datastart, res.image.dataend);
  return img;
}

}  // namespace agv::overhead_app::test
