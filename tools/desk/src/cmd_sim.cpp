// agvloc-desk sim: writes a simulated recording (docs/design/simulator.md,
// docs/guide/recording.md).
#include <CLI/CLI.hpp>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <vector>

#include "agv/recording/recording.hpp"
#include "agv/sim/imu_model.hpp"
#include "agv/sim/render.hpp"
#include "agv/sim/trajectory.hpp"
#include "commands.hpp"
#include "config.hpp"

namespace agv::desk {

namespace {

namespace fs = std::filesystem;

}  // namespace

int sim(int argc, char** argv) {
  CLI::App app{
      "Write a simulated recording: textured floor with landmarks, a differential-drive "
      "vehicle, odometry with errors, ground truth (docs/design/simulator.md)",
      "agvloc-desk sim"};
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
  app.add_option("--out", out_dir, "Recording directory to write")->required();
  app.add_option("--map", map_path,
                 "Landmark map (docs/design/landmark.md); default: built-in 5x5 grid at 1 m "
                 "(= tools/maps/default_grid.csv)");
  app.add_option("--trajectory", trajectory, "line|square|circle|figure8|lawnmower|calibration")
      ->capture_default_str();
  app.add_option("--duration-s", duration_s, "Recording length in seconds")
      ->check(CLI::Range(0.1, 3600.0))
      ->capture_default_str();
  app.add_option("--fps", fps, "Frame rate")->check(CLI::Range(1.0, 200.0))->capture_default_str();
  app.add_option("--odom-hz", odom_hz, "Odometry (and truth) rate")
      ->check(CLI::Range(10.0, 1000.0))
      ->capture_default_str();
  sim::OdometryParams op;
  app.add_option("--slip-rate-per-s", op.slip_rate_per_s, "Mean wheel-slip events per second")
      ->check(CLI::Range(0.0, 10.0));
  app.add_option("--slip-excess", op.slip_excess,
                 "Fraction the slipping wheel over-reports (0.05 = 5 %)")
      ->check(CLI::Range(0.0, 2.0));
  app.add_option("--odom-sample", odom_sample,
                 "period_mean (mean over the period ending at the sample, as encoder counts give) "
                 "| instant (true speed at the sample time)")
      ->capture_default_str();
  app.add_option("--misprint", misprint,
                 "ID:DX_MM:DY_MM: landmark ID's QR claims its map pose shifted by (DX, DY) mm "
                 "(needs --payload full)");
  app.add_option("--seed", seed, "Seed for every random effect (same seed = same recording)")
      ->capture_default_str();
  app.add_option("--speed-mps", speed_mps, "Cruise speed")
      ->check(CLI::Range(0.01, 5.0))
      ->capture_default_str();
  app.add_option("--profile", profile, "Camera profile 640x480|1280x800")->capture_default_str();
  app.add_option("--degrade", degrade,
                 "clean (anti-aliasing only) | realistic (defocus, motion "
                 "blur, illumination gradient, noise)")
      ->capture_default_str();
  app.add_option("--exposure-ms", exposure_ms, "Exposure time for motion blur (realistic only)")
      ->check(CLI::Range(0.0, 50.0))
      ->capture_default_str();
  app.add_option("--family", family,
                 "qr (QR landmarks) | tag36h11 (AprilTags, tag id = map id; replay with "
                 "landmark.family: tag36h11 and the map)")
      ->capture_default_str();
  app.add_option("--payload", payload_mode, "full (pose in the QR) | id (pose from the map)")
      ->capture_default_str();
  app.add_option("--grid-spacing-mm", grid_spacing_mm, "Landmark grid spacing the path follows")
      ->check(CLI::Range(200.0, 100000.0))
      ->capture_default_str();
  app.add_option("--k1", k1, "Radial distortion k1 of the simulated lens")->capture_default_str();
  app.add_option("--k2", k2, "Radial distortion k2 of the simulated lens")->capture_default_str();
  app.add_option("--occluder-fraction", occluder, "Fraction of every landmark border covered")
      ->check(CLI::Range(0.0, 1.0))
      ->capture_default_str();
  app.add_option("--occluder-overhang-mm", occluder_overhang_mm,
                 "How far the occluder reaches beyond the border (mm; default 3 border-width "
                 "units; past a tag's 15 mm margin it breaks libapriltag's quad)")
      ->check(CLI::Range(0.0, 1000.0));
  app.add_option("--qr-cover-fraction", qr_cover,
                 "Fraction of every landmark's QR code under an opaque patch (border intact)")
      ->check(CLI::Range(0.0, 1.0 / 3.0))
      ->capture_default_str();
  app.add_option("--scratches", scratches, "Scratches per landmark")
      ->check(CLI::Range(0, 100))
      ->capture_default_str();
  app.add_option("--dirt", dirt, "Mean dirt spots per landmark")
      ->check(CLI::Range(0.0, 100.0))
      ->capture_default_str();
  int scuffs = 0;
  double ink_variation = 0.0;
  std::vector<std::uint32_t> worn_ids;
  app.add_option("--scuffs", scuffs,
                 "Patches of ink rubbed off along the border edges, per landmark")
      ->check(CLI::Range(0, 100))
      ->capture_default_str();
  app.add_option("--ink-variation", ink_variation,
                 "Ink lighter (fading across the print) and paper darker by up to this fraction")
      ->check(CLI::Range(0.0, 1.0))
      ->capture_default_str();
  app.add_option("--wear-landmarks", worn_ids,
                 "Landmark ids the degradations (occluder, QR cover, scratches, dirt, scuffs, ink "
                 "variation) apply to, comma-separated; default: all")
      ->delimiter(',');
  // The camera mounting (docs/design/frames.md); defaults = the profile's centred, untilted camera.
  double mount_x_mm = 0.0, mount_y_mm = 0.0, mount_yaw_deg = 0.0, roll_deg = 0.0, pitch_deg = 0.0;
  double mount_height_mm = 0.0;
  app.add_option("--mount-offset-x-mm", mount_x_mm, "Camera optical centre in the vehicle, x")
      ->check(CLI::Range(-5000.0, 5000.0))
      ->capture_default_str();
  app.add_option("--mount-offset-y-mm", mount_y_mm, "Camera optical centre in the vehicle, y")
      ->check(CLI::Range(-5000.0, 5000.0))
      ->capture_default_str();
  app.add_option("--mount-yaw-deg", mount_yaw_deg, "Camera yaw (image axes vs vehicle)")
      ->check(CLI::Range(-180.0, 180.0))
      ->capture_default_str();
  app.add_option("--mount-height-mm", mount_height_mm,
                 "Camera height above the floor; 0 = the profile's 200 mm")
      ->check(CLI::Range(0.0, 5000.0))
      ->capture_default_str();
  app.add_option("--roll-deg", roll_deg, "Camera roll (docs/design/frames.md \"Camera tilt\")")
      ->check(CLI::Range(-45.0, 45.0))
      ->capture_default_str();
  app.add_option("--pitch-deg", pitch_deg, "Camera pitch (docs/design/frames.md \"Camera tilt\")")
      ->check(CLI::Range(-45.0, 45.0))
      ->capture_default_str();
  double odom_time_offset_ms = 0.0, yaw_bias_degps = 0.0;
  bool nominal_meta = false;
  app.add_option("--odom-scale-error", op.scale_error,
                 "Both wheels report this fraction too much (speed scale error)")
      ->check(CLI::Range(-0.5, 0.5))
      ->capture_default_str();
  app.add_option("--odom-asymmetry", op.scale_asymmetry,
                 "Right minus left wheel scale error (curves straight runs)")
      ->check(CLI::Range(-0.5, 0.5))
      ->capture_default_str();
  app.add_option("--odom-yaw-scale-error", op.yaw_rate_scale_error,
                 "Reported yaw rate scaled by (1 + this) on top of the wheels")
      ->check(CLI::Range(-0.5, 0.5))
      ->capture_default_str();
  app.add_option("--odom-yaw-bias-degps", yaw_bias_degps, "Added to the reported yaw rate")
      ->check(CLI::Range(-10.0, 10.0))
      ->capture_default_str();
  app.add_option("--odom-noise-mps", op.noise_mps, "White noise per wheel speed sample (sigma)")
      ->check(CLI::Range(0.0, 1.0))
      ->capture_default_str();
  app.add_option("--odom-time-offset-ms", odom_time_offset_ms,
                 "Odometry timestamps late by this (camera-odometry clock offset)")
      ->check(CLI::Range(-1000.0, 1000.0))
      ->capture_default_str();
  app.add_flag("--nominal-meta", nominal_meta,
               "meta.yaml records the profile's nominal camera mounting instead of the simulated "
               "one (a recording made with an uncalibrated configuration)");
  // The gyro (imu.csv): a typical industrial MEMS gyro by default (docs/design/simulator.md
  // "Gyro"). The CLI takes degrees, as data sheets state them; the model takes radians.
  bool gyro = true;
  sim::GyroParams gp;
  double gyro_noise_dps_rthz = 0.01, gyro_bias_dps = 0.2, gyro_bias_instability_dps = 0.005,
         gyro_bias_rw_dps_rts = 1e-4, gyro_range_dps = 250.0, gyro_latency_ms = 0.0;
  app.add_flag("--gyro,!--no-gyro", gyro,
               "Write imu.csv from a simulated MEMS gyro (default on; --no-gyro: no imu.csv)");
  app.add_option("--gyro-hz", gp.rate_hz, "Gyro output data rate")
      ->check(CLI::Range(1.0, 10000.0))
      ->capture_default_str();
  app.add_option("--gyro-noise-dps-rthz", gyro_noise_dps_rthz,
                 "Gyro white rate noise density (angle random walk), deg/s/sqrt(Hz)")
      ->check(CLI::Range(0.0, 10.0))
      ->capture_default_str();
  app.add_option("--gyro-bias-dps", gyro_bias_dps, "Gyro constant bias, deg/s")
      ->check(CLI::Range(-100.0, 100.0))
      ->capture_default_str();
  app.add_option("--gyro-bias-instability-dps", gyro_bias_instability_dps,
                 "Gyro bias instability: sigma of a Gauss-Markov bias, deg/s")
      ->check(CLI::Range(0.0, 10.0))
      ->capture_default_str();
  app.add_option("--gyro-bias-corr-s", gp.bias_correlation_s,
                 "Correlation time of the Gauss-Markov bias, s")
      ->check(CLI::Range(0.01, 1e6))
      ->capture_default_str();
  app.add_option("--gyro-bias-rw-dps-rts", gyro_bias_rw_dps_rts,
                 "Gyro bias random walk (rate random walk), deg/s/sqrt(s)")
      ->check(CLI::Range(0.0, 1.0))
      ->capture_default_str();
  app.add_option("--gyro-scale-error", gp.scale_error,
                 "Gyro scale error: reports (1 + this) x the true rate (0.003 = 0.3 %)")
      ->check(CLI::Range(-0.4, 0.4))
      ->capture_default_str();
  app.add_option("--gyro-range-dps", gyro_range_dps,
                 "Gyro full scale: samples are clipped to +-this, deg/s")
      ->check(CLI::Range(1.0, 5000.0))
      ->capture_default_str();
  app.add_option("--gyro-latency-ms", gyro_latency_ms,
                 "Gyro timestamps late by this (its latency / clock offset; negative: early)")
      ->check(CLI::Range(-1000.0, 1000.0))
      ->capture_default_str();
  app.add_flag("--force", force, "Overwrite an existing recording in --out");
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return app.exit(e) == 0 ? 0 : 2;
  }

  auto usage_error = [](const std::string& msg) {
    std::fprintf(stderr, "agvloc-desk sim: %s\n", msg.c_str());
    return 2;
  };
  sim::TrajectoryParams tp;
  if (!sim::parse_trajectory_kind(trajectory, &tp.kind)) {
    return usage_error("unknown trajectory '" + trajectory + "'");
  }
  CameraModel cam;
  if (profile == "640x480") {
    cam = CameraModel::default_640x480();
  } else if (profile == "1280x800") {
    cam = CameraModel::default_1280x800();
  } else {
    return usage_error("unknown profile '" + profile + "' (640x480 or 1280x800)");
  }
  cam.intrinsics.k1 = k1;
  cam.intrinsics.k2 = k2;
  cam.mount.offset_x_mm = mount_x_mm;
  cam.mount.offset_y_mm = mount_y_mm;
  cam.mount.yaw_rad = deg_to_rad(mount_yaw_deg);
  if (mount_height_mm > 0.0) {
    if (mount_height_mm < 10.0) return usage_error("--mount-height-mm must be >= 10");
    cam.mount.height_mm = mount_height_mm;
  }
  cam.mount.roll_rad = deg_to_rad(roll_deg);
  cam.mount.pitch_rad = deg_to_rad(pitch_deg);
  sim::RenderOptions ro;
  if (degrade == "realistic") {
    ro = sim::realistic_options();
    ro.exposure_s = exposure_ms * 1e-3;
  } else if (degrade != "clean") {
    return usage_error("unknown --degrade '" + degrade + "' (clean or realistic)");
  }
  ro.occluder_border_fraction = occluder;
  ro.occluder_overhang_mm = occluder_overhang_mm;
  ro.scratches_per_landmark = scratches;
  ro.qr_cover_fraction = qr_cover;
  ro.dirt_spots_per_landmark = dirt;
  ro.degradation_seed = seed * 7919 + 3;
  ro.edge_scuffs_per_landmark = scuffs;
  ro.ink_variation = ink_variation;
  ro.worn_ids = worn_ids;
  sim::PayloadMode pm;
  if (payload_mode == "full") {
    pm = sim::PayloadMode::kFull;
  } else if (payload_mode == "id") {
    pm = sim::PayloadMode::kIdOnly;
  } else {
    return usage_error("unknown --payload '" + payload_mode + "' (full or id)");
  }

  if (!sim::parse_odom_sample_timing(odom_sample, &op.timing)) {
    return usage_error("unknown --odom-sample '" + odom_sample + "' (period_mean or instant)");
  }
  unsigned long misprint_id = 0;
  Vec2 misprint_offset_mm{};
  if (!misprint.empty()) {
    char tail = 0;
    if (std::sscanf(misprint.c_str(), "%lu:%lf:%lf%c", &misprint_id, &misprint_offset_mm.x,
                    &misprint_offset_mm.y, &tail) != 3 ||
        misprint.front() == '-' || misprint_id == 0 || misprint_id > 0xFFFFFFFFUL ||
        !std::isfinite(misprint_offset_mm.x) || !std::isfinite(misprint_offset_mm.y)) {
      return usage_error("--misprint '" + misprint + "': expected ID:DX_MM:DY_MM");
    }
    if (pm != sim::PayloadMode::kFull) return usage_error("--misprint needs --payload full");
  }

  gp.noise_density_radps_rthz = deg_to_rad(gyro_noise_dps_rthz);
  gp.bias_radps = deg_to_rad(gyro_bias_dps);
  gp.bias_instability_radps = deg_to_rad(gyro_bias_instability_dps);
  gp.bias_random_walk_radps_rts = deg_to_rad(gyro_bias_rw_dps_rts);
  gp.range_radps = deg_to_rad(gyro_range_dps);
  gp.latency_ns = std::llround(gyro_latency_ms * 1e6);
  gp.seed = seed;

  std::string err;
  if (gyro && !sim::check_gyro_params(gp, &err)) return usage_error(err);
  LandmarkMap map = sim::default_landmark_grid();
  if (!map_path.empty()) {
    if (!config::load_map_file(map_path, &map, &err)) return usage_error(err);
    if (map.entries.empty()) return usage_error(map_path + ": no landmarks");
  }
  // A worn id the floor does not have would silently leave every landmark clean.
  for (std::uint32_t id : worn_ids) {
    if (!map.find(id)) {
      return usage_error("--wear-landmarks: landmark " + std::to_string(id) + " is not in the map");
    }
  }

  // Lay the path over the map's bounding box.
  double minx = 1e300, miny = 1e300, maxx = -1e300, maxy = -1e300;
  for (const auto& [id, e] : map.entries) {
    minx = std::min(minx, e.pose.x_mm);
    miny = std::min(miny, e.pose.y_mm);
    maxx = std::max(maxx, e.pose.x_mm);
    maxy = std::max(maxy, e.pose.y_mm);
  }
  tp.grid_origin_mm = {minx, miny};
  tp.grid_spacing_mm = grid_spacing_mm;
  tp.grid_columns = std::max(2, static_cast<int>(std::lround((maxx - minx) / grid_spacing_mm)) + 1);
  tp.grid_rows = std::max(2, static_cast<int>(std::lround((maxy - miny) / grid_spacing_mm)) + 1);
  tp.lawnmower_rows = tp.grid_rows - (tp.grid_rows % 2);  // even: the loop closes
  tp.speed_mps = speed_mps;
  sim::Trajectory traj;
  if (!sim::make_trajectory(tp, &traj, &err)) return usage_error("trajectory: " + err);

  sim::Scene scene;
  if (family == "tag36h11") {
    if (!misprint.empty()) return usage_error("--misprint needs --family qr");
    if (!sim::make_tag_scene(map, AprilTagGeometry{}, &scene, &err)) return usage_error(err);
  } else if (family != "qr") {
    return usage_error("unknown --family '" + family + "' (qr or tag36h11)");
  } else if (!sim::make_scene(map, LandmarkGeometry{}, pm, &scene, &err)) {
    return usage_error(err);
  }
  scene.floor.seed = seed;
  if (!misprint.empty() && !sim::misprint_landmark(&scene, static_cast<std::uint32_t>(misprint_id),
                                                   misprint_offset_mm, &err)) {
    return usage_error("--misprint: " + err);
  }

  std::error_code ec;
  if (fs::exists(fs::path(out_dir) / "meta.yaml", ec) && !force) {
    return usage_error(out_dir + " already holds a recording (use --force to overwrite)");
  }
  if (force) {
    fs::remove_all(fs::path(out_dir) / "frames", ec);
    fs::remove(fs::path(out_dir) / "imu.csv", ec);  // a --no-gyro rewrite must not keep an old one
  }
  fs::create_directories(out_dir, ec);
  if (ec) {
    std::fprintf(stderr, "agvloc-desk sim: cannot create %s: %s\n", out_dir.c_str(),
                 ec.message().c_str());
    return 1;
  }

  recording::Meta meta;
  meta.camera = cam;
  if (nominal_meta) {
    meta.camera.mount =
        (profile == "640x480" ? CameraModel::default_640x480() : CameraModel::default_1280x800())
            .mount;
  }
  op.yaw_rate_bias_radps = deg_to_rad(yaw_bias_degps);
  meta.landmark_size_mm = scene.geometry.size_mm;
  meta.landmark_family = family;  // replay runs the printed family without a --config saying so
  std::string cmdline = "agvloc-desk sim";
  for (int i = 1; i < argc; ++i) cmdline += std::string(" ") + argv[i];
  // The sample timing is part of what the recording means (the replay's fusion must agree), so
  // it is stated even when it is the default. meta.yaml has no key for it
  // (docs/guide/recording.md).
  meta.source = cmdline + " (odometry samples: " + sim::to_string(op.timing) + ")";
  if (!recording::write_meta(out_dir, meta, &err)) {
    std::fprintf(stderr, "agvloc-desk sim: %s\n", err.c_str());
    return 1;
  }

  // Monotonic clock starts at an arbitrary 10 s, like a freshly booted controller.
  constexpr std::int64_t kT0_ns = 10'000'000'000LL;
  const auto duration_ns = static_cast<std::int64_t>(std::llround(duration_s * 1e9));
  op.seed = seed;
  const auto odom_period_ns = static_cast<std::int64_t>(std::llround(1e9 / odom_hz));
  op.period_ns = odom_period_ns;
  const std::vector<sim::SlipEvent> slips = sim::make_slip_events(op, duration_ns);
  const auto odom_time_offset_ns =
      static_cast<std::int64_t>(std::llround(odom_time_offset_ms * 1e6));

  std::vector<recording::OdomRow> odom;
  std::vector<std::int64_t> truth_times;
  for (std::int64_t t = 0; t <= duration_ns; t += odom_period_ns) {
    const sim::OdometrySample o = sim::odometry_sample(op, slips, traj, t);
    odom.push_back({kT0_ns + t + odom_time_offset_ns, o.v_mps, o.omega_radps});
    truth_times.push_back(t);
  }

  // The gyro's own samples (own rate and stamps), on the same clock as odometry and frames.
  std::vector<recording::ImuRow> imu;
  if (gyro) {
    for (const sim::ImuSample& g : sim::simulate_gyro(gp, traj, duration_ns)) {
      imu.push_back({kT0_ns + g.t_ns, g.gyro_z_radps});
    }
  }

  const sim::FrameRenderer renderer(scene, cam);
  std::mt19937_64 noise_rng(seed * 0x2545F4914F6CDD1DULL + 1);
  std::vector<recording::FrameRow> frames;
  const auto n_frames = static_cast<std::int64_t>(std::floor(duration_s * fps)) + 1;
  const auto t_start = std::chrono::steady_clock::now();
  std::int64_t frames_with_landmark = 0;
  for (std::int64_t k = 0; k < n_frames; ++k) {
    const auto t = static_cast<std::int64_t>(std::llround(static_cast<double>(k) * 1e9 / fps));
    if (t > duration_ns) break;
    const sim::MotionState m = sim::trajectory_state(traj, t);
    sim::RenderOptions fo = ro;
    fo.speed_mps = m.v_mps;
    fo.yaw_rate_radps = m.omega_radps;
    const cv::Mat img = renderer.render(m.pose, fo, noise_rng);
    if (!renderer.visible_landmarks(m.pose).empty()) ++frames_with_landmark;
    char name[40];
    std::snprintf(name, sizeof name, "frames/%06lld.png", static_cast<long long>(k));
    if (!recording::write_frame_png(out_dir, name, img, &err)) {
      std::fprintf(stderr, "agvloc-desk sim: %s\n", err.c_str());
      return 1;
    }
    frames.push_back({kT0_ns + t, name});
    truth_times.push_back(t);
  }
  const double render_s =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - t_start).count();

  // Truth at every odometry and frame time (exact pose at each exposure mid-time).
  std::sort(truth_times.begin(), truth_times.end());
  truth_times.erase(std::unique(truth_times.begin(), truth_times.end()), truth_times.end());
  std::vector<recording::TruthRow> truth;
  truth.reserve(truth_times.size());
  for (std::int64_t t : truth_times) {
    const sim::MotionState m = sim::trajectory_state(traj, t);
    truth.push_back({kT0_ns + t, m.pose.x_mm, m.pose.y_mm, rad_to_deg(m.pose.theta_rad)});
  }
  if (!recording::write_frames_csv(out_dir, frames, &err) ||
      !recording::write_odom_csv(out_dir, odom, &err) ||
      !recording::write_truth_csv(out_dir, truth, &err) ||
      (gyro && !recording::write_imu_csv(out_dir, imu, &err))) {
    std::fprintf(stderr, "agvloc-desk sim: %s\n", err.c_str());
    return 1;
  }
  std::printf(
      "agvloc-desk sim: wrote %s: %zu frames (%lld with a landmark in view), %zu odometry rows, "
      "%zu truth rows, %s; trajectory %s, lap %.1f m, %zu slip events; %.1f s to render\n",
      out_dir.c_str(), frames.size(), static_cast<long long>(frames_with_landmark), odom.size(),
      truth.size(), gyro ? (std::to_string(imu.size()) + " gyro rows").c_str() : "no gyro",
      sim::to_string(tp.kind), traj.length_mm / 1000.0, slips.size(), render_s);
  return 0;
}

}  // namespace agv::desk
