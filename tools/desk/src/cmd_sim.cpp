// agvloc-desk sim: writes a simulated recording (docs/design/simulator.md,
// docs/guide/recording.md).
#include <CLI/CLI.hpp>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <memory>
#include <string>
#include <vector>

#include "agv/recording/recording.hpp"
#include "agv/sim/imu_model.hpp"
#include "agv/sim/render.hpp"
#include "agv/sim/trajectory.hpp"
#include "cli_parse.hpp"
#include "commands.hpp"
#include "config.hpp"

namespace agv::desk {

namespace {

namespace fs = std::filesystem;

// Monotonic clock starts at an arbitrary 10 s, like a freshly booted controller.
constexpr std::int64_t kT0_ns = 10'000'000'000LL;

// The command line, as given (units as the options state them).
struct SimArgs {
  std::string out_dir, map_path, trajectory = "line", profile = "640x480", degrade = "realistic",
                                 payload_mode = "full", odom_sample = "period_mean", misprint,
                                 family = "qr";
  double duration_s = 60.0, fps = 30.0, odom_hz = 100.0, speed_mps = 0.5, exposure_ms = 2.0;
  double grid_spacing_mm = 1000.0, k1 = 0.0, k2 = 0.0, occluder = 0.0, dirt = 0.0;
  double occluder_overhang_mm = -1.0;
  double qr_cover = 0.0;
  int scratches = 0;
  std::uint64_t seed = 1;
  bool force = false;
  sim::OdometryParams op;
  int scuffs = 0;
  double ink_variation = 0.0;
  std::vector<std::uint32_t> worn_ids;
  // The camera mounting (docs/design/frames.md); defaults = the profile's centred, untilted camera.
  double mount_x_mm = 0.0, mount_y_mm = 0.0, mount_yaw_deg = 0.0, roll_deg = 0.0, pitch_deg = 0.0;
  double mount_height_mm = 0.0;
  double odom_time_offset_ms = 0.0, yaw_bias_degps = 0.0;
  bool nominal_meta = false;
  // The gyro (imu.csv): a typical industrial MEMS gyro by default (docs/design/simulator.md
  // "Gyro"). The CLI takes degrees, as data sheets state them; the model takes radians.
  bool gyro = true;
  sim::GyroParams gp;
  double gyro_noise_dps_rthz = 0.01, gyro_bias_dps = 0.2, gyro_bias_instability_dps = 0.005,
         gyro_bias_rw_dps_rts = 1e-4, gyro_range_dps = 250.0, gyro_latency_ms = 0.0;
};

// What the arguments make: the camera, the renderer's options, the floor and the drive.
struct SimSetup {
  sim::TrajectoryParams tp;
  CameraModel cam;
  sim::RenderOptions ro;
  sim::PayloadMode pm = sim::PayloadMode::kFull;
  unsigned long misprint_id = 0;
  Vec2 misprint_offset_mm{};
  LandmarkMap map = sim::default_landmark_grid();
  sim::Trajectory traj;
  sim::Scene scene;
};

// What the run writes besides the frames.
struct SimRun {
  std::int64_t duration_ns = 0;
  std::vector<sim::SlipEvent> slips;
  std::vector<recording::OdomRow> odom;
  std::vector<std::int64_t> truth_times;  // since kT0_ns
  std::vector<recording::ImuRow> imu;
  std::vector<recording::FrameRow> frames;
  std::int64_t frames_with_landmark = 0;
  double render_s = 0.0;
};

int sim_usage_error(const std::string& msg) {
  std::fprintf(stderr, "agvloc-desk sim: %s\n", msg.c_str());
  return 2;
}

void add_drive_options(CLI::App& app, SimArgs& a) {
  app.add_option("--out", a.out_dir, "Recording directory to write")->required();
  app.add_option("--map", a.map_path,
                 "Landmark map (docs/design/landmark.md); default: built-in 5x5 grid at 1 m "
                 "(= tools/maps/default_grid.csv)");
  app.add_option("--trajectory", a.trajectory, "line|square|circle|figure8|lawnmower|calibration")
      ->capture_default_str();
  app.add_option("--duration-s", a.duration_s, "Recording length in seconds")
      ->check(CLI::Range(0.1, 3600.0))
      ->capture_default_str();
  app.add_option("--fps", a.fps, "Frame rate")
      ->check(CLI::Range(1.0, 200.0))
      ->capture_default_str();
  app.add_option("--odom-hz", a.odom_hz, "Odometry (and truth) rate")
      ->check(CLI::Range(10.0, 1000.0))
      ->capture_default_str();
  app.add_option("--slip-rate-per-s", a.op.slip_rate_per_s, "Mean wheel-slip events per second")
      ->check(CLI::Range(0.0, 10.0));
  app.add_option("--slip-excess", a.op.slip_excess,
                 "Fraction the slipping wheel over-reports (0.05 = 5 %)")
      ->check(CLI::Range(0.0, 2.0));
  app.add_option("--odom-sample", a.odom_sample,
                 "period_mean (mean over the period ending at the sample, as encoder counts give) "
                 "| instant (true speed at the sample time)")
      ->capture_default_str();
  app.add_option("--misprint", a.misprint,
                 "ID:DX_MM:DY_MM: landmark ID's QR claims its map pose shifted by (DX, DY) mm "
                 "(needs --payload full)");
  app.add_option("--seed", a.seed, "Seed for every random effect (same seed = same recording)")
      ->capture_default_str();
  app.add_option("--speed-mps", a.speed_mps, "Cruise speed")
      ->check(CLI::Range(0.01, 5.0))
      ->capture_default_str();
  app.add_option("--profile", a.profile, "Camera profile 640x480|1280x800")->capture_default_str();
  app.add_option("--degrade", a.degrade,
                 "clean (anti-aliasing only) | realistic (defocus, motion "
                 "blur, illumination gradient, noise)")
      ->capture_default_str();
  app.add_option("--exposure-ms", a.exposure_ms, "Exposure time for motion blur (realistic only)")
      ->check(CLI::Range(0.0, 50.0))
      ->capture_default_str();
  app.add_option("--family", a.family,
                 "qr (QR landmarks) | tag36h11 (AprilTags, tag id = map id; replay with "
                 "landmark.family: tag36h11 and the map)")
      ->capture_default_str();
  app.add_option("--payload", a.payload_mode, "full (pose in the QR) | id (pose from the map)")
      ->capture_default_str();
  app.add_option("--grid-spacing-mm", a.grid_spacing_mm, "Landmark grid spacing the path follows")
      ->check(CLI::Range(200.0, 100000.0))
      ->capture_default_str();
  app.add_option("--k1", a.k1, "Radial distortion k1 of the simulated lens")->capture_default_str();
  app.add_option("--k2", a.k2, "Radial distortion k2 of the simulated lens")->capture_default_str();
}

void add_print_options(CLI::App& app, SimArgs& a) {
  app.add_option("--occluder-fraction", a.occluder, "Fraction of every landmark border covered")
      ->check(CLI::Range(0.0, 1.0))
      ->capture_default_str();
  app.add_option("--occluder-overhang-mm", a.occluder_overhang_mm,
                 "How far the occluder reaches beyond the border (mm; default 3 border-width "
                 "units; past a tag's 15 mm margin it breaks libapriltag's quad)")
      ->check(CLI::Range(0.0, 1000.0));
  app.add_option("--qr-cover-fraction", a.qr_cover,
                 "Fraction of every landmark's QR code under an opaque patch (border intact)")
      ->check(CLI::Range(0.0, 1.0 / 3.0))
      ->capture_default_str();
  app.add_option("--scratches", a.scratches, "Scratches per landmark")
      ->check(CLI::Range(0, 100))
      ->capture_default_str();
  app.add_option("--dirt", a.dirt, "Mean dirt spots per landmark")
      ->check(CLI::Range(0.0, 100.0))
      ->capture_default_str();
  app.add_option("--scuffs", a.scuffs,
                 "Patches of ink rubbed off along the border edges, per landmark")
      ->check(CLI::Range(0, 100))
      ->capture_default_str();
  app.add_option("--ink-variation", a.ink_variation,
                 "Ink lighter (fading across the print) and paper darker by up to this fraction")
      ->check(CLI::Range(0.0, 1.0))
      ->capture_default_str();
  app.add_option("--wear-landmarks", a.worn_ids,
                 "Landmark ids the degradations (occluder, QR cover, scratches, dirt, scuffs, ink "
                 "variation) apply to, comma-separated; default: all")
      ->delimiter(',');
}

void add_mounting_options(CLI::App& app, SimArgs& a) {
  app.add_option("--mount-offset-x-mm", a.mount_x_mm, "Camera optical centre in the vehicle, x")
      ->check(CLI::Range(-5000.0, 5000.0))
      ->capture_default_str();
  app.add_option("--mount-offset-y-mm", a.mount_y_mm, "Camera optical centre in the vehicle, y")
      ->check(CLI::Range(-5000.0, 5000.0))
      ->capture_default_str();
  app.add_option("--mount-yaw-deg", a.mount_yaw_deg, "Camera yaw (image axes vs vehicle)")
      ->check(CLI::Range(-180.0, 180.0))
      ->capture_default_str();
  app.add_option("--mount-height-mm", a.mount_height_mm,
                 "Camera height above the floor; 0 = the profile's 200 mm")
      ->check(CLI::Range(0.0, 5000.0))
      ->capture_default_str();
  app.add_option("--roll-deg", a.roll_deg, "Camera roll (docs/design/frames.md \"Camera tilt\")")
      ->check(CLI::Range(-45.0, 45.0))
      ->capture_default_str();
  app.add_option("--pitch-deg", a.pitch_deg, "Camera pitch (docs/design/frames.md \"Camera tilt\")")
      ->check(CLI::Range(-45.0, 45.0))
      ->capture_default_str();
}

void add_odometry_options(CLI::App& app, SimArgs& a) {
  app.add_option("--odom-scale-error", a.op.scale_error,
                 "Both wheels report this fraction too much (speed scale error)")
      ->check(CLI::Range(-0.5, 0.5))
      ->capture_default_str();
  app.add_option("--odom-asymmetry", a.op.scale_asymmetry,
                 "Right minus left wheel scale error (curves straight runs)")
      ->check(CLI::Range(-0.5, 0.5))
      ->capture_default_str();
  app.add_option("--odom-yaw-scale-error", a.op.yaw_rate_scale_error,
                 "Reported yaw rate scaled by (1 + this) on top of the wheels")
      ->check(CLI::Range(-0.5, 0.5))
      ->capture_default_str();
  app.add_option("--odom-yaw-bias-degps", a.yaw_bias_degps, "Added to the reported yaw rate")
      ->check(CLI::Range(-10.0, 10.0))
      ->capture_default_str();
  app.add_option("--odom-noise-mps", a.op.noise_mps, "White noise per wheel speed sample (sigma)")
      ->check(CLI::Range(0.0, 1.0))
      ->capture_default_str();
  app.add_option("--odom-time-offset-ms", a.odom_time_offset_ms,
                 "Odometry timestamps late by this (camera-odometry clock offset)")
      ->check(CLI::Range(-1000.0, 1000.0))
      ->capture_default_str();
  app.add_flag("--nominal-meta", a.nominal_meta,
               "meta.yaml records the profile's nominal camera mounting instead of the simulated "
               "one (a recording made with an uncalibrated configuration)");
}

void add_gyro_options(CLI::App& app, SimArgs& a) {
  // The gyro (imu.csv): a typical industrial MEMS gyro by default (docs/design/simulator.md
  // "Gyro"). The CLI takes degrees, as data sheets state them; the model takes radians.
  app.add_flag("--gyro,!--no-gyro", a.gyro,
               "Write imu.csv from a simulated MEMS gyro (default on; --no-gyro: no imu.csv)");
  app.add_option("--gyro-hz", a.gp.rate_hz, "Gyro output data rate")
      ->check(CLI::Range(1.0, 10000.0))
      ->capture_default_str();
  app.add_option("--gyro-noise-dps-rthz", a.gyro_noise_dps_rthz,
                 "Gyro white rate noise density (angle random walk), deg/s/sqrt(Hz)")
      ->check(CLI::Range(0.0, 10.0))
      ->capture_default_str();
  app.add_option("--gyro-bias-dps", a.gyro_bias_dps, "Gyro constant bias, deg/s")
      ->check(CLI::Range(-100.0, 100.0))
      ->capture_default_str();
  app.add_option("--gyro-bias-instability-dps", a.gyro_bias_instability_dps,
                 "Gyro bias instability: sigma of a Gauss-Markov bias, deg/s")
      ->check(CLI::Range(0.0, 10.0))
      ->capture_default_str();
  app.add_option("--gyro-bias-corr-s", a.gp.bias_correlation_s,
                 "Correlation time of the Gauss-Markov bias, s")
      ->check(CLI::Range(0.01, 1e6))
      ->capture_default_str();
  app.add_option("--gyro-bias-rw-dps-rts", a.gyro_bias_rw_dps_rts,
                 "Gyro bias random walk (rate random walk), deg/s/sqrt(s)")
      ->check(CLI::Range(0.0, 1.0))
      ->capture_default_str();
  app.add_option("--gyro-scale-error", a.gp.scale_error,
                 "Gyro scale error: reports (1 + this) x the true rate (0.003 = 0.3 %)")
      ->check(CLI::Range(-0.4, 0.4))
      ->capture_default_str();
  app.add_option("--gyro-range-dps", a.gyro_range_dps,
                 "Gyro full scale: samples are clipped to +-this, deg/s")
      ->check(CLI::Range(1.0, 5000.0))
      ->capture_default_str();
  app.add_option("--gyro-latency-ms", a.gyro_latency_ms,
                 "Gyro timestamps late by this (its latency / clock offset; negative: early)")
      ->check(CLI::Range(-1000.0, 1000.0))
      ->capture_default_str();
  app.add_flag("--force", a.force, "Overwrite an existing recording in --out");
}

// The command line; -1 to go on, else the exit code.
int parse_args(int argc, char** argv, SimArgs* args) {
  SimArgs& a = *args;
  CLI::App app{
      "Write a simulated recording: textured floor with landmarks, a differential-drive "
      "vehicle, odometry with errors, ground truth (docs/design/simulator.md)",
      "agvloc-desk sim"};
  add_drive_options(app, a);
  add_print_options(app, a);
  add_mounting_options(app, a);
  add_odometry_options(app, a);
  add_gyro_options(app, a);
  return cli::parse(app, argc, argv);
}

// The trajectory kind and the camera. -1 to go on, else the exit code.
int make_camera(const SimArgs& a, SimSetup* setup) {
  SimSetup& s = *setup;
  if (!sim::parse_trajectory_kind(a.trajectory, &s.tp.kind)) {
    return sim_usage_error("unknown trajectory '" + a.trajectory + "'");
  }
  if (a.profile == "640x480") {
    s.cam = CameraModel::default_640x480();
  } else if (a.profile == "1280x800") {
    s.cam = CameraModel::default_1280x800();
  } else {
    return sim_usage_error("unknown profile '" + a.profile + "' (640x480 or 1280x800)");
  }
  s.cam.intrinsics.k1 = a.k1;
  s.cam.intrinsics.k2 = a.k2;
  s.cam.mount.offset_x_mm = a.mount_x_mm;
  s.cam.mount.offset_y_mm = a.mount_y_mm;
  s.cam.mount.yaw_rad = deg_to_rad(a.mount_yaw_deg);
  if (a.mount_height_mm > 0.0) {
    if (a.mount_height_mm < 10.0) return sim_usage_error("--mount-height-mm must be >= 10");
    s.cam.mount.height_mm = a.mount_height_mm;
  }
  s.cam.mount.roll_rad = deg_to_rad(a.roll_deg);
  s.cam.mount.pitch_rad = deg_to_rad(a.pitch_deg);
  return -1;
}

// The renderer's degradations, the payload and the misprint. -1 to go on, else the exit code.
int make_print(SimArgs& a, SimSetup* setup) {
  SimSetup& s = *setup;
  if (a.degrade == "realistic") {
    s.ro = sim::realistic_options();
    s.ro.exposure_s = a.exposure_ms * 1e-3;
  } else if (a.degrade != "clean") {
    return sim_usage_error("unknown --degrade '" + a.degrade + "' (clean or realistic)");
  }
  s.ro.occluder_border_fraction = a.occluder;
  s.ro.occluder_overhang_mm = a.occluder_overhang_mm;
  s.ro.scratches_per_landmark = a.scratches;
  s.ro.qr_cover_fraction = a.qr_cover;
  s.ro.dirt_spots_per_landmark = a.dirt;
  s.ro.degradation_seed = a.seed * 7919 + 3;
  s.ro.edge_scuffs_per_landmark = a.scuffs;
  s.ro.ink_variation = a.ink_variation;
  s.ro.worn_ids = a.worn_ids;
  if (a.payload_mode == "full") {
    s.pm = sim::PayloadMode::kFull;
  } else if (a.payload_mode == "id") {
    s.pm = sim::PayloadMode::kIdOnly;
  } else {
    return sim_usage_error("unknown --payload '" + a.payload_mode + "' (full or id)");
  }

  if (!sim::parse_odom_sample_timing(a.odom_sample, &a.op.timing)) {
    return sim_usage_error("unknown --odom-sample '" + a.odom_sample +
                           "' (period_mean or instant)");
  }
  if (!a.misprint.empty()) {
    char tail = 0;
    if (std::sscanf(a.misprint.c_str(), "%lu:%lf:%lf%c", &s.misprint_id, &s.misprint_offset_mm.x,
                    &s.misprint_offset_mm.y, &tail) != 3 ||
        a.misprint.front() == '-' || s.misprint_id == 0 || s.misprint_id > 0xFFFFFFFFUL ||
        !std::isfinite(s.misprint_offset_mm.x) || !std::isfinite(s.misprint_offset_mm.y)) {
      return sim_usage_error("--misprint '" + a.misprint + "': expected ID:DX_MM:DY_MM");
    }
    if (s.pm != sim::PayloadMode::kFull) return sim_usage_error("--misprint needs --payload full");
  }
  return -1;
}

// The gyro model, the map, the drive over it and the scene. -1 to go on, else the exit code.
int make_world(SimArgs& a, SimSetup* setup) {
  SimSetup& s = *setup;
  a.gp.noise_density_radps_rthz = deg_to_rad(a.gyro_noise_dps_rthz);
  a.gp.bias_radps = deg_to_rad(a.gyro_bias_dps);
  a.gp.bias_instability_radps = deg_to_rad(a.gyro_bias_instability_dps);
  a.gp.bias_random_walk_radps_rts = deg_to_rad(a.gyro_bias_rw_dps_rts);
  a.gp.range_radps = deg_to_rad(a.gyro_range_dps);
  a.gp.latency_ns = std::llround(a.gyro_latency_ms * 1e6);
  a.gp.seed = a.seed;

  std::string err;
  if (a.gyro && !sim::check_gyro_params(a.gp, &err)) return sim_usage_error(err);
  if (!a.map_path.empty()) {
    if (!config::load_map_file(a.map_path, &s.map, &err)) return sim_usage_error(err);
    if (s.map.entries.empty()) return sim_usage_error(a.map_path + ": no landmarks");
  }
  // A worn id the floor does not have would silently leave every landmark clean.
  for (std::uint32_t id : a.worn_ids) {
    if (!s.map.find(id)) {
      return sim_usage_error("--wear-landmarks: landmark " + std::to_string(id) +
                             " is not in the map");
    }
  }

  // Lay the path over the map's bounding box.
  double minx = 1e300, miny = 1e300, maxx = -1e300, maxy = -1e300;
  for (const auto& [id, e] : s.map.entries) {
    minx = std::min(minx, e.pose.x_mm);
    miny = std::min(miny, e.pose.y_mm);
    maxx = std::max(maxx, e.pose.x_mm);
    maxy = std::max(maxy, e.pose.y_mm);
  }
  s.tp.grid_origin_mm = {minx, miny};
  s.tp.grid_spacing_mm = a.grid_spacing_mm;
  s.tp.grid_columns =
      std::max(2, static_cast<int>(std::lround((maxx - minx) / a.grid_spacing_mm)) + 1);
  s.tp.grid_rows =
      std::max(2, static_cast<int>(std::lround((maxy - miny) / a.grid_spacing_mm)) + 1);
  s.tp.lawnmower_rows = s.tp.grid_rows - (s.tp.grid_rows % 2);  // even: the loop closes
  s.tp.speed_mps = a.speed_mps;
  if (!sim::make_trajectory(s.tp, &s.traj, &err)) return sim_usage_error("trajectory: " + err);

  LandmarkFamily landmark_family = LandmarkFamily::kQr;
  if (!parse_landmark_family(a.family, &landmark_family)) {
    return sim_usage_error("unknown --family '" + a.family + "' (qr or tag36h11)");
  }
  if (landmark_family == LandmarkFamily::kTag36h11) {
    if (!a.misprint.empty()) return sim_usage_error("--misprint needs --family qr");
    if (!sim::make_tag_scene(s.map, AprilTagGeometry{}, &s.scene, &err))
      return sim_usage_error(err);
  } else if (!sim::make_scene(s.map, LandmarkGeometry{}, s.pm, &s.scene, &err)) {
    return sim_usage_error(err);
  }
  s.scene.floor.seed = a.seed;
  if (!a.misprint.empty() &&
      !sim::misprint_landmark(&s.scene, static_cast<std::uint32_t>(s.misprint_id),
                              s.misprint_offset_mm, &err)) {
    return sim_usage_error("--misprint: " + err);
  }
  return -1;
}

// The recording directory and its meta.yaml. -1 to go on, else the exit code.
int start_recording(SimArgs& a, const SimSetup& s, const std::string& cmdline) {
  std::error_code ec;
  if (fs::exists(fs::path(a.out_dir) / "meta.yaml", ec) && !a.force) {
    return sim_usage_error(a.out_dir + " already holds a recording (use --force to overwrite)");
  }
  if (a.force) {
    fs::remove_all(fs::path(a.out_dir) / "frames", ec);
    fs::remove(fs::path(a.out_dir) / "imu.csv",
               ec);  // a --no-gyro rewrite must not keep an old one
  }
  fs::create_directories(a.out_dir, ec);
  if (ec) {
    std::fprintf(stderr, "agvloc-desk sim: cannot create %s: %s\n", a.out_dir.c_str(),
                 ec.message().c_str());
    return 1;
  }

  std::string err;
  recording::Meta meta;
  meta.camera = s.cam;
  if (a.nominal_meta) {
    meta.camera.mount =
        (a.profile == "640x480" ? CameraModel::default_640x480() : CameraModel::default_1280x800())
            .mount;
  }
  a.op.yaw_rate_bias_radps = deg_to_rad(a.yaw_bias_degps);
  meta.landmark_size_mm = s.scene.geometry.size_mm;
  meta.landmark_family = a.family;  // replay runs the printed family without a --config saying so
  // The sample timing is part of what the recording means (the replay's fusion must agree), so
  // it is stated even when it is the default. meta.yaml has no key for it
  // (docs/guide/recording.md).
  meta.source = cmdline + " (odometry samples: " + sim::to_string(a.op.timing) + ")";
  if (!recording::write_meta(a.out_dir, meta, &err)) {
    std::fprintf(stderr, "agvloc-desk sim: %s\n", err.c_str());
    return 1;
  }
  return -1;
}

// Odometry (with its slips), the truth times and the gyro's samples.
void simulate_inputs(SimArgs& a, const SimSetup& s, SimRun* r) {
  r->duration_ns = static_cast<std::int64_t>(std::llround(a.duration_s * 1e9));
  a.op.seed = a.seed;
  const auto odom_period_ns = static_cast<std::int64_t>(std::llround(1e9 / a.odom_hz));
  a.op.period_ns = odom_period_ns;
  r->slips = sim::make_slip_events(a.op, r->duration_ns);
  const auto odom_time_offset_ns =
      static_cast<std::int64_t>(std::llround(a.odom_time_offset_ms * 1e6));

  for (std::int64_t t = 0; t <= r->duration_ns; t += odom_period_ns) {
    const sim::OdometrySample o = sim::odometry_sample(a.op, r->slips, s.traj, t);
    r->odom.push_back({kT0_ns + t + odom_time_offset_ns, o.v_mps, o.omega_radps});
    r->truth_times.push_back(t);
  }

  // The gyro's own samples (own rate and stamps), on the same clock as odometry and frames.
  if (a.gyro) {
    for (const sim::ImuSample& g : sim::simulate_gyro(a.gp, s.traj, r->duration_ns)) {
      r->imu.push_back({kT0_ns + g.t_ns, g.gyro_z_radps});
    }
  }
}

// The frames, rendered and written. -1 to go on, else the exit code.
int render_frames(const SimArgs& a, const SimSetup& s, SimRun* r) {
  std::string err;
  const sim::FrameRenderer renderer(s.scene, s.cam);
  std::mt19937_64 noise_rng(a.seed * 0x2545F4914F6CDD1DULL + 1);
  const auto n_frames = static_cast<std::int64_t>(std::floor(a.duration_s * a.fps)) + 1;
  const auto t_start = std::chrono::steady_clock::now();
  for (std::int64_t k = 0; k < n_frames; ++k) {
    const auto t = static_cast<std::int64_t>(std::llround(static_cast<double>(k) * 1e9 / a.fps));
    if (t > r->duration_ns) break;
    const sim::MotionState m = sim::trajectory_state(s.traj, t);
    sim::RenderOptions fo = s.ro;
    fo.speed_mps = m.v_mps;
    fo.yaw_rate_radps = m.omega_radps;
    const cv::Mat img = renderer.render(m.pose, fo, noise_rng);
    if (!renderer.visible_landmarks(m.pose).empty()) ++r->frames_with_landmark;
    char name[40];
    std::snprintf(name, sizeof name, "frames/%06lld.png", static_cast<long long>(k));
    if (!recording::write_frame_png(a.out_dir, name, img, &err)) {
      std::fprintf(stderr, "agvloc-desk sim: %s\n", err.c_str());
      return 1;
    }
    r->frames.push_back({kT0_ns + t, name});
    r->truth_times.push_back(t);
  }
  r->render_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t_start).count();
  return -1;
}

// Truth and the tables; the summary line. The exit code.
int write_tables(const SimArgs& a, const SimSetup& s, SimRun* r) {
  std::string err;
  // Truth at every odometry and frame time (exact pose at each exposure mid-time).
  std::sort(r->truth_times.begin(), r->truth_times.end());
  r->truth_times.erase(std::unique(r->truth_times.begin(), r->truth_times.end()),
                       r->truth_times.end());
  std::vector<recording::TruthRow> truth;
  truth.reserve(r->truth_times.size());
  for (std::int64_t t : r->truth_times) {
    const sim::MotionState m = sim::trajectory_state(s.traj, t);
    truth.push_back({kT0_ns + t, m.pose.x_mm, m.pose.y_mm, rad_to_deg(m.pose.theta_rad)});
  }
  if (!recording::write_frames_csv(a.out_dir, r->frames, &err) ||
      !recording::write_odom_csv(a.out_dir, r->odom, &err) ||
      !recording::write_truth_csv(a.out_dir, truth, &err) ||
      (a.gyro && !recording::write_imu_csv(a.out_dir, r->imu, &err))) {
    std::fprintf(stderr, "agvloc-desk sim: %s\n", err.c_str());
    return 1;
  }
  std::printf(
      "agvloc-desk sim: wrote %s: %zu frames (%lld with a landmark in view), %zu odometry rows, "
      "%zu truth rows, %s; trajectory %s, lap %.1f m, %zu slip events; %.1f s to render\n",
      a.out_dir.c_str(), r->frames.size(), static_cast<long long>(r->frames_with_landmark),
      r->odom.size(), truth.size(),
      a.gyro ? (std::to_string(r->imu.size()) + " gyro rows").c_str() : "no gyro",
      sim::to_string(s.tp.kind), s.traj.length_mm / 1000.0, r->slips.size(), r->render_s);
  return 0;
}

}  // namespace

int sim(int argc, char** argv) {
  SimArgs a;
  if (const int rc = parse_args(argc, argv, &a); rc >= 0) return rc;
  auto s = std::make_unique<SimSetup>();
  if (const int rc = make_camera(a, s.get()); rc >= 0) return rc;
  if (const int rc = make_print(a, s.get()); rc >= 0) return rc;
  if (const int rc = make_world(a, s.get()); rc >= 0) return rc;
  std::string cmdline = "agvloc-desk sim";
  for (int i = 1; i < argc; ++i) cmdline += std::string(" ") + argv[i];
  if (const int rc = start_recording(a, *s, cmdline); rc >= 0) return rc;
  SimRun r;
  simulate_inputs(a, *s, &r);
  if (const int rc = render_frames(a, *s, &r); rc >= 0) return rc;
  return write_tables(a, *s, &r);
}

}  // namespace agv::desk
