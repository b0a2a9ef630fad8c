// agvloc-desk fleet: N vehicles working random tasks on a site (docs/design/fleet_sim.md). Writes
// one recording folder per vehicle (meta.yaml, an empty frames.csv, odom.csv, truth.csv,
// imu.csv: odometry-only recordings), plus fleet.csv (every vehicle's truth), tasks.csv and
// events.csv under --out.
#include <CLI/CLI.hpp>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include "agv/recording/recording.hpp"
#include "agv/sim/fleet.hpp"
#include "cli_parse.hpp"
#include "commands.hpp"
#include "site_io.hpp"

namespace agv::desk {

namespace {

namespace fs = std::filesystem;

constexpr std::int64_t kFleetT0Ns = 10'000'000'000LL;  // as agvloc-desk sim: clocks start at 10 s

std::string folder_name(const std::string& id, std::size_t i) {
  std::string s;
  for (char c : id) {
    const bool ok = (c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z') || (c >= '0' && c <= '9') ||
                    c == '-' || c == '_';
    s += ok ? c : '_';
  }
  if (s.empty() || s.size() > 64) s = "agv" + std::to_string(i);
  return s;
}

bool write_text(const fs::path& path, const std::string& text, std::string* error) {
  std::ofstream f(path, std::ios::binary | std::ios::trunc);
  f << text;
  f.close();
  if (!f) {
    *error = "cannot write " + path.string();
    return false;
  }
  return true;
}

bool write_vehicle(const std::string& dir, const sim::FleetVehicleOutput& v, bool gyro,
                   const std::string& source, std::string* error) {
  recording::Meta meta;
  meta.camera = CameraModel::default_640x480();
  meta.source = source;
  std::vector<recording::OdomRow> odom;
  std::vector<recording::TruthRow> truth;
  std::vector<recording::ImuRow> imu;
  odom.reserve(v.odom.size());
  truth.reserve(v.truth.size());
  for (const sim::FleetOdomSample& o : v.odom)
    odom.push_back({kFleetT0Ns + o.t_ns, o.v_mps, o.omega_radps});
  for (const sim::FleetTruthSample& t : v.truth) {
    truth.push_back({kFleetT0Ns + t.t_ns, t.pose.x_mm, t.pose.y_mm, rad_to_deg(t.pose.theta_rad)});
  }
  for (const sim::ImuSample& g : v.gyro) imu.push_back({kFleetT0Ns + g.t_ns, g.gyro_z_radps});
  std::error_code ec;
  fs::remove(fs::path(dir) / "imu.csv", ec);  // a --no-gyro rewrite must not keep an old one
  return recording::write_meta(dir, meta, error) && recording::write_frames_csv(dir, {}, error) &&
         recording::write_odom_csv(dir, odom, error) &&
         recording::write_truth_csv(dir, truth, error) &&
         (!gyro || recording::write_imu_csv(dir, imu, error));
}

std::string fleet_csv(const sim::FleetResult& r, const std::vector<std::string>& names) {
  std::string s = "t_ns,agv,x_mm,y_mm,theta_deg,v_mps,omega_radps\n";
  char line[256];
  const std::size_t n = r.vehicles.empty() ? 0 : r.vehicles[0].truth.size();
  for (std::size_t k = 0; k < n; ++k) {
    for (std::size_t i = 0; i < r.vehicles.size(); ++i) {
      const sim::FleetTruthSample& t = r.vehicles[i].truth[k];
      std::snprintf(line, sizeof line, "%lld,%s,%.1f,%.1f,%.4f,%.4f,%.5f\n",
                    static_cast<long long>(kFleetT0Ns + t.t_ns), names[i].c_str(), t.pose.x_mm,
                    t.pose.y_mm, rad_to_deg(t.pose.theta_rad), t.v_mps, t.omega_radps);
      s += line;
    }
  }
  return s;
}

std::string tasks_csv(const sim::FleetResult& r, const std::vector<std::string>& names) {
  std::string s =
      "agv,task,pick_x_mm,pick_y_mm,drop_x_mm,drop_y_mm,start_s,picked_s,finish_s,error\n";
  char line[512];
  for (const sim::FleetTaskRecord& t : r.tasks) {
    std::string err = t.error;
    for (char& c : err) c = (c == ',' || c == '\n' || c == '\r') ? ';' : c;
    std::snprintf(line, sizeof line, "%s,%d,%.0f,%.0f,%.0f,%.0f,%.3f,%.3f,%.3f,",
                  names[static_cast<std::size_t>(t.vehicle)].c_str(), t.index, t.task.pick_mm.x,
                  t.task.pick_mm.y, t.task.drop_mm.x, t.task.drop_mm.y, t.start_s, t.picked_s,
                  t.finish_s);
    s += line + err + "\n";
  }
  return s;
}

std::string events_csv(const sim::FleetResult& r) {
  std::string s = "t_s,kind,vehicles,text\n";
  char head[64];
  for (const sim::FleetEvent& e : r.events) {
    std::snprintf(head, sizeof head, "%.3f,%s,", e.t_s, sim::to_string(e.kind));
    std::string ids;
    for (std::size_t i = 0; i < e.vehicles.size(); ++i)
      ids += (i ? ";" : "") + std::to_string(e.vehicles[i]);
    std::string text = e.text;
    for (char& c : text) c = (c == ',' || c == '\n' || c == '\r') ? ';' : c;
    s += head + ids + "," + text + "\n";
  }
  return s;
}

// One recording folder name per vehicle: its id made a folder name, or agv<i> when taken.
std::vector<std::string> folder_names(const std::vector<sim::FleetVehicleSpec>& specs) {
  std::vector<std::string> names;
  for (std::size_t i = 0; i < specs.size(); ++i) {
    std::string name = folder_name(specs[i].id, i);
    for (const std::string& o : names) {
      if (o == name) name = "agv" + std::to_string(i);
    }
    names.push_back(name);
  }
  return names;
}

// The first of the folders under out_dir that already holds a recording, or "".
std::string taken_folder(const std::string& out_dir, const std::vector<std::string>& names) {
  std::error_code ec;
  for (const std::string& name : names) {
    if (fs::exists(fs::path(out_dir) / name / "meta.yaml", ec)) return name;
  }
  return "";
}

// Every vehicle's recording, fleet.csv, tasks.csv and events.csv under out_dir.
bool write_fleet(const std::string& out_dir, const std::vector<std::string>& names,
                 const sim::FleetResult& r, bool gyro, const std::string& cmdline,
                 std::string* err) {
  std::error_code ec;
  fs::create_directories(out_dir, ec);
  for (std::size_t i = 0; i < names.size(); ++i) {
    const std::string dir = (fs::path(out_dir) / names[i]).string();
    if (!write_vehicle(dir, r.vehicles[i], gyro, cmdline + " (vehicle " + names[i] + ")", err)) {
      return false;
    }
  }
  return write_text(fs::path(out_dir) / "fleet.csv", fleet_csv(r, names), err) &&
         write_text(fs::path(out_dir) / "tasks.csv", tasks_csv(r, names), err) &&
         write_text(fs::path(out_dir) / "events.csv", events_csv(r), err);
}

// The fleet's events other than evasions, and the run's summary line.
void print_summary(const std::string& out_dir, std::size_t n_vehicles, const sim::FleetResult& r,
                   double wall_s) {
  int waits = 0;
  double wait_s = 0.0;
  for (const sim::FleetVehicleOutput& v : r.vehicles) {
    waits += v.waits;
    wait_s += v.wait_s;
  }
  for (const sim::FleetEvent& e : r.events) {
    if (e.kind != sim::FleetEventKind::kEvade) {
      std::printf("  %9.2f s  %-15s %s\n", e.t_s, sim::to_string(e.kind), e.text.c_str());
    }
  }
  std::printf(
      "agvloc-desk fleet: wrote %s: %zu vehicles, %.0f s simulated; tasks finished %d of %zu; "
      "min pair distance %.0f mm (margin over r_i + r_j + %.0f mm clearance: %.0f mm); waits %d "
      "(%.1f vehicle-s); deadlocks %d, blocked by idle %d, unresolved %d; %.1f s to simulate "
      "(%.0fx real time)\n",
      out_dir.c_str(), n_vehicles, r.simulated_s, r.tasks_finished, r.tasks.size(),
      r.min_pair_distance_mm, r.clearance_mm, r.min_pair_margin_mm, waits, wait_s, r.deadlocks,
      r.blocked_by_idle, r.unresolved, wall_s, wall_s > 0.0 ? r.simulated_s / wall_s : 0.0);
}

}  // namespace

int fleet_command(int argc, char** argv) {
  CLI::App app{
      "Simulate a fleet working random tasks on a site: per-vehicle recordings (truth, "
      "odometry, gyro), fleet.csv, tasks.csv (docs/design/fleet_sim.md)",
      "agvloc-desk fleet"};
  std::string site_path, out_dir;
  int agvs = 0, tasks_per_agv = 5;
  double duration_s = 600.0, radius_mm = 400.0;
  std::uint64_t seed = 1;
  bool force = false, gyro = true;
  sim::FleetParams fp;
  app.add_option("--site", site_path, "Site file (docs/guide/site.md)")->required();
  app.add_option("--out", out_dir, "Folder to write (one recording folder per vehicle)")
      ->required();
  app.add_option("--agvs", agvs, "Number of vehicles; 0 = the site's fleet")
      ->check(CLI::Range(0, 500))
      ->capture_default_str();
  app.add_option("--duration-s", duration_s, "Simulated time")
      ->check(CLI::Range(1.0, 86400.0))
      ->capture_default_str();
  app.add_option("--seed", seed, "Seed for start points, tasks and sensor errors")
      ->capture_default_str();
  app.add_option("--tasks-per-agv", tasks_per_agv, "Random pick-and-drop tasks per vehicle")
      ->check(CLI::Range(0, 100000))
      ->capture_default_str();
  app.add_option("--radius-mm", radius_mm, "Radius of vehicles beyond the site's fleet")
      ->check(CLI::Range(50.0, 5000.0))
      ->capture_default_str();
  app.add_option("--dwell-s", fp.dwell_s, "Standing time at each pick and drop point")
      ->check(CLI::Range(0.0, 3600.0))
      ->capture_default_str();
  app.add_option("--speed-mps", fp.drive.speed_mps, "Cruise speed")
      ->check(CLI::Range(0.05, 5.0))
      ->capture_default_str();
  app.add_flag("--gyro,!--no-gyro", gyro, "Write imu.csv per vehicle (default on)");
  app.add_flag("--force", force, "Overwrite recordings already in --out");
  if (const int parse_rc = cli::parse(app, argc, argv); parse_rc >= 0) return parse_rc;
  auto usage = [](const std::string& msg) {
    std::fprintf(stderr, "agvloc-desk fleet: %s\n", msg.c_str());
    return 2;
  };
  site::Site site;
  std::string err;
  if (!load_site(site_path, &site, &err)) {
    std::fprintf(stderr, "%s", err.c_str());
    return 2;
  }
  const std::size_t n = agvs > 0 ? static_cast<std::size_t>(agvs) : site.fleet.size();
  if (n == 0) return usage(site_path + " has no fleet: give --agvs N");
  std::vector<double> radii(n, radius_mm);
  for (std::size_t i = 0; i < n && i < site.fleet.size(); ++i) radii[i] = site.fleet[i].radius_mm;
  site::RoutePlanner planner;
  if (!sim::route_planner_for_fleet(site, radii, &planner, &err)) return usage("planner: " + err);
  std::vector<sim::FleetVehicleSpec> specs;
  if (!sim::make_random_fleet(planner, site, radii, tasks_per_agv, seed, &specs, &err)) {
    return usage(err);
  }
  const std::vector<std::string> names = folder_names(specs);
  const std::string taken = force ? std::string() : taken_folder(out_dir, names);
  if (!taken.empty()) {
    return usage(out_dir + "/" + taken + " already holds a recording (use --force to overwrite)");
  }
  fp.duration_s = duration_s;
  fp.seed = seed;
  fp.gyro_enabled = gyro;
  sim::FleetResult r;
  const auto t0 = std::chrono::steady_clock::now();
  if (!sim::simulate_fleet(site, planner, specs, fp, &r, &err)) return usage(err);
  const double wall_s =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();

  std::string cmdline = "agvloc-desk fleet";
  for (int i = 1; i < argc; ++i) cmdline += std::string(" ") + argv[i];
  if (!write_fleet(out_dir, names, r, gyro, cmdline, &err)) {
    std::fprintf(stderr, "agvloc-desk fleet: %s\n", err.c_str());
    return 1;
  }
  print_summary(out_dir, specs.size(), r, wall_s);
  return 0;
}

}  // namespace agv::desk
