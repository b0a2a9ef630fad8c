// agvloc-desk calibrate ranging-mount: the second camera's mount from a recorded drive past the
// site's rack landmarks, with the vehicle's poses from a replay of the same recording on the
// floor camera and wheels alone (solver: calib_ranging_mount.hpp; procedure: docs/guide/ranging.md,
// "Calibrating the mount"). Exit 0 solved, 1 no mount (named error) or write failure, 2 bad input.
#include <CLI/CLI.hpp>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <sstream>

#include "calib_cli.hpp"
#include "calib_ranging_mount.hpp"
#include "commands.hpp"
#include "config.hpp"
#include "desk_input.hpp"
#include "ranging_stream.hpp"
#include "report.hpp"

namespace agv::desk {

// A namespace of its own: the desk library is built in unity batches, where every file's
// anonymous namespace in agv::desk is one (cmd_calibrate_ceiling.cpp has a named_error too).
namespace ranging_mount_cmd {

namespace {

namespace fs = std::filesystem;
constexpr double kRadToDeg = 180.0 / kPi;
constexpr const char* kCmd = "calibrate ranging-mount";
// Two output ticks further apart than this are not interpolated across (a gap in poses.csv).
constexpr std::int64_t kMaxTickGapNs = 50'000'000;

struct Args {
  std::string config_path, rec_dir, replay_dir, out_path;
  double max_pose_sigma_mm = 2.0, max_pose_sigma_deg = 0.1;
  rcal::Options opt;
};

int named_error(const char* name, const std::string& what, int code) {
  std::fprintf(stderr, "agvloc-desk %s: error %s: %s\n", kCmd, name, what.c_str());
  return code;
}

// The floor localizer's pose at t_ns, linear between the two ticks around it; false unless both
// are localized (health 1) and within the sigma limits.
bool pose_at(const std::vector<PoseRow>& ticks, std::int64_t t_ns, const Args& a,
             rcal::MountSighting* s) {
  const auto it = std::lower_bound(ticks.begin(), ticks.end(), t_ns,
                                   [](const PoseRow& r, std::int64_t t) { return r.t_ns < t; });
  if (it == ticks.begin() || it == ticks.end()) return false;
  const PoseRow& b = *it;
  const PoseRow& p = *(it - 1);
  if (b.t_ns - p.t_ns > kMaxTickGapNs) return false;
  for (const PoseRow* r : {&p, &b}) {
    if (!r->valid || r->health != 1 || !(r->sigma_x_mm <= a.max_pose_sigma_mm) ||
        !(r->sigma_y_mm <= a.max_pose_sigma_mm) ||
        !(r->sigma_theta_rad * kRadToDeg <= a.max_pose_sigma_deg))
      return false;
  }
  const double w = b.t_ns == p.t_ns ? 0.0 : double(t_ns - p.t_ns) / double(b.t_ns - p.t_ns);
  const double dth = std::remainder(b.pose.theta_rad - p.pose.theta_rad, 2.0 * kPi);
  s->vehicle = {p.pose.x_mm + w * (b.pose.x_mm - p.pose.x_mm),
                p.pose.y_mm + w * (b.pose.y_mm - p.pose.y_mm), p.pose.theta_rad + w * dth};
  s->vehicle_sigma = {std::max(p.sigma_x_mm, b.sigma_x_mm), std::max(p.sigma_y_mm, b.sigma_y_mm),
                      std::max(p.sigma_theta_rad, b.sigma_theta_rad)};
  return true;
}

// The replay must be of the floor camera and wheels alone: with the second camera on (its
// summary has a "ranging camera" line), its poses already carry the mount being calibrated.
bool floor_only_replay(const std::string& replay_dir, std::string* error) {
  std::ifstream f(fs::path(replay_dir) / "summary.txt");
  std::string line;
  while (std::getline(f, line)) {
    if (line.rfind("ranging camera", 0) != 0) continue;
    *error = replay_dir +
             "/summary.txt: the replay ran with the second camera; replay the recording "
             "without ranging_camera.enabled so the poses come from the floor camera alone";
    return false;
  }
  return true;
}

struct Input {
  config::Config cfg;
  app::RackSite site;
  std::vector<rcal::MountSighting> sightings;
  int frames = 0, frames_at_poses = 0, unreadable = 0;
};

// Reads the configuration, the site, the poses and the stream, and measures every frame taken
// at a usable pose. Returns 0, or the exit code after printing the error.
int load_input(const Args& a, Input* in) {
  std::vector<std::string> errors;
  // As replay reads it: the floor camera's calibration may come from the recording (unused here).
  if (!config::load_config(a.config_path, &in->cfg, &errors, config::ConfigUse::kReplay)) {
    for (const auto& e : errors) std::fprintf(stderr, "agvloc-desk %s: %s\n", kCmd, e.c_str());
    return 2;
  }
  const config::RangingCameraSection& rc = in->cfg.ranging_camera;
  if (!rc.enabled) {
    return named_error("no-ranging-camera",
                       a.config_path +
                           ": ranging_camera.enabled is false (the camera, its "
                           "intrinsics, site and a first mount are needed)",
                       2);
  }
  std::string err;
  if (!app::load_rack_site(rc.site_file, &in->site, &err)) return named_error("bad-site", err, 2);
  if (!floor_only_replay(a.replay_dir, &err)) return named_error("ranging-replay", err, 2);
  std::vector<PoseRow> ticks;
  if (!read_poses_csv((fs::path(a.replay_dir) / "poses.csv").string(), &ticks, &err))
    return named_error("bad-poses", err, 2);
  recording::Recording stream;
  std::vector<std::string> warnings;
  if (!app::read_ranging_stream(a.rec_dir, rc, &stream, &warnings, &err))
    return named_error("bad-recording", a.rec_dir + ": " + err, 2);
  for (const auto& w : warnings)
    std::fprintf(stderr, "agvloc-desk %s: warning: %s\n", kCmd, w.c_str());
  ranging::LandmarkObserver observer(rc.intrinsics, rc.mount, in->site.walls);
  if (observer.status() != ranging::TableStatus::kOk) {
    return named_error(ranging::table_status_name(observer.status()), observer.status_detail(), 2);
  }
  const std::int64_t offset_ns = std::llround(rc.time_offset_ms * 1e6);
  for (std::size_t i = 0; i < stream.frames.size(); ++i) {
    ++in->frames;
    rcal::MountSighting at;
    at.t_ns = stream.frames[i].t_ns + offset_ns;
    if (!pose_at(ticks, at.t_ns, a, &at)) continue;
    ++in->frames_at_poses;
    cv::Mat gray;
    if (!recording::load_frame(stream, i, &gray, &err)) {
      ++in->unreadable;
      continue;
    }
    for (const ranging::LandmarkObservation& o : observer.observe(gray).seen) {
      at.landmark_index = o.landmark_index;
      at.corners_undistorted_px = o.corners_undistorted_px;
      at.corner_sigma_px = o.corner_sigma_px;
      in->sightings.push_back(at);
    }
  }
  return 0;
}

void print_mount(const ranging::RangingMount& before, const rcal::Result& r) {
  const double was[6] = {before.x_mm,
                         before.y_mm,
                         before.z_mm,
                         before.roll_rad * kRadToDeg,
                         before.pitch_rad * kRadToDeg,
                         before.yaw_rad * kRadToDeg};
  const double now[6] = {r.mount.x_mm,
                         r.mount.y_mm,
                         r.mount.z_mm,
                         r.mount.roll_rad * kRadToDeg,
                         r.mount.pitch_rad * kRadToDeg,
                         r.mount.yaw_rad * kRadToDeg};
  const char* names[6] = {"x_mm", "y_mm", "z_mm", "roll_deg", "pitch_deg", "yaw_deg"};
  std::printf("  key          configured   calibrated     change      sigma\n");
  for (std::size_t i = 0; i < 6; ++i) {
    const double s = r.sigma[i] * (i < 3 ? 1.0 : kRadToDeg);
    std::printf("  %-10s %12.4f %12.4f %+10.4f %10.4f\n", names[i], was[i], now[i], now[i] - was[i],
                s);
  }
}

// The snippet `agvloc-desk config apply` merges: the mount, and its sigma as the configuration's
// mount sigma (the largest of the angles' and of the offsets').
std::string snippet(const rcal::Result& r) {
  const double s_deg = std::max({r.sigma[3], r.sigma[4], r.sigma[5]}) * kRadToDeg;
  const double s_mm = std::max({r.sigma[0], r.sigma[1], r.sigma[2]});
  std::ostringstream o;
  o.precision(6);
  o << std::fixed;
  o << "# agvloc-desk calibrate ranging-mount: corner RMS " << r.rms_px << " px over "
    << r.sightings_used << " sightings in " << r.frames_used << " frames\n"
    << "ranging_camera:\n  mount:\n"
    << "    x_mm: " << r.mount.x_mm << "\n    y_mm: " << r.mount.y_mm
    << "\n    z_mm: " << r.mount.z_mm << "\n    roll_deg: " << r.mount.roll_rad * kRadToDeg
    << "\n    pitch_deg: " << r.mount.pitch_rad * kRadToDeg
    << "\n    yaw_deg: " << r.mount.yaw_rad * kRadToDeg << "\n    sigma_deg: " << s_deg
    << "\n    sigma_mm: " << s_mm << "\n";
  return o.str();
}

void add_options(CLI::App& app, Args* a) {
  app.add_option("--config", a->config_path,
                 "Vehicle configuration with ranging_camera (intrinsics, site, a first mount)")
      ->required();
  app.add_option("--recording", a->rec_dir, "Recording of the drive, with its ranging/ stream")
      ->required();
  app.add_option("--replay", a->replay_dir,
                 "Output folder of `agvloc replay` of that recording without the second camera "
                 "(its poses.csv)")
      ->required();
  app.add_option("--out", a->out_path, "Write the mount as a configuration snippet (YAML)");
  app.add_option("--max-pose-sigma-mm", a->max_pose_sigma_mm,
                 "Use frames where the floor localizer's x and y sigma are at most this")
      ->check(calib::finite_in(0.01, 100.0))
      ->capture_default_str();
  app.add_option("--max-pose-sigma-deg", a->max_pose_sigma_deg,
                 "and its heading sigma at most this")
      ->check(calib::finite_in(0.001, 10.0))
      ->capture_default_str();
  app.add_option("--corner-sigma-px", a->opt.corner_sigma_px,
                 "Corner noise (px, per coordinate) where the observer states none")
      ->check(calib::finite_in(0.01, 10.0))
      ->capture_default_str();
}

}  // namespace

int run(int argc, char** argv) {
  CLI::App app{
      "The second camera's mount from a drive past the site's rack landmarks, the vehicle "
      "localized by the floor camera (docs/guide/ranging.md, \"Calibrating the mount\"). Exit 0 "
      "solved, 1 no mount, 2 bad input",
      "agvloc-desk calibrate ranging-mount"};
  Args a;
  add_options(app, &a);
  CLI11_PARSE(app, argc, argv);
  Input in;
  if (const int rc = load_input(a, &in); rc != 0) return rc;
  const ranging::RangingMount& before = in.cfg.ranging_camera.mount;
  a.opt.focal_sigma_rel = in.cfg.ranging_camera.focal_sigma_rel;
  a.opt.principal_sigma_px = in.cfg.ranging_camera.calibration_sigma_px;
  std::printf(
      "%d frames, %d at localized poses within the sigma limits (%d unreadable), %zu "
      "landmark sightings\n",
      in.frames, in.frames_at_poses, in.unreadable, in.sightings.size());
  const rcal::Result r = rcal::solve_mount(in.cfg.ranging_camera.intrinsics, in.site.walls,
                                           in.sightings, before, a.opt);
  if (r.error == rcal::Error::kTooFewSightings || r.error == rcal::Error::kSolveFailed)
    return named_error(rcal::to_string(r.error), r.message, 1);
  for (const rcal::LandmarkResidual& l : r.landmarks) {
    if (l.rejected)
      std::printf(
          "rejected landmark %u: corner RMS %.2f px in %d sightings (surveyed wrong, or "
          "moved?)\n",
          l.id, l.rms_px, l.sightings);
  }
  std::printf("mount (corner RMS %.3f px, reduced chi-square %.2f, %d sightings in %d frames):\n",
              r.rms_px, r.reduced_chi2, r.sightings_used, r.frames_used);
  print_mount(before, r);
  if (r.error == rcal::Error::kPoorlyObserved)
    return named_error(rcal::to_string(r.error), r.message, 1);
  if (!a.out_path.empty()) {
    std::ofstream f(a.out_path, std::ios::binary | std::ios::trunc);
    f << snippet(r);
    if (!f) return named_error("write-failed", a.out_path + ": cannot be written", 1);
    std::printf("wrote %s (merge it with agvloc-desk config apply)\n", a.out_path.c_str());
  }
  return 0;
}

}  // namespace ranging_mount_cmd

int calibrate_ranging_mount(int argc, char** argv) { return ranging_mount_cmd::run(argc, argv); }

}  // namespace agv::desk
