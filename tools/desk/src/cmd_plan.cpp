// agvloc-desk plan: a route between two points of a site (docs/design/site_planner.md), the
// drivable trajectory along it, and optionally its CSV, SVG and VDA 5050 order.
//   plan --site S --from X,Y --to X,Y [--radius-mm R --clearance-mm C --speed V ...]
//        [--csv F] [--waypoints F] [--svg F] [--order F.json --order-id ID --map-id M]
#include <CLI/CLI.hpp>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <string>

#include "agv/site/planner.hpp"
#include "agv/vda5050/order.hpp"
#include "agv/vda5050/vda5050.hpp"
#include "cli_parse.hpp"
#include "commands.hpp"
#include "site_io.hpp"
#include "site_svg.hpp"

namespace agv::desk {

namespace {

bool parse_xy(const std::string& text, Vec2* out) {
  double x = 0, y = 0;
  char tail = 0;
  if (std::sscanf(text.c_str(), "%lf,%lf%c", &x, &y, &tail) != 2) return false;
  if (!std::isfinite(x) || !std::isfinite(y)) return false;
  *out = {x, y};
  return true;
}

bool write_plan_output(const std::string& path, const std::string& text) {
  std::ofstream f(path, std::ios::binary);
  f << text;
  f.close();
  if (!f) std::fprintf(stderr, "agvloc-desk plan: cannot write %s\n", path.c_str());
  return static_cast<bool>(f);
}

std::string trajectory_csv(const site::RouteTrajectory& tr, double dt_s) {
  std::string out = "t_s,x_mm,y_mm,theta_rad,v_mps\n";
  char line[160];
  const int n = static_cast<int>(std::ceil(tr.duration_s() / dt_s));
  for (int i = 0; i <= n; ++i) {
    const site::TrajectorySample s = tr.at(std::min(tr.duration_s(), i * dt_s));
    std::snprintf(line, sizeof line, "%.3f,%.1f,%.1f,%.5f,%.4f\n", s.t_s, s.pose.x_mm, s.pose.y_mm,
                  s.pose.theta_rad, s.v_mps);
    out += line;
  }
  return out;
}

}  // namespace

int plan_command(int argc, char** argv) {
  CLI::App app{
      "Plan a route around a site's obstacles (visibility graph, Dijkstra) and the "
      "drivable trajectory along it. Prints length and time",
      "agvloc-desk plan"};
  std::string site_path, from_text, to_text, csv_path, wp_path, svg_path, order_path;
  std::string order_id = "route-1", map_id, manufacturer = "agvloc", serial = "agv-1";
  double radius_mm = -1, clearance_mm = -1, dt_s = 0.1;
  site::DriveLimits lim;
  app.add_option("--site", site_path, "The site file (site.yaml)")->required();
  app.add_option("--from", from_text, "Start X,Y in mm (site frame)")->required();
  app.add_option("--to", to_text, "Goal X,Y in mm")->required();
  app.add_option("--radius-mm", radius_mm,
                 "Vehicle radius (default: the fleet's first AGV, else 400)");
  app.add_option("--clearance-mm", clearance_mm, "Kept beyond the radius (default: the site's)");
  app.add_option("--speed", lim.speed_mps, "Top speed, m/s")->capture_default_str();
  app.add_option("--accel", lim.accel_mps2, "Longitudinal acceleration, m/s^2")
      ->capture_default_str();
  app.add_option("--lateral-accel", lim.lateral_accel_mps2, "Lateral acceleration, m/s^2")
      ->capture_default_str();
  app.add_option("--min-radius-mm", lim.max_curvature_per_mm, "Tightest blend radius, mm")
      ->transform([](const std::string& s) { return std::to_string(1.0 / std::stod(s)); });
  app.add_option("--csv", csv_path, "Write the trajectory (t_s,x_mm,y_mm,theta_rad,v_mps)");
  app.add_option("--dt", dt_s, "Trajectory CSV time step, s")->capture_default_str();
  app.add_option("--waypoints", wp_path, "Write the route's waypoints (x_mm,y_mm)");
  app.add_option("--svg", svg_path, "Draw the site, the inflated obstacles and the path");
  app.add_option("--order", order_path, "Write the route as a VDA 5050 2.1.0 order (JSON)");
  app.add_option("--order-id", order_id, "orderId of the order")->capture_default_str();
  app.add_option("--map-id", map_id, "mapId of the order's nodes (default: the site's name)");
  app.add_option("--manufacturer", manufacturer, "manufacturer of the order")
      ->capture_default_str();
  app.add_option("--serial", serial, "serialNumber of the order")->capture_default_str();
  if (const int parse_rc = cli::parse(app, argc, argv); parse_rc >= 0) return parse_rc;
  Vec2 from, to;
  if (!parse_xy(from_text, &from) || !parse_xy(to_text, &to)) {
    std::fprintf(stderr, "agvloc-desk plan: --from and --to take X,Y in mm (e.g. 1200,3400)\n");
    return 2;
  }
  if (!(dt_s > 0.001)) {
    std::fprintf(stderr, "agvloc-desk plan: --dt must be above 0.001 s\n");
    return 2;
  }
  site::Site site;
  std::string errors;
  if (!load_site(site_path, &site, &errors)) {
    std::fputs(errors.c_str(), stderr);
    return 2;
  }
  site::PlannerParams params;
  params.vehicle_radius_mm =
      radius_mm >= 0 ? radius_mm : (site.fleet.empty() ? 400.0 : site.fleet[0].radius_mm);
  params.clearance_mm = clearance_mm >= 0 ? clearance_mm : site.clearance_mm;
  site::RoutePlanner planner, collision;
  std::string error;
  if (!site::RoutePlanner::build(site, params, &planner, &error)) {
    std::fprintf(stderr, "agvloc-desk plan: %s\n", error.c_str());
    return 2;
  }
  const site::Route route = planner.plan(from, to);
  if (route.status != site::PlanStatus::kOk) {
    std::fprintf(stderr, "agvloc-desk plan: %s: %s\n", site::to_string(route.status),
                 route.error.c_str());
    return 2;
  }
  site::PlannerParams bare = params;
  bare.clearance_mm = 0.0;
  site::RouteTrajectory tr;
  if (!site::RoutePlanner::build(site, bare, &collision, &error) ||
      !site::RouteTrajectory::make_checked(route, lim, collision, &tr, &error)) {
    std::fprintf(stderr, "agvloc-desk plan: route found (%.3f m) but not drivable: %s\n",
                 route.length_mm * 1e-3, error.c_str());
    return 1;
  }
  std::printf(
      "route: %.3f m, %zu waypoints; drivable path %.3f m in %.2f s (corners cut in by "
      "at most %.0f mm of the %.0f mm clearance)\n",
      route.length_mm * 1e-3, route.waypoints_mm.size(), tr.length_mm() * 1e-3, tr.duration_s(),
      tr.max_corner_deviation_mm(), params.clearance_mm);
  bool ok = true;
  if (!csv_path.empty()) ok &= write_plan_output(csv_path, trajectory_csv(tr, dt_s));
  if (!wp_path.empty()) {
    std::string text = "x_mm,y_mm\n";
    char line[80];
    for (const Vec2& p : route.waypoints_mm) {
      std::snprintf(line, sizeof line, "%.1f,%.1f\n", p.x, p.y);
      text += line;
    }
    ok &= write_plan_output(wp_path, text);
  }
  if (!svg_path.empty())
    ok &= write_plan_output(svg_path, site_svg(site, {tr.polyline(50.0)}, planner.inflated()));
  if (!order_path.empty()) {
    vda5050::Order header;
    header.timestamp =
        vda5050::iso8601_utc_ms(std::chrono::duration_cast<std::chrono::nanoseconds>(
                                    std::chrono::system_clock::now().time_since_epoch())
                                    .count());
    header.manufacturer = manufacturer, header.serial_number = serial, header.order_id = order_id;
    const vda5050::Order order = vda5050::order_from_waypoints(
        route.waypoints_mm, map_id.empty() ? site.name : map_id, header);
    ok &= write_plan_output(order_path, vda5050::encode_order(order) + "\n");
  }
  return ok ? 0 : 1;
}

}  // namespace agv::desk
