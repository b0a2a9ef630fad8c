// agvloc-desk render-site: frames of one ceiling camera of a site, with the site's fleet on the
// floor, parcels and clutter (docs/design/site_render.md). Writes a recording folder: meta.yaml
// (the camera's intrinsics), frames/ and frames.csv as `sim` does, plus camera.yaml (the camera's
// 6-DoF pose in the site) and site_truth.csv (every object's pose, corner pixels and visible
// fraction in every frame).
#include <CLI/CLI.hpp>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include "agv/recording/recording.hpp"
#include "agv/sim/site_render.hpp"
#include "commands.hpp"
#include "site_io.hpp"

namespace agv::desk {

namespace {

namespace fs = std::filesystem;

struct RenderSiteArgs {
  std::string site_path, out_dir, camera_id;
  int frames = 10;
  double fps = 10.0;
  double speed_mps = 1.0;
  double loaded_fraction = 0.5;
  int people = 2, pallets = 2;
  std::uint64_t seed = 1;
  bool clean = false, force = false;
};

int render_site_usage(const std::string& msg) {
  std::fprintf(stderr, "agvloc-desk render-site: %s\n", msg.c_str());
  return 2;
}

bool write_camera_yaml(const std::string& dir, const site::CeilingCamera& c, std::string* err) {
  std::ofstream f(fs::path(dir) / "camera.yaml");
  const CameraIntrinsics& k = c.intrinsics;
  f.precision(17);
  f << "# The rendered ceiling camera: p_site = r_site_cam * p_cam + t_site_cam_mm\n"
    << "id: " << c.id << "\nwidth_px: " << k.width_px << "\nheight_px: " << k.height_px
    << "\nfx: " << k.fx << "\nfy: " << k.fy << "\ncx: " << k.cx << "\ncy: " << k.cy
    << "\ndistortion: [" << k.k1 << ", " << k.k2 << ", " << k.p1 << ", " << k.p2 << ", " << k.k3
    << "]\nr_site_cam: [";
  for (size_t i = 0; i < 9; ++i) f << (i ? ", " : "") << c.r_site_cam[i];
  f << "]\nt_site_cam_mm: [" << c.t_site_cam_mm[0] << ", " << c.t_site_cam_mm[1] << ", "
    << c.t_site_cam_mm[2] << "]\n";
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
    std::fprintf(f, ",%.4f,%.4f", ok ? corners[i].x : std::nan(""), ok ? corners[i].y : std::nan(""));
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

// The fleet at random free places, driving straight ahead at speed_mps (one seed = one scene).
sim::SiteScene make_render_scene(const site::Site& site, const RenderSiteArgs& a) {
  sim::SiteScene s;
  s.site = site;
  double radius = 0.0;
  for (const site::FleetAgv& v : site.fleet) radius = std::max(radius, v.radius_mm);
  const std::vector<Pose2> poses =
      sim::random_free_poses(site, static_cast<int>(site.fleet.size()), radius, a.seed);
  s.site.fleet.resize(poses.size());  // a site too full for its fleet renders fewer vehicles
  for (const Pose2& p : poses) s.agvs.push_back({p, a.speed_mps, 0.0});
  sim::add_random_parcels(&s, a.loaded_fraction, a.seed);
  sim::add_random_clutter(&s, a.people, a.pallets, a.seed);
  s.floor.seed = a.seed;
  return s;
}

int render_frames(const RenderSiteArgs& a, const site::CeilingCamera& cam,
                  sim::SiteScene scene) {
  std::string err;
  std::FILE* tf = std::fopen((fs::path(a.out_dir) / "site_truth.csv").string().c_str(), "w");
  if (!tf) return render_site_usage("cannot write site_truth.csv in " + a.out_dir);
  std::fprintf(tf, "t_ns,object,id,x_mm,y_mm,theta_rad,c0_x,c0_y,c1_x,c1_y,c2_x,c2_y,c3_x,c3_y,"
                   "visible_fraction\n");
  const sim::SiteRenderParams params =
      a.clean ? sim::SiteRenderParams{} : sim::realistic_site_params();
  const sim::RenderCamera rc = sim::RenderCamera::from_ceiling(cam);
  const sim::SiteFrameRenderer renderer(cam.intrinsics);
  constexpr std::int64_t kT0_ns = 10'000'000'000LL;
  std::vector<recording::FrameRow> frames;
  const std::vector<sim::AgvState> start = scene.agvs;
  for (int k = 0; k < a.frames; ++k) {
    const double t_s = k / a.fps;
    for (size_t i = 0; i < start.size(); ++i) {
      scene.agvs[i].pose = sim::advance_agv_pose(start[i], t_s);
    }
    const sim::RenderResult r =
        renderer.render(scene, rc, params, a.seed * 0x2545F4914F6CDD1DULL + static_cast<unsigned>(k));
    if (r.image.empty()) {
      std::fclose(tf);
      return render_site_usage("the scene could not be rendered");
    }
    const auto t_ns = kT0_ns + static_cast<std::int64_t>(std::llround(t_s * 1e9));
    char name[40];
    std::snprintf(name, sizeof name, "frames/%06d.png", k);
    if (!recording::write_frame_png(a.out_dir, name, r.image, &err)) {
      std::fclose(tf);
      return render_site_usage(err);
    }
    frames.push_back({t_ns, name});
    write_truth_rows(tf, t_ns, scene, r);
  }
  const bool closed = std::fclose(tf) == 0;
  if (!closed || !recording::write_frames_csv(a.out_dir, frames, &err) ||
      !recording::write_odom_csv(a.out_dir, {}, &err)) {
    return render_site_usage(closed ? err : "cannot write site_truth.csv");
  }
  std::printf("agvloc-desk render-site: wrote %s: %zu frames of camera %s, %zu vehicles, "
              "%zu parcels, %zu clutter objects\n",
              a.out_dir.c_str(), frames.size(), cam.id.c_str(), scene.agvs.size(),
              scene.parcels.size(), scene.clutter.size());
  return 0;
}

}  // namespace

int render_site_command(int argc, char** argv) {
  CLI::App app{"Render frames of one ceiling camera of a site with its fleet, parcels and clutter "
               "(docs/design/site_render.md)",
               "agvloc-desk render-site"};
  RenderSiteArgs a;
  app.add_option("--site", a.site_path, "The site file (site.yaml)")->required();
  app.add_option("--out", a.out_dir, "Recording directory to write")->required();
  app.add_option("--camera", a.camera_id, "Id of the site's ceiling camera")->required();
  app.add_option("--frames", a.frames, "Frames to render")->check(CLI::Range(1, 100000));
  app.add_option("--fps", a.fps, "Frame rate")->check(CLI::Range(0.1, 200.0));
  app.add_option("--speed-mps", a.speed_mps, "Vehicles drive straight ahead at this speed")
      ->check(CLI::Range(0.0, 5.0));
  app.add_option("--loaded-fraction", a.loaded_fraction, "Share of vehicles carrying parcels")
      ->check(CLI::Range(0.0, 1.0));
  app.add_option("--people", a.people, "People standing on the floor")->check(CLI::Range(0, 1000));
  app.add_option("--pallets", a.pallets, "Pallets on the floor")->check(CLI::Range(0, 1000));
  app.add_option("--seed", a.seed, "Seed of placements, parcels and noise");
  app.add_flag("--clean", a.clean, "No motion blur, noise or vignetting");
  app.add_flag("--force", a.force, "Overwrite an existing recording in --out");
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return app.exit(e) == 0 ? 0 : 2;
  }
  site::Site site;
  std::string err;
  if (!load_site(a.site_path, &site, &err)) {
    std::fputs(err.c_str(), stderr);
    return 2;
  }
  const site::CeilingCamera* cam = nullptr;
  std::string ids;
  for (const site::CeilingCamera& c : site.cameras) {
    if (c.id == a.camera_id) cam = &c;
    ids += (ids.empty() ? "" : ", ") + c.id;
  }
  if (!cam) {
    return render_site_usage("no camera '" + a.camera_id + "' in " + a.site_path +
                             (ids.empty() ? " (it has no cameras)" : " (cameras: " + ids + ")"));
  }
  std::error_code ec;
  if (fs::exists(fs::path(a.out_dir) / "meta.yaml", ec) && !a.force) {
    return render_site_usage(a.out_dir + " already holds a recording (use --force to overwrite)");
  }
  if (a.force) fs::remove_all(fs::path(a.out_dir) / "frames", ec);
  fs::create_directories(a.out_dir, ec);
  if (ec) return render_site_usage("cannot create " + a.out_dir + ": " + ec.message());
  recording::Meta meta;
  meta.camera.intrinsics = cam->intrinsics;  // the mount fields do not apply: see camera.yaml
  meta.landmark_size_mm = site.fleet.empty() ? 160.0 : site.fleet.front().tag_size_mm;
  meta.landmark_family = "tag36h11";
  meta.source = "agvloc-desk render-site";
  for (int i = 1; i < argc; ++i) meta.source += std::string(" ") + argv[i];
  if (!recording::write_meta(a.out_dir, meta, &err) || !write_camera_yaml(a.out_dir, *cam, &err)) {
    return render_site_usage(err);
  }
  return render_frames(a, *cam, make_render_scene(site, a));
}

}  // namespace agv::desk
