// agvloc-desk calibrate vehicle RECORDING --map MAP [--config CFG] [--out DIR]: camera mounting
// (offset, yaw, height, roll, pitch), odometry scales and bias, camera-odometry time offset from
// a calibration drive over mapped landmarks. Model: calib_vehicle.hpp. Needs no truth.csv. With
// an imu.csv also the gyro's scale, bias and clock offset (calib_gyro.hpp). The texts it writes:
// cmd_calibrate_vehicle_report.cpp.
#include "cmd_calibrate_vehicle.hpp"

#include <CLI/CLI.hpp>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <map>
#include <memory>

#include "agv/config/yaml_keys.hpp"
#include "agv/recording/png_io.hpp"
#include "agv/vision/landmark_localizer.hpp"
#include "calib_cli.hpp"
#include "cli_parse.hpp"
#include "commands.hpp"
#include "config.hpp"
#include "desk_input.hpp"
#include "key_ranges.hpp"

namespace agv::desk {

namespace {

namespace fs = std::filesystem;
using vehicle_cmd::GyroOutcome;
using vehicle_cmd::Inputs;
using vehicle_cmd::Observed;
using vehicle_cmd::Outcome;

int vehicle_fail(const std::string& m, int code) {
  std::fprintf(stderr, "agvloc-desk calibrate vehicle: %s\n", m.c_str());
  return code;
}

// Corner observation of one frame: the edge points of each border line, undistorted to
// normalised coordinates (intrinsics only), fitted with robust straight lines (a floor line
// images to a straight line through a pinhole, tilted or not; the vision stage's robust fit, so
// wear on part of an edge does not move it) and intersected (vcal::corners_from_edges). Which
// landmark side a line is comes from the fix under the configured camera model (only for
// labelling, a few mm of mounting error cannot swap sides 6 mm apart).
bool corner_observation(const vision::LandmarkLocalizer& loc, const vision::LandmarkFix& fix,
                        const CameraModel& cam, const LandmarkGeometry& geom, std::int64_t t_ns,
                        vcal::CornerObservation* out) {
  const Pose2 l_from_v = inverse(fix.landmark_in_vehicle);
  vcal::BorderEdges edges;
  for (int l = 0; l < vision::LandmarkLocalizer::kEdgeLines; ++l) {
    const auto& px = loc.edge_points_px(l);
    if (px.size() < 5) continue;
    std::vector<Vec2> xn;
    Vec2 mean{0, 0};
    int nm = 0;
    for (const Vec2& p : px) {
      Vec2 n, v;
      if (!cam.undistort_pixel_to_normalized(p, &n)) continue;
      xn.push_back(n);
      if (cam.pixel_to_vehicle(p, &v)) {
        const Vec2 q = transform(l_from_v, v);
        mean = {mean.x + q.x, mean.y + q.y};
        ++nm;
      }
    }
    if (nm < 5) continue;
    mean = {mean.x / nm, mean.y / nm};
    const double ho = geom.outer_half_mm(), hi = geom.inner_half_mm();
    const bool on_x = std::abs(mean.x) > std::abs(mean.y);
    const double r = on_x ? std::abs(mean.x) : std::abs(mean.y);
    const int inner = std::abs(r - hi) < std::abs(r - ho) ? 1 : 0;
    if (std::abs(r - (inner ? hi : ho)) > 0.4 * (ho - hi)) continue;  // not a border edge
    const int side = on_x ? (mean.x > 0 ? 0 : 2) : (mean.y > 0 ? 1 : 3);
    edges.xn[static_cast<size_t>(inner)][static_cast<size_t>(side)] = std::move(xn);
  }
  out->t_ns = t_ns;
  out->landmark_id = fix.landmark_id;
  return vcal::corners_from_edges(edges, cam.intrinsics.fx, out);
}

// The command line; -1 to go on, else the exit code.
int parse_args(int argc, char** argv, Inputs* in, vcal::Options* opt) {
  CLI::App app{
      "Calibrate the camera mounting (offset, yaw, height, roll, pitch), the odometry (speed "
      "scale, yaw-rate scale, yaw-rate bias) and the camera-odometry time offset from a "
      "calibration drive over mapped landmarks (docs/guide/commissioning.md)",
      "agvloc-desk calibrate vehicle"};
  app.add_option("recording", in->rec_dir, "Recording of the calibration drive")->required();
  app.add_option("--map", in->map_path, "Surveyed landmark map (docs/design/landmark.md)")
      ->required();
  app.add_option("--config", in->config_path,
                 "Configuration with the current (nominal) camera and mounting; default: the "
                 "recording's meta.yaml. In wheels odometry mode it must be the configuration "
                 "the drive was recorded with: the yaw-rate scale is written as its "
                 "can.odometry.track_width_mm divided by the scale");
  app.add_option("--out", in->out_dir,
                 "Directory for vehicle_calibration.yaml, report.txt, "
                 "residuals.svg; default: RECORDING/calibration");
  app.add_option("--pixel-sigma-px", opt->pixel_sigma_px, "Corner noise (px)")
      ->check(calib::finite_in(0.001, 10.0))
      ->capture_default_str();
  app.add_option("--odom-v-sigma-mps", opt->odom_v_sigma_mps, "Odometry speed noise per sample")
      ->check(calib::finite_in(1e-6, 1.0))
      ->capture_default_str();
  app.add_option("--odom-omega-sigma-radps", opt->odom_omega_sigma_radps,
                 "Odometry yaw-rate noise per sample")
      ->check(calib::finite_in(1e-7, 1.0))
      ->capture_default_str();
  app.add_option("--min-passes", opt->min_passes, "Fewest landmark passes accepted")
      ->check(CLI::Range(2, 10000))
      ->capture_default_str();
  return cli::parse(app, argc, argv);
}

// --config over the recording's meta.yaml: -1 to go on, else the exit code.
int apply_config(Inputs* in, std::string* err) {
  config::Config& cfg = in->cfg;
  const LandmarkFamily meta_family = cfg.vision.family;
  if (!config::load_config_or_report(in->config_path, "calibrate vehicle", &cfg)) return 2;
  std::string text;
  std::vector<config::YamlEntry> entries;
  if (!recording::read_file_bounded(in->config_path, config::kMaxConfigBytes, &text, err) ||
      !config::yaml_entries(text, &entries, err)) {
    return vehicle_fail("config: " + in->config_path + ": " + *err, 2);
  }
  if (std::any_of(entries.begin(), entries.end(),
                  [](const config::YamlEntry& e) { return e.key == "landmark.family"; })) {
    in->family_source = "--config";
  } else {
    cfg.vision.family = meta_family;
  }
  in->cam = cfg.camera_model;
  in->geom = config::landmark_geometry(cfg);
  if (in->cam.intrinsics.width_px != in->rec.meta.camera.intrinsics.width_px ||
      in->cam.intrinsics.height_px != in->rec.meta.camera.intrinsics.height_px) {
    return vehicle_fail("the configuration's image size differs from the recording's", 2);
  }
  return -1;
}

// The recording, the configuration and the map: -1 to go on, else the exit code.
int load_inputs(Inputs* in) {
  std::string err;
  if (!recording::read_recording(in->rec_dir, &in->rec, &err)) return vehicle_fail(err, 1);
  for (const auto& w : in->rec.warnings) {
    std::fprintf(stderr, "agvloc-desk calibrate vehicle: warning: %s\n", w.c_str());
  }
  in->cam = in->rec.meta.camera;
  in->geom.size_mm = in->rec.meta.landmark_size_mm;
  // The family follows replay's rule (docs/guide/replay.md): a --config that sets it wins, else
  // the recording's meta.yaml; a tag drive calibrated as QR gives no fix at all.
  if (!in->rec.meta.landmark_family.empty()) {
    parse_landmark_family(in->rec.meta.landmark_family, &in->cfg.vision.family);
    in->family_source = "meta.yaml";
  }
  if (!in->config_path.empty()) {
    if (const int rc = apply_config(in, &err); rc >= 0) return rc;
  }
  if (!config::load_map_file(in->map_path, &in->map, &err)) return vehicle_fail("map: " + err, 2);
  if (in->map.entries.empty()) return vehicle_fail("map " + in->map_path + " has no landmarks", 2);
  if (in->rec.odom.empty()) {
    return vehicle_fail(in->rec_dir +
                            " has no odometry (odom.csv is empty): record the drive with the "
                            "motor controllers on the bus",
                        1);
  }
  if (in->out_dir.empty()) in->out_dir = (fs::path(in->rec_dir) / "calibration").string();
  return -1;
}

// Frames without a fix, by reason: a landmark whose print disagrees with the map, or a family
// the floor does not have, must not vanish silently.
void summarise_failures(const std::map<vision::FixStatus, int>& failed, Observed* seen) {
  for (const auto& [st, n] : failed) {
    if (st == vision::FixStatus::kNoLandmark) continue;  // frames between landmarks: expected
    seen->failures +=
        (seen->failures.empty() ? "" : ", ") + std::to_string(n) + " " + vision::to_string(st);
  }
  // A print that disagrees with the map is a survey or printing error to fix, not noise.
  const auto misprint = failed.find(vision::FixStatus::kPayloadInvalid);
  if (misprint != failed.end()) {
    seen->misprint_warning =
        std::to_string(misprint->second) +
        " frames show a landmark whose code disagrees with the map (or is malformed): "
        "check that landmark's print against the map";
  }
}

// Every frame through the vision stage: the corner observations of its fixes, and why the other
// frames gave none. -1 to go on, else the exit code.
int observe_frames(const Inputs& in, Observed* seen) {
  // Desk work takes every pixel row: the corner observations are fitted from the raw edge points
  // (edge_points_px), and the vehicle's edge_row_step would leave out two of every three.
  vision::VisionConfig every_row = in.cfg.vision;
  every_row.edge_row_step = 1;
  vision::LandmarkLocalizer loc(every_row, in.cam, in.geom, &in.map);
  std::map<vision::FixStatus, int> failed;
  // What they gave, for the likely cause when the drive gives no (or too few) fixes: replay's
  // diagnosis (localizer/no_fix_diagnosis.hpp), not a second one.
  std::uint64_t by_status[localizer::kFixStatusCount] = {};
  std::vector<localizer::FrameOutcome> outcomes;
  std::string err;
  for (const auto& f : in.rec.frames) {
    cv::Mat img;
    const std::string file = (fs::path(in.rec_dir) / f.file).string();
    // A FIFO or device among the frames would block the read forever.
    if (!input::regular_file(file, input::kMaxImageBytes, &err)) return vehicle_fail(err, 1);
    if (!png::read_gray(file, &img, &err, in.cam.intrinsics.width_px,
                        in.cam.intrinsics.height_px)) {
      return vehicle_fail(err, 1);
    }
    vision::LandmarkFix fix;
    const vision::FixStatus st = loc.process(img, &fix);
    if (st != vision::FixStatus::kOk) {
      ++failed[st];
      ++by_status[static_cast<int>(st)];
      if (st != vision::FixStatus::kNoLandmark) outcomes.push_back(localizer::frame_outcome(fix));
      continue;
    }
    ++seen->fixes;
    vcal::CornerObservation o;
    if (corner_observation(loc, fix, in.cam, in.geom, f.t_ns, &o)) seen->obs.push_back(o);
  }
  localizer::NoFixContext why;
  why.family = in.cfg.vision.family;
  why.family_source = in.family_source;
  why.have_map = true;
  why.height_mm = in.cam.mount.height_mm;
  why.size_mm = in.geom.size_mm;
  why.calibrating = true;
  // Over the frames without a fix only: with some fixes, the family is right, but the map or the
  // height may still lose most landmarks (a height 1 mm off loses tag frames).
  seen->no_fix_frames = in.rec.frames.size() - static_cast<std::uint64_t>(seen->fixes);
  seen->diagnosis = localizer::diagnose_no_fix(seen->no_fix_frames, by_status, outcomes, why);
  summarise_failures(failed, seen);
  return -1;
}

// No corner observation at all: what failed and why (the localizer only fixes landmarks of the
// map, an unmapped id is a failed frame).
int no_observation(const Inputs& in, const Observed& seen) {
  std::string cause;
  if (seen.fixes == 0 && seen.diagnosis.cause != localizer::NoFixCause::kNone) {
    cause = seen.diagnosis.statuses + "): likely cause: " + seen.diagnosis.text;
  } else if (seen.fixes > 0) {
    cause = std::to_string(seen.fixes) + " fixes with fewer than 3 border corners" +
            (seen.failures.empty() ? "" : "; frames with a landmark but no fix: " + seen.failures) +
            "): the landmarks were never wholly in view: drive over their centres";
  } else {
    cause = "no frame read)";
  }
  return vehicle_fail("no frame of " + std::to_string(in.rec.frames.size()) +
                          " gave a usable fix on a landmark of " + in.map_path + " (" + cause +
                          (seen.misprint_warning.empty() ? "" : "; " + seen.misprint_warning),
                      1);
}

// The mounting, odometry and camera clock. -1 to go on, else the exit code.
int solve_vehicle(const Inputs& in, const Observed& seen, vcal::Options opt, vcal::Result* r) {
  std::vector<vcal::OdomSample> odom;
  for (const auto& o : in.rec.odom) odom.push_back({o.t_ns, o.v_mps, o.omega_radps});
  vcal::VehicleParams initial;
  initial.mount = in.cam.mount;
  opt.fx_px = in.cam.intrinsics.fx;
  opt.track_width_mm = in.cfg.fusion.slip.wheel_track_mm;
  std::string err;
  if (!vcal::calibrate_vehicle(odom, seen.obs, in.map, in.geom.outer_half_mm(),
                               in.geom.inner_half_mm(), initial, opt, r, &err)) {
    // Too few fixes: the frames that gave none may say why (the map or the height; not the family,
    // which the fixes that were given show to be right).
    const localizer::NoFixDiagnosis& d = seen.diagnosis;
    if (d.cause == localizer::NoFixCause::kMap || d.cause == localizer::NoFixCause::kScale) {
      err += "; " + std::to_string(seen.no_fix_frames) + " frames gave no fix (" + d.statuses +
             "): likely cause: " + d.text;
    }
    return vehicle_fail(err, 1);
  }
  return -1;
}

// The gyro: from the fix headings under the calibrated mounting. The clock offset is solved as
// gyro clock - camera clock = camera.time_offset + imu.time_offset.
GyroOutcome solve_gyro(const Inputs& in, const Observed& seen, const vcal::Result& r) {
  const config::Config& cfg = in.cfg;
  GyroOutcome g;
  g.have = !in.rec.imu.empty();
  const double odo_offset_s = r.param("camera.time_offset_ms").determined
                                  ? r.estimate.time_offset_s
                                  : cfg.camera.time_offset_ms * 1e-3;
  if (g.have) {
    std::vector<vcal::GyroSample> samples;
    samples.reserve(in.rec.imu.size());
    for (const auto& s : in.rec.imu) samples.push_back({s.t_ns, s.gyro_z_radps});
    vcal::GyroOptions gopt;
    gopt.noise_density_radps_rthz = cfg.fusion.gyro.noise_density_radps_per_sqrt_hz;
    g.ok = vcal::calibrate_gyro(samples, seen.obs, in.map, in.geom.outer_half_mm(),
                                in.geom.inner_half_mm(), r.estimate.mount, cfg.imu.scale,
                                odo_offset_s + cfg.imu.time_offset_ms * 1e-3, gopt, &g.result,
                                &g.error);
  }
  const vcal::GyroResult& gyro = g.result;
  g.offset_ms = (gyro.clock_offset_s - odo_offset_s) * 1e3;
  if (g.ok) {
    if (gyro.scale_determined) g.out_of_range.push_back(outside_key_range("imu.scale", gyro.scale));
    if (gyro.bias_determined) {
      g.out_of_range.push_back(outside_key_range("imu.bias_degps", rad_to_deg(gyro.bias_radps)));
    }
    if (gyro.clock_offset_determined) {
      g.out_of_range.push_back(outside_key_range("imu.time_offset_ms", g.offset_ms));
    }
  }
  return g;
}

// Results the configuration would reject (the key table's ranges) are errors, not "ok": the
// snippet is not written, --check-config would refuse it anyway.
void check_ranges(const Inputs& in, Outcome* o) {
  o->wheels = in.cfg.can.odometry_mode == protocol::OdometryMode::kWheels;
  o->out_of_range.assign(o->r.params.size(), std::string());
  for (size_t i = 0; i < o->r.params.size(); ++i) {
    const auto& p = o->r.params[i];
    if (!p.determined) continue;
    o->out_of_range[i] = o->wheels && p.name == "odometry.yaw_rate_scale"
                             ? outside_key_range("can.odometry.track_width_mm",
                                                 in.cfg.fusion.slip.wheel_track_mm / p.value)
                             : outside_key_range(p.name, p.value);
  }
  for (const auto& e : o->gyro.out_of_range) o->out_of_range.push_back(e);
  o->any_out_of_range = std::any_of(o->out_of_range.begin(), o->out_of_range.end(),
                                    [](const auto& e) { return !e.empty(); });
}

// Writes the files and prints the report; the exit code.
int write_results(const Inputs& in, const Observed& seen, const Outcome& o) {
  const std::string rep = vehicle_cmd::report_text(in, seen, o);
  std::error_code ec;
  fs::create_directories(in.out_dir, ec);
  if (ec) return vehicle_fail("cannot create " + in.out_dir + ": " + ec.message(), 1);
  const std::pair<const char*, std::string> files[] = {
      {"vehicle_calibration.yaml", vehicle_cmd::snippet_text(in, o)},
      {"report.txt", rep},
      {"residuals.svg", vehicle_cmd::residual_svg(o.r)}};
  if (o.any_out_of_range) {
    // Not even a stale snippet of an earlier run may be left to merge.
    fs::remove(fs::path(in.out_dir) / "vehicle_calibration.yaml", ec);
    for (const auto& [name, text] : files) {
      if (std::string(name) == "vehicle_calibration.yaml") continue;
      std::ofstream f(fs::path(in.out_dir) / name, std::ios::binary | std::ios::trunc);
      f << text;
    }
    std::fputs(rep.c_str(), stdout);
    for (const auto& e : o.out_of_range) {
      if (!e.empty()) std::fprintf(stderr, "agvloc-desk calibrate vehicle: %s\n", e.c_str());
    }
    return vehicle_fail(
        "result outside the configuration's accepted ranges (the drive, the odometry "
        "decoding or the clocks are wrong): vehicle_calibration.yaml not written; " +
            in.out_dir + "/report.txt has the details",
        1);
  }
  for (const auto& [name, text] : files) {
    std::ofstream f(fs::path(in.out_dir) / name, std::ios::binary | std::ios::trunc);
    f << text;
    if (!f) return vehicle_fail("cannot write " + (fs::path(in.out_dir) / name).string(), 1);
  }
  std::fputs(rep.c_str(), stdout);
  std::printf("\nwrote %s/{vehicle_calibration.yaml,report.txt,residuals.svg}\n",
              in.out_dir.c_str());
  int undetermined = 0;
  for (const auto& p : o.r.params) undetermined += p.determined ? 0 : 1;
  if (o.gyro.have) {
    // The gyro's clock offset is written when determined but not required (the fusion is
    // much less sensitive to it than to the scale).
    const vcal::GyroResult& gyro = o.gyro.result;
    undetermined +=
        !o.gyro.ok ? 1 : (gyro.scale_determined ? 0 : 1) + (gyro.bias_determined ? 0 : 1);
  }
  if (undetermined > 0) {
    std::fprintf(stderr,
                 "agvloc-desk calibrate vehicle: %d parameter(s) not determined by this drive "
                 "(not written; see the warnings)\n",
                 undetermined);
    return 1;
  }
  return 0;
}

}  // namespace

int calibrate_vehicle(int argc, char** argv) {
  auto in = std::make_unique<Inputs>();
  vcal::Options opt;
  if (const int rc = parse_args(argc, argv, in.get(), &opt); rc >= 0) return rc;
  if (const int rc = load_inputs(in.get()); rc >= 0) return rc;
  Observed seen;
  if (const int rc = observe_frames(*in, &seen); rc >= 0) return rc;
  if (seen.obs.empty()) return no_observation(*in, seen);
  Outcome o;
  if (const int rc = solve_vehicle(*in, seen, opt, &o.r); rc >= 0) return rc;
  o.gyro = solve_gyro(*in, seen, o.r);
  check_ranges(*in, &o);
  o.wheel_priors = vcal::odometry_priors(o.r);
  return write_results(*in, seen, o);
}

}  // namespace agv::desk
