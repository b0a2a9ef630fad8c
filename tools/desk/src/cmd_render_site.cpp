// agvloc-desk render-site: frames of a site's cameras with the fleet driving its tasks (the fleet
// simulator's routes, reservations and true velocities), parcels and clutter
// (docs/design/site_render.md). One recording folder per camera under --out: meta.yaml (the
// camera's intrinsics), frames/ and frames.csv as `sim` writes them, odom.csv, camera.yaml (the
// camera's 6-DoF pose: the recording reader refuses unknown meta.yaml keys, so it stays beside
// it) and site_truth.csv (every object's pose, corner pixels and visible fraction in every
// frame). A camera on a vehicle adds that vehicle's odom.csv/truth.csv and camera_poses.csv.
#include <CLI/CLI.hpp>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include "agv/recording/recording.hpp"
#include "cli_parse.hpp"
#include "commands.hpp"
#include "render_site_motion.hpp"
#include "site_io.hpp"

namespace agv::desk {

namespace {

namespace fs = std::filesystem;

constexpr std::int64_t kT0Ns = 10'000'000'000LL;  // as agvloc-desk sim: clocks start at 10 s

struct RenderSiteArgs {
  std::string site_path, out_dir, camera_id, cameras = "all";
  std::string vehicle_agv, mount_text = "0,0,1000,0,0,0", intrinsics_text;
  int frames = 10;
  double fps = 10.0, start_s = 10.0, speed_mps = 1.0, scale = 1.0;
  double parcel_fraction = 0.5;
  int clutter = 4;
  std::uint64_t seed = 1;
  bool clean = false, force = false;
};

// One camera to render: fixed in the site, or on fleet vehicle `agv`.
struct View {
  std::string name;
  CameraIntrinsics k;
  site::CeilingCamera fixed;
  bool on_vehicle = false;
  std::size_t agv = 0;
  sim::VehicleCameraMount mount;
};

int usage(const std::string& msg) {
  std::fprintf(stderr, "agvloc-desk render-site: %s\n", msg.c_str());
  return 2;
}

int io_failure(const std::string& msg) {
  std::fprintf(stderr, "agvloc-desk render-site: %s\n", msg.c_str());
  return 1;
}

void write_intrinsics(std::ofstream& f, const CameraIntrinsics& k) {
  f << "width_px: " << k.width_px << "\nheight_px: " << k.height_px << "\nfx: " << k.fx
    << "\nfy: " << k.fy << "\ncx: " << k.cx << "\ncy: " << k.cy << "\ndistortion: [" << k.k1 << ", "
    << k.k2 << ", " << k.p1 << ", " << k.p2 << ", " << k.k3 << "]\n";
}

bool write_camera_yaml(const std::string& dir, const View& v, const site::Site& site,
                       std::string* err) {
  std::ofstream f(fs::path(dir) / "camera.yaml");
  f.precision(17);
  if (v.on_vehicle) {
    f << "# A camera on a vehicle: its pose in the site per frame is in camera_poses.csv\n"
      << "id: " << v.name << "\nvehicle: " << site.fleet[v.agv].id << "\n";
    write_intrinsics(f, v.k);
    f << "mount: {x_mm: " << v.mount.x_mm << ", y_mm: " << v.mount.y_mm
      << ", z_mm: " << v.mount.z_mm << ", yaw_deg: " << rad_to_deg(v.mount.yaw_rad)
      << ", pitch_deg: " << rad_to_deg(v.mount.pitch_rad)
      << ", roll_deg: " << rad_to_deg(v.mount.roll_rad) << "}\n";
  } else {
    f << "# A camera fixed in the site: p_site = r_site_cam * p_cam + t_site_cam_mm\n"
      << "id: " << v.name << "\n";
    write_intrinsics(f, v.k);
    f << "r_site_cam: [";
    for (size_t i = 0; i < 9; ++i) f << (i ? ", " : "") << v.fixed.r_site_cam[i];
    f << "]\nt_site_cam_mm: [" << v.fixed.t_site_cam_mm[0] << ", " << v.fixed.t_site_cam_mm[1]
      << ", " << v.fixed.t_site_cam_mm[2] << "]\n";
  }
  f.close();
  if (!f) *err = "cannot write " + (fs::path(dir) / "camera.yaml").string();
  return static_cast<bool>(f);
}

// One truth row: t_ns, object, id, pose, four corner pixels (NaN when not in front of the
// camera or not applicable) and the visible fraction.
void truth_row(std::FILE* f, std::int64_t t_ns, const char* object, const std::string& id, double x,
               double y, double theta, const Vec2* corners, bool projected, double visible) {
  std::fprintf(f, "%lld,%s,%s,%.3f,%.3f,%.6f", static_cast<long long>(t_ns), object, id.c_str(), x,
               y, theta);
  for (int i = 0; i < 4; ++i) {
    const bool ok = corners && projected;
    std::fprintf(f, ",%.4f,%.4f", ok ? corners[i].x : std::nan(""),
                 ok ? corners[i].y : std::nan(""));
  }
  std::fprintf(f, ",%.4f\n", visible);
}

void write_truth_rows(std::FILE* f, std::int64_t t_ns, const sim::SiteScene& scene,
                      const sim::RenderResult& r) {
  for (const sim::AgvTruth& a : r.agvs) {
    truth_row(f, t_ns, "agv", a.id, a.pose.x_mm, a.pose.y_mm, a.pose.theta_rad,
              a.tag_corners_px.data(), a.projected, a.tag_visible_fraction);
  }
  for (size_t k = 0; k < r.wall_landmarks.size(); ++k) {
    const site::WallLandmark& w = scene.site.wall_landmarks[k];
    truth_row(f, t_ns, "wall_landmark", std::to_string(w.id), w.x_mm, w.y_mm, w.facing_rad,
              r.wall_landmarks[k].corners_px.data(), r.wall_landmarks[k].projected,
              r.wall_landmarks[k].visible_fraction);
  }
  for (const sim::BoxTruth& b : r.parcels) {
    const sim::Parcel& p = scene.parcels[b.index];
    const Vec2 c[4] = {b.centre_px, b.centre_px, b.centre_px, b.centre_px};
    truth_row(f, t_ns, "parcel", std::to_string(b.index), b.centre_site.x, b.centre_site.y,
              scene.agvs[p.agv].pose.theta_rad + p.yaw_rad, c, b.projected, std::nan(""));
  }
  for (const sim::BoxTruth& b : r.clutter) {
    const sim::Clutter& c0 = scene.clutter[b.index];
    const Vec2 c[4] = {b.centre_px, b.centre_px, b.centre_px, b.centre_px};
    truth_row(f, t_ns, c0.kind == sim::ClutterKind::kPerson ? "person" : "pallet",
              std::to_string(b.index), c0.x_mm, c0.y_mm, c0.yaw_rad, c, b.projected, std::nan(""));
  }
}

std::int64_t frame_fleet_ns(const RenderSiteArgs& a, int k) {
  return static_cast<std::int64_t>(std::llround((a.start_s + k / a.fps) * 1e9));
}

// The vehicle's own odometry and truth over the rendered span, clocks as in frames.csv.
bool write_vehicle_streams(const std::string& dir, const RenderSiteArgs& a, const View& v,
                           const FleetMotion& m, std::string* err) {
  const std::int64_t t0 = frame_fleet_ns(a, 0), t1 = frame_fleet_ns(a, a.frames - 1);
  const sim::FleetVehicleOutput& out = m.result.vehicles[v.agv];
  std::vector<recording::OdomRow> odom;
  std::vector<recording::TruthRow> truth;
  for (const sim::FleetOdomSample& o : out.odom) {
    if (o.t_ns >= t0 - 100'000'000 && o.t_ns <= t1 + 100'000'000) {
      odom.push_back({kT0Ns + o.t_ns, o.v_mps, o.omega_radps});
    }
  }
  for (const sim::FleetTruthSample& t : out.truth) {
    if (t.t_ns >= t0 - 100'000'000 && t.t_ns <= t1 + 100'000'000) {
      truth.push_back({kT0Ns + t.t_ns, t.pose.x_mm, t.pose.y_mm, rad_to_deg(t.pose.theta_rad)});
    }
  }
  return recording::write_odom_csv(dir, odom, err) && recording::write_truth_csv(dir, truth, err);
}

void camera_pose_row(std::FILE* f, std::int64_t t_ns, const sim::RenderCamera& rc) {
  std::fprintf(f, "%lld", static_cast<long long>(t_ns));
  for (double r : rc.r_site_cam) std::fprintf(f, ",%.9f", r);
  std::fprintf(f, ",%.3f,%.3f,%.3f\n", rc.t_site_cam_mm[0], rc.t_site_cam_mm[1],
               rc.t_site_cam_mm[2]);
}

struct OpenFiles {
  std::FILE* truth = nullptr;
  std::FILE* poses = nullptr;
  ~OpenFiles() {
    if (truth) std::fclose(truth);
    if (poses) std::fclose(poses);
  }
};

int render_view(const RenderSiteArgs& a, const View& v, const FleetMotion& m,
                sim::SiteScene scene) {
  const std::string dir = (fs::path(a.out_dir) / v.name).string();
  OpenFiles files;
  files.truth = std::fopen((fs::path(dir) / "site_truth.csv").string().c_str(), "w");
  if (v.on_vehicle) {
    files.poses = std::fopen((fs::path(dir) / "camera_poses.csv").string().c_str(), "w");
  }
  if (!files.truth || (v.on_vehicle && !files.poses)) return io_failure("cannot write in " + dir);
  std::fprintf(files.truth,
               "t_ns,object,id,x_mm,y_mm,theta_rad,c0_x,c0_y,c1_x,c1_y,c2_x,c2_y,"
               "c3_x,c3_y,visible_fraction\n");
  if (files.poses)
    std::fprintf(files.poses, "t_ns,r00,r01,r02,r10,r11,r12,r20,r21,r22,x_mm,y_mm,z_mm\n");
  const sim::SiteRenderParams params =
      a.clean ? sim::SiteRenderParams{} : sim::realistic_site_params();
  const sim::SiteFrameRenderer renderer(v.k);
  std::vector<recording::FrameRow> frames;
  std::string err;
  for (int k = 0; k < a.frames; ++k) {
    const std::int64_t t_fleet = frame_fleet_ns(a, k);
    scene.agvs = fleet_states_at(m, t_fleet);
    const sim::RenderCamera rc =
        v.on_vehicle ? sim::RenderCamera::on_vehicle(v.k, scene.agvs[v.agv].pose, v.mount)
                     : sim::RenderCamera::from_ceiling(v.fixed);
    const sim::RenderResult r = renderer.render(
        scene, rc, params, a.seed * 0x2545F4914F6CDD1DULL + static_cast<unsigned>(k));
    if (r.image.empty()) return io_failure("the scene could not be rendered for " + v.name);
    const std::int64_t t_ns = kT0Ns + t_fleet;
    char name[40];
    std::snprintf(name, sizeof name, "frames/%06d.png", k);
    if (!recording::write_frame_png(dir, name, r.image, &err)) return io_failure(err);
    frames.push_back({t_ns, name});
    write_truth_rows(files.truth, t_ns, scene, r);
    if (files.poses) camera_pose_row(files.poses, t_ns, rc);
  }
  if (!recording::write_frames_csv(dir, frames, &err) ||
      !(v.on_vehicle ? write_vehicle_streams(dir, a, v, m, &err)
                     : recording::write_odom_csv(dir, {}, &err))) {
    return io_failure(err);
  }
  std::printf("agvloc-desk render-site: wrote %s: %zu frames %dx%d\n", dir.c_str(), frames.size(),
              v.k.width_px, v.k.height_px);
  return 0;
}

}  // namespace

namespace {

// The cameras asked for; false with *error (exit 2) for an unknown camera or vehicle, a bad mount
// or intrinsics.
bool select_views(const RenderSiteArgs& a, const site::Site& site, std::vector<View>* views,
                  std::string* error) {
  std::string ids;
  for (const site::CeilingCamera& c : site.cameras) ids += (ids.empty() ? "" : ", ") + c.id;
  const std::string want = a.camera_id.empty() ? a.cameras : a.camera_id;
  if (a.camera_id.empty() && a.cameras != "all" && a.cameras != "none") {
    return (*error = "--cameras takes 'all' or 'none' (one camera: --camera ID)", false);
  }
  for (const site::CeilingCamera& c : site.cameras) {
    if (want == "all" || want == c.id) {
      View v;
      v.name = c.id;
      v.fixed = c;
      v.fixed.intrinsics = v.k = scale_intrinsics(c.intrinsics, a.scale);
      views->push_back(v);
    }
  }
  if (!a.camera_id.empty() && views->empty()) {
    *error = "no camera '" + a.camera_id + "' in " + a.site_path +
             (ids.empty() ? " (it has no cameras)" : " (cameras: " + ids + ")");
    return false;
  }
  if (a.vehicle_agv.empty()) return true;
  View v;
  v.on_vehicle = true;
  v.name = a.vehicle_agv + "-forward";
  std::string agvs;
  bool found = false;
  for (std::size_t i = 0; i < site.fleet.size(); ++i) {
    agvs += (agvs.empty() ? "" : ", ") + site.fleet[i].id;
    if (site.fleet[i].id == a.vehicle_agv) v.agv = i, found = true;
  }
  if (!found) {
    *error = "no AGV '" + a.vehicle_agv + "' in " + a.site_path +
             (agvs.empty() ? " (it has no fleet)" : " (fleet: " + agvs + ")");
    return false;
  }
  for (char c : a.vehicle_agv) {
    if (c == '/' || c == '\\' || a.vehicle_agv == "." || a.vehicle_agv == "..") {
      return (*error = "AGV id '" + a.vehicle_agv + "' cannot name a folder", false);
    }
  }
  if (!parse_mount(a.mount_text, &v.mount, error)) return false;
  CameraIntrinsics k{1280, 800, 700.0, 700.0, 639.5, 399.5};
  if (!a.intrinsics_text.empty() && !parse_intrinsics(a.intrinsics_text, &k, error)) return false;
  v.k = scale_intrinsics(k, a.scale);
  for (const View& o : *views) {
    if (o.name == v.name)
      return (*error = "camera id '" + v.name + "' is the vehicle camera's folder", false);
  }
  views->push_back(v);
  return true;
}

// Nothing is overwritten without --force; with it, only the folders about to be written go.
bool prepare_out(const RenderSiteArgs& a, const std::vector<View>& views, std::string* error) {
  std::error_code ec;
  const fs::path out(a.out_dir);
  if (fs::exists(out, ec) && !fs::is_directory(out, ec)) {
    return (*error = a.out_dir + " exists and is not a folder", false);
  }
  if (fs::is_directory(out, ec) && !fs::is_empty(out, ec) && !a.force) {
    return (*error = a.out_dir + " is not empty (use --force to overwrite its camera folders)",
            false);
  }
  for (const View& v : views) {
    if (a.force) fs::remove_all(out / v.name, ec);
    fs::create_directories(out / v.name, ec);
    if (ec)
      return (*error = "cannot create " + (out / v.name).string() + ": " + ec.message(), false);
  }
  return true;
}

sim::SiteScene make_scene(const site::Site& site, const RenderSiteArgs& a, const FleetMotion& m) {
  sim::SiteScene s;
  s.site = site;
  s.agvs = fleet_states_at(m, frame_fleet_ns(a, 0));
  sim::add_random_parcels(&s, a.parcel_fraction, a.seed);
  add_clutter_off_paths(&s, m, a.clutter, a.seed);
  s.floor.seed = a.seed;
  return s;
}

bool write_view_meta(const RenderSiteArgs& a, const View& v, const site::Site& site,
                     const std::string& source, std::string* err) {
  const std::string dir = (fs::path(a.out_dir) / v.name).string();
  recording::Meta meta;
  meta.camera.intrinsics = v.k;  // the floor-camera mount fields do not apply: see camera.yaml
  double size = site.fleet.empty() ? 160.0 : site.fleet.front().tag_size_mm;
  if (v.on_vehicle) {
    for (const site::WallLandmark& w : site.wall_landmarks) {
      if (w.family == site::LandmarkFamily::kTag36h11) {
        size = w.size_mm;
        break;
      }
    }
  }
  meta.landmark_size_mm = size;
  meta.landmark_family = "tag36h11";
  meta.source = source;
  return recording::write_meta(dir, meta, err) && write_camera_yaml(dir, v, site, err);
}

void add_options(CLI::App& app, RenderSiteArgs& a) {
  app.add_option("--site", a.site_path, "The site file (site.yaml)")->required();
  app.add_option("--out", a.out_dir, "Folder to write: one recording folder per camera")
      ->required();
  app.add_option("--camera", a.camera_id, "Render only this ceiling camera");
  app.add_option("--cameras", a.cameras, "'all' ceiling cameras (default) or 'none'");
  app.add_option("--vehicle-camera", a.vehicle_agv,
                 "Also render a camera on this AGV (folder <AGV id>-forward)");
  app.add_option("--mount", a.mount_text,
                 "Vehicle camera: x_mm,y_mm,z_mm,yaw_deg,pitch_deg,roll_deg in the vehicle frame")
      ->capture_default_str();
  app.add_option("--intrinsics", a.intrinsics_text,
                 "Vehicle camera: WxH,fx,fy,cx,cy (default 1280x800,700,700,639.5,399.5)");
  app.add_option("--scale", a.scale, "Scale every camera's image size and focal lengths")
      ->check(CLI::Range(0.01, 8.0))
      ->capture_default_str();
  app.add_option("--frames", a.frames, "Frames to render")->check(CLI::Range(1, 100000));
  app.add_option("--fps", a.fps, "Frame rate")->check(CLI::Range(0.1, 200.0));
  app.add_option("--start-s", a.start_s, "Fleet time of the first frame (vehicles start at rest)")
      ->check(CLI::Range(0.0, 86400.0))
      ->capture_default_str();
  app.add_option("--speed-mps", a.speed_mps, "The fleet's cruise speed")
      ->check(CLI::Range(0.05, 5.0))
      ->capture_default_str();
  app.add_option("--parcel-fraction", a.parcel_fraction, "Share of trays carrying parcels")
      ->check(CLI::Range(0.0, 1.0))
      ->capture_default_str();
  app.add_option("--clutter", a.clutter, "People and pallets on free floor, off the fleet's paths")
      ->check(CLI::Range(0, 1000))
      ->capture_default_str();
  app.add_option("--seed", a.seed, "Seed of tasks, parcels, clutter and noise");
  app.add_flag("--clean", a.clean, "No motion blur, noise, vignetting or light gradient");
  app.add_flag("--force", a.force, "Write into a non-empty --out, replacing the camera folders");
}

}  // namespace

int render_site_command(int argc, char** argv) {
  CLI::App app{
      "Render frames of a site's cameras (ceiling cameras and one on a vehicle) with the "
      "fleet driving its tasks, parcels and clutter (docs/design/site_render.md)",
      "agvloc-desk render-site"};
  RenderSiteArgs a;
  add_options(app, a);
  if (const int parse_rc = cli::parse(app, argc, argv); parse_rc >= 0) return parse_rc;
  site::Site site;
  std::string err;
  if (!load_site(a.site_path, &site, &err)) {
    std::fputs(err.c_str(), stderr);
    return 2;
  }
  std::vector<View> views;
  if (!select_views(a, site, &views, &err)) return usage(err);
  if (views.empty()) return usage("no camera to render (the site has none: add --vehicle-camera)");
  FleetMotion motion;
  const double end_s = a.start_s + (a.frames - 1) / a.fps + 0.5;
  if (!simulate_site_fleet(site, end_s, a.speed_mps, a.seed, &motion, &err)) {
    return usage("fleet: " + err);
  }
  if (!prepare_out(a, views, &err)) return usage(err);
  std::string source = "agvloc-desk render-site";
  for (int i = 1; i < argc; ++i) source += std::string(" ") + argv[i];
  const sim::SiteScene scene = make_scene(site, a, motion);
  for (const View& v : views) {
    if (!write_view_meta(a, v, site, source, &err)) return io_failure(err);
    if (const int rc = render_view(a, v, motion, scene); rc != 0) return rc;
  }
  std::printf(
      "agvloc-desk render-site: %zu cameras, %d frames each, %zu vehicles, %zu parcels, "
      "%zu clutter objects\n",
      views.size(), a.frames, scene.agvs.size(), scene.parcels.size(), scene.clutter.size());
  return 0;
}

}  // namespace agv::desk
