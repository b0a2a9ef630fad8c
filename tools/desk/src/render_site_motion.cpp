// agvloc-desk render-site: fleet motion for the frames and option parsing
// (render_site_motion.hpp).
#include "render_site_motion.hpp"

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <sstream>

namespace agv::desk {

bool simulate_site_fleet(const site::Site& site, double duration_s, double speed_mps,
                         std::uint64_t seed, FleetMotion* out, std::string* error) {
  if (site.fleet.empty()) return (*error = "the site has no fleet", false);
  std::vector<double> radii;
  for (const site::FleetAgv& v : site.fleet) radii.push_back(v.radius_mm);
  site::RoutePlanner planner;
  if (!sim::route_planner_for_fleet(site, radii, &planner, error)) {
    *error = "planner: " + *error;
    return false;
  }
  // Enough tasks that nobody runs out during a render.
  if (!sim::make_random_fleet(planner, site, radii, 20, seed, &out->specs, error)) return false;
  sim::FleetParams fp;
  fp.duration_s = duration_s;
  fp.seed = seed;
  fp.drive.speed_mps = speed_mps;
  fp.gyro_enabled = false;
  if (!sim::simulate_fleet(site, planner, out->specs, fp, &out->result, error)) return false;
  for (const sim::FleetVehicleOutput& v : out->result.vehicles) {
    if (v.truth.empty()) return (*error = "the fleet simulation produced no truth", false);
  }
  return true;
}

std::vector<sim::AgvState> fleet_states_at(const FleetMotion& m, std::int64_t t_ns) {
  std::vector<sim::AgvState> s;
  for (const sim::FleetVehicleOutput& v : m.result.vehicles) {
    const auto it =
        std::lower_bound(v.truth.begin(), v.truth.end(), t_ns,
                         [](const sim::FleetTruthSample& a, std::int64_t t) { return a.t_ns < t; });
    auto best = it == v.truth.end() ? std::prev(it) : it;
    if (it != v.truth.begin() && it != v.truth.end() &&
        t_ns - std::prev(it)->t_ns < it->t_ns - t_ns) {
      best = std::prev(it);
    }
    const sim::AgvState at{best->pose, best->v_mps, best->omega_radps};
    s.push_back({sim::advance_agv_pose(at, static_cast<double>(t_ns - best->t_ns) * 1e-9),
                 best->v_mps, best->omega_radps});
  }
  return s;
}

void add_clutter_off_paths(sim::SiteScene* scene, const FleetMotion& m, int count,
                           std::uint64_t seed) {
  // add_random_clutter keeps clutter off the scene's vehicles: give it a scene whose "vehicles"
  // are every vehicle at every half metre of its run.
  sim::SiteScene probe = *scene;
  probe.site.fleet.clear();
  probe.agvs.clear();
  for (std::size_t i = 0; i < m.result.vehicles.size(); ++i) {
    Pose2 last{1e300, 1e300, 0.0};
    for (const sim::FleetTruthSample& t : m.result.vehicles[i].truth) {
      if (std::hypot(t.pose.x_mm - last.x_mm, t.pose.y_mm - last.y_mm) < 500.0) continue;
      last = t.pose;
      probe.site.fleet.push_back(scene->site.fleet[i]);
      probe.agvs.push_back({t.pose, 0.0, 0.0});
    }
  }
  const int people = (count + 1) / 2;
  sim::add_random_clutter(&probe, people, count - people, seed);
  scene->clutter = probe.clutter;
}

namespace {

bool parse_numbers(const std::string& text, std::size_t n, std::vector<double>* out) {
  out->clear();
  std::stringstream ss(text);
  std::string item;
  while (std::getline(ss, item, ',')) {
    char* end = nullptr;
    const double v = std::strtod(item.c_str(), &end);
    if (item.empty() || *end != '\0' || !std::isfinite(v)) return false;
    out->push_back(v);
  }
  return out->size() == n && (text.empty() || text.back() != ',');
}

}  // namespace

bool parse_mount(const std::string& text, sim::VehicleCameraMount* out, std::string* error) {
  std::vector<double> v;
  if (!parse_numbers(text, 6, &v)) {
    *error = "--mount '" + text + "': expected x_mm,y_mm,z_mm,yaw_deg,pitch_deg,roll_deg";
    return false;
  }
  if (std::abs(v[0]) > 1e5 || std::abs(v[1]) > 1e5 || v[2] <= 0.0 || v[2] > 1e5 ||
      std::abs(v[4]) >= 90.0) {
    *error = "--mount '" + text +
             "': z must be in (0, 100000] mm, |x|, |y| <= 100000 mm and "
             "|pitch| < 90 deg";
    return false;
  }
  const double d = kPi / 180.0;
  *out = {v[0], v[1], v[2], v[3] * d, v[4] * d, v[5] * d};
  return true;
}

bool parse_intrinsics(const std::string& text, CameraIntrinsics* out, std::string* error) {
  const auto x = text.find('x');
  const auto comma = text.find(',');
  std::vector<double> v;
  const bool shape = x != std::string::npos && comma != std::string::npos && x < comma &&
                     parse_numbers(text.substr(0, x) + "," + text.substr(x + 1), 6, &v);
  if (!shape || v[0] != std::floor(v[0]) || v[1] != std::floor(v[1]) || v[0] < 16 || v[1] < 16 ||
      v[0] > 16384 || v[1] > 16384 || v[2] <= 0.0 || v[3] <= 0.0) {
    *error = "--intrinsics '" + text + "': expected WxH,fx,fy,cx,cy (16..16384 px, fx, fy > 0)";
    return false;
  }
  *out = CameraIntrinsics{};
  out->width_px = static_cast<int>(v[0]);
  out->height_px = static_cast<int>(v[1]);
  out->fx = v[2], out->fy = v[3], out->cx = v[4], out->cy = v[5];
  return true;
}

CameraIntrinsics scale_intrinsics(const CameraIntrinsics& k, double s) {
  CameraIntrinsics o = k;
  o.width_px = std::max(1, static_cast<int>(std::lround(k.width_px * s)));
  o.height_px = std::max(1, static_cast<int>(std::lround(k.height_px * s)));
  o.fx = k.fx * s, o.fy = k.fy * s;
  o.cx = (k.cx + 0.5) * s - 0.5, o.cy = (k.cy + 0.5) * s - 0.5;
  return o;
}

}  // namespace agv::desk
