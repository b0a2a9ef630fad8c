// Site renderer speed (not a ctest; docs/design/site_render.md gives the command and figures):
// a 3840x2160 ceiling camera 6 m up over 20 vehicles (half of them loaded), two racks, people and
// pallets. Prints the ray-map set-up time and the median CPU time per frame on one core, clean
// and with the realistic effects (motion blur of moving vehicles, noise, vignetting).
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <ctime>
#include <vector>

#include "agv/sim/site_render.hpp"

using namespace agv;
using namespace agv::sim;

namespace {

SiteScene bench_scene() {
  SiteScene s;
  s.site.outline.vertices_mm = {{-5500, -3200}, {5500, -3200}, {5500, 3200}, {-5500, 3200}};
  site::Obstacle rack;
  rack.kind = site::ObstacleKind::kRack;
  rack.height_mm = 2500.0;
  rack.outline.vertices_mm = {{-5400, -3100}, {-4400, -3100}, {-4400, 3100}, {-5400, 3100}};
  s.site.obstacles.push_back(rack);
  rack.outline.vertices_mm = {{4400, -3100}, {5400, -3100}, {5400, 3100}, {4400, 3100}};
  s.site.obstacles.push_back(rack);
  for (int i = 0; i < 20; ++i) {
    site::FleetAgv a;
    a.id = "agv" + std::to_string(i + 1);
    a.tag_id = static_cast<std::uint32_t>(i + 1);
    s.site.fleet.push_back(a);
  }
  const std::vector<Pose2> poses = random_free_poses(s.site, 20, 330.0, 1);
  for (const Pose2& p : poses) s.agvs.push_back({p, 1.0, 0.2});
  s.site.fleet.resize(s.agvs.size());
  add_random_parcels(&s, 0.5, 1);
  add_random_clutter(&s, 3, 2, 1);
  return s;
}

double median_ms(const SiteFrameRenderer& r, const SiteScene& s, const RenderCamera& cam,
                 const SiteRenderParams& p, int n) {
  std::vector<double> t;
  for (int i = 0; i < n; ++i) {
    // Process CPU time: the machine running this may be shared, wall time would mislead.
    const std::clock_t a = std::clock();
    const RenderResult res = r.render(s, cam, p, static_cast<std::uint64_t>(i));
    const std::clock_t b = std::clock();
    if (res.image.empty()) return -1.0;
    t.push_back(1000.0 * static_cast<double>(b - a) / CLOCKS_PER_SEC);
  }
  std::nth_element(t.begin(), t.begin() + n / 2, t.end());
  return t[static_cast<size_t>(n / 2)];
}

}  // namespace

int main(int argc, char** argv) {
  const int n = argc > 1 ? std::max(1, std::atoi(argv[1])) : 5;
  const SiteScene scene = bench_scene();
  site::CeilingCamera cc;
  cc.intrinsics.width_px = 3840;
  cc.intrinsics.height_px = 2160;
  cc.intrinsics.fx = cc.intrinsics.fy = 2400.0;  // 9.6 m x 5.4 m of floor from 6 m
  cc.intrinsics.cx = 1919.5;
  cc.intrinsics.cy = 1079.5;
  cc.intrinsics.k1 = -0.08;
  cc.intrinsics.k2 = 0.01;
  const RenderCamera cam = RenderCamera::from_ceiling(cc);
  const std::clock_t a = std::clock();
  const SiteFrameRenderer r(cc.intrinsics);
  const double setup_ms = 1000.0 * static_cast<double>(std::clock() - a) / CLOCKS_PER_SEC;
  const double clean = median_ms(r, scene, cam, SiteRenderParams{}, n);
  const double real = median_ms(r, scene, cam, realistic_site_params(), n);
  const RenderResult res = r.render(scene, cam, SiteRenderParams{}, 0);
  int tags_seen = 0;
  for (const AgvTruth& t : res.agvs) tags_seen += t.tag_visible_fraction > 0.99 ? 1 : 0;
  std::printf(
      "3840x2160, 6 m, %zu vehicles (%d tags fully visible), %zu parcels, %zu clutter: ray map "
      "%.0f ms once; median per frame over %d runs: clean %.0f ms, realistic %.0f ms\n",
      scene.agvs.size(), tags_seen, scene.parcels.size(), scene.clutter.size(), setup_ms, n, clean,
      real);
  return 0;
}
