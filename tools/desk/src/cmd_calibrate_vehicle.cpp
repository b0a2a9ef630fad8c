// agvloc-desk calibrate vehicle RECORDING --map MAP [--config CFG] [--out DIR]: camera mounting
// (offset, yaw, height, roll, pitch), odometry scales and bias, camera-odometry time offset from
// a calibration drive over mapped landmarks. Model: calib_vehicle.hpp. Needs no truth.csv. With
// an imu.csv also the gyro's scale, bias and clock offset (calib_gyro.hpp).
#include <CLI/CLI.hpp>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <map>
#include <sstream>

#include "agv/config/yaml_keys.hpp"
#include "agv/localizer/no_fix_diagnosis.hpp"
#include "agv/recording/png_io.hpp"
#include "agv/recording/recording.hpp"
#include "agv/vision/landmark_localizer.hpp"
#include "calib_cli.hpp"
#include "calib_gyro.hpp"
#include "calib_vehicle.hpp"
#include "commands.hpp"
#include "config.hpp"
#include "desk_input.hpp"
#include "key_ranges.hpp"

namespace agv::desk {

namespace {

namespace fs = std::filesystem;

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

std::string fmt(const char* f, double v) {
  char b[64];
  std::snprintf(b, sizeof b, f, v);
  return b;
}

// Bar chart of the per-pass RMS before/after (log scale), SVG.
std::string residual_svg(const vcal::Result& r) {
  const double w = 760, h = 360, l = 70, bottom = 40, top = 40;
  const size_t n = std::max<size_t>(r.passes.size(), 1);
  double vmax = 1e-3, vmin = 1e9;
  for (const auto& p : r.passes) {
    vmax = std::max({vmax, p.rms_before_px, p.rms_after_px});
    vmin = std::min({vmin, std::max(p.rms_after_px, 1e-3), std::max(p.rms_before_px, 1e-3)});
  }
  const double lo = std::floor(std::log10(vmin)), hi = std::ceil(std::log10(vmax));
  auto ypos = [&](double v) {
    const double lv = std::log10(std::max(v, std::pow(10.0, lo)));
    return top + (h - top - bottom) * (1.0 - (lv - lo) / std::max(hi - lo, 1.0));
  };
  std::ostringstream s;
  s << "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"" << w << "\" height=\"" << h
    << "\" font-family=\"sans-serif\" font-size=\"11\">\n<rect width=\"100%\" height=\"100%\" "
       "fill=\"white\"/>\n<text x=\""
    << w / 2
    << "\" y=\"18\" text-anchor=\"middle\" font-size=\"13\">Corner residual RMS per landmark pass "
       "(px, log scale): before (grey) and after (blue) calibration</text>\n";
  for (double d = lo; d <= hi; d += 1.0) {
    const double y = ypos(std::pow(10.0, d));
    s << "<line x1=\"" << l << "\" x2=\"" << w - 10 << "\" y1=\"" << y << "\" y2=\"" << y
      << "\" stroke=\"#ddd\"/><text x=\"" << l - 5 << "\" y=\"" << y + 4
      << "\" text-anchor=\"end\">" << fmt("%g", std::pow(10.0, d)) << "</text>\n";
  }
  const double bw = (w - l - 10) / static_cast<double>(n);
  for (size_t i = 0; i < r.passes.size(); ++i) {
    const auto& p = r.passes[i];
    const double x = l + bw * static_cast<double>(i);
    const double yb = ypos(p.rms_before_px), ya = ypos(p.rms_after_px), y0 = h - bottom;
    s << "<rect x=\"" << x + bw * 0.1 << "\" y=\"" << yb << "\" width=\"" << bw * 0.38
      << "\" height=\"" << y0 - yb << "\" fill=\"#999\"/>\n";
    s << "<rect x=\"" << x + bw * 0.52 << "\" y=\"" << ya << "\" width=\"" << bw * 0.38
      << "\" height=\"" << y0 - ya << "\" fill=\"#2060c0\"/>\n";
    if (r.passes.size() <= 40 || i % 5 == 0) {
      s << "<text x=\"" << x + bw / 2 << "\" y=\"" << h - bottom + 14
        << "\" text-anchor=\"middle\">" << p.index << "</text>\n";
    }
  }
  s << "<text x=\"" << w / 2 << "\" y=\"" << h - 8
    << "\" text-anchor=\"middle\">landmark pass (report.txt lists id and time)</text>\n</svg>\n";
  return s.str();
}

}  // namespace

int calibrate_vehicle(int argc, char** argv) {
  CLI::App app{
      "Calibrate the camera mounting (offset, yaw, height, roll, pitch), the odometry (speed "
      "scale, yaw-rate scale, yaw-rate bias) and the camera-odometry time offset from a "
      "calibration drive over mapped landmarks (docs/guide/commissioning.md)",
      "agvloc-desk calibrate vehicle"};
  std::string rec_dir, map_path, config_path, out_dir;
  vcal::Options opt;
  app.add_option("recording", rec_dir, "Recording of the calibration drive")->required();
  app.add_option("--map", map_path, "Surveyed landmark map (docs/design/landmark.md)")->required();
  app.add_option("--config", config_path,
                 "Configuration with the current (nominal) camera and mounting; default: the "
                 "recording's meta.yaml. In wheels odometry mode it must be the configuration "
                 "the drive was recorded with: the yaw-rate scale is written as its "
                 "can.odometry.track_width_mm divided by the scale");
  app.add_option("--out", out_dir,
                 "Directory for vehicle_calibration.yaml, report.txt, "
                 "residuals.svg; default: RECORDING/calibration");
  app.add_option("--pixel-sigma-px", opt.pixel_sigma_px, "Corner noise (px)")
      ->check(calib::finite_in(0.001, 10.0))
      ->capture_default_str();
  app.add_option("--odom-v-sigma-mps", opt.odom_v_sigma_mps, "Odometry speed noise per sample")
      ->check(calib::finite_in(1e-6, 1.0))
      ->capture_default_str();
  app.add_option("--odom-omega-sigma-radps", opt.odom_omega_sigma_radps,
                 "Odometry yaw-rate noise per sample")
      ->check(calib::finite_in(1e-7, 1.0))
      ->capture_default_str();
  app.add_option("--min-passes", opt.min_passes, "Fewest landmark passes accepted")
      ->check(CLI::Range(2, 10000))
      ->capture_default_str();
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return app.exit(e) == 0 ? 0 : 2;
  }
  auto fail = [](const std::string& m, int code) {
    std::fprintf(stderr, "agvloc-desk calibrate vehicle: %s\n", m.c_str());
    return code;
  };
  recording::Recording rec;
  std::string err;
  if (!recording::read_recording(rec_dir, &rec, &err)) return fail(err, 1);
  for (const auto& w : rec.warnings) {
    std::fprintf(stderr, "agvloc-desk calibrate vehicle: warning: %s\n", w.c_str());
  }
  config::Config cfg;
  CameraModel cam = rec.meta.camera;
  LandmarkGeometry geom;
  geom.size_mm = rec.meta.landmark_size_mm;
  // The family follows replay's rule (docs/guide/replay.md): a --config that sets it wins, else
  // the recording's meta.yaml; a tag drive calibrated as QR gives no fix at all.
  std::string family_source;
  if (!rec.meta.landmark_family.empty()) {
    cfg.vision.family =
        rec.meta.landmark_family == "tag36h11" ? LandmarkFamily::kTag36h11 : LandmarkFamily::kQr;
    family_source = "meta.yaml";
  }
  if (!config_path.empty()) {
    const LandmarkFamily meta_family = cfg.vision.family;
    if (!config::load_config_or_report(config_path, "calibrate vehicle", &cfg)) return 2;
    std::string text;
    std::vector<config::YamlEntry> entries;
    if (!recording::read_file_bounded(config_path, config::kMaxConfigBytes, &text, &err) ||
        !config::yaml_entries(text, &entries, &err)) {
      return fail("config: " + config_path + ": " + err, 2);
    }
    if (std::any_of(entries.begin(), entries.end(),
                    [](const config::YamlEntry& e) { return e.key == "landmark.family"; })) {
      family_source = "--config";
    } else {
      cfg.vision.family = meta_family;
    }
    cam = cfg.camera_model;
    geom.size_mm = cfg.landmark_size_mm;
    if (cam.intrinsics.width_px != rec.meta.camera.intrinsics.width_px ||
        cam.intrinsics.height_px != rec.meta.camera.intrinsics.height_px) {
      return fail("the configuration's image size differs from the recording's", 2);
    }
  }
  LandmarkMap map;
  if (!config::load_map_file(map_path, &map, &err)) return fail("map: " + err, 2);
  if (map.entries.empty()) return fail("map " + map_path + " has no landmarks", 2);
  if (rec.odom.empty()) {
    return fail(rec_dir +
                    " has no odometry (odom.csv is empty): record the drive with the "
                    "motor controllers on the bus",
                1);
  }
  if (out_dir.empty()) out_dir = (fs::path(rec_dir) / "calibration").string();

  // Desk work takes every pixel row: the corner observations are fitted from the raw edge points
  // (edge_points_px), and the vehicle's edge_row_step would leave out two of every three.
  vision::VisionConfig every_row = cfg.vision;
  every_row.edge_row_step = 1;
  vision::LandmarkLocalizer loc(every_row, cam, geom, &map);
  std::vector<vcal::CornerObservation> obs;
  int fixes = 0;
  // Frames without a fix, by reason: a landmark whose print disagrees with the map, or a family
  // the floor does not have, must not vanish silently.
  std::map<vision::FixStatus, int> failed;
  // What they gave, for the likely cause when the drive gives no (or too few) fixes: replay's
  // diagnosis (localizer/no_fix_diagnosis.hpp), not a second one.
  std::uint64_t by_status[localizer::kFixStatusCount] = {};
  std::vector<localizer::FrameOutcome> outcomes;
  for (const auto& f : rec.frames) {
    cv::Mat img;
    const std::string file = (fs::path(rec_dir) / f.file).string();
    // A FIFO or device among the frames would block the read forever.
    if (!input::regular_file(file, input::kMaxImageBytes, &err)) return fail(err, 1);
    if (!png::read_gray(file, &img, &err, cam.intrinsics.width_px, cam.intrinsics.height_px)) {
      return fail(err, 1);
    }
    vision::LandmarkFix fix;
    const vision::FixStatus st = loc.process(img, &fix);
    if (st != vision::FixStatus::kOk) {
      ++failed[st];
      ++by_status[static_cast<int>(st)];
      if (st != vision::FixStatus::kNoLandmark) outcomes.push_back(localizer::frame_outcome(fix));
      continue;
    }
    ++fixes;
    vcal::CornerObservation o;
    if (corner_observation(loc, fix, cam, geom, f.t_ns, &o)) obs.push_back(o);
  }
  localizer::NoFixContext why;
  why.family = cfg.vision.family;
  why.family_source = family_source;
  why.have_map = true;
  why.height_mm = cam.mount.height_mm;
  why.size_mm = geom.size_mm;
  why.calibrating = true;
  // Over the frames without a fix only: with some fixes, the family is right, but the map or the
  // height may still lose most landmarks (a height 1 mm off loses tag frames).
  const std::uint64_t no_fix_frames = rec.frames.size() - static_cast<std::uint64_t>(fixes);
  const localizer::NoFixDiagnosis diagnosis =
      localizer::diagnose_no_fix(no_fix_frames, by_status, outcomes, why);
  std::string failures;
  for (const auto& [st, n] : failed) {
    if (st == vision::FixStatus::kNoLandmark) continue;  // frames between landmarks: expected
    failures += (failures.empty() ? "" : ", ") + std::to_string(n) + " " + vision::to_string(st);
  }
  // A print that disagrees with the map is a survey or printing error to fix, not noise.
  const auto misprint = failed.find(vision::FixStatus::kPayloadInvalid);
  const std::string misprint_warning =
      misprint == failed.end()
          ? std::string()
          : std::to_string(misprint->second) +
                " frames show a landmark whose code disagrees with the map (or is malformed): "
                "check that landmark's print against the map";
  if (obs.empty()) {
    // The localizer only fixes landmarks of the map (an unmapped id is a failed frame), so what
    // failed and why is the hint.
    std::string cause;
    if (fixes == 0 && diagnosis.cause != localizer::NoFixCause::kNone) {
      cause = diagnosis.statuses + "): likely cause: " + diagnosis.text;
    } else if (fixes > 0) {
      cause = std::to_string(fixes) + " fixes with fewer than 3 border corners" +
              (failures.empty() ? "" : "; frames with a landmark but no fix: " + failures) +
              "): the landmarks were never wholly in view: drive over their centres";
    } else {
      cause = "no frame read)";
    }
    return fail("no frame of " + std::to_string(rec.frames.size()) +
                    " gave a usable fix on a landmark of " + map_path + " (" + cause +
                    (misprint_warning.empty() ? "" : "; " + misprint_warning),
                1);
  }
  std::vector<vcal::OdomSample> odom;
  for (const auto& o : rec.odom) odom.push_back({o.t_ns, o.v_mps, o.omega_radps});
  vcal::VehicleParams initial;
  initial.mount = cam.mount;
  opt.fx_px = cam.intrinsics.fx;
  opt.track_width_mm = cfg.fusion.slip.wheel_track_mm;
  vcal::Result r;
  if (!vcal::calibrate_vehicle(odom, obs, map, geom.outer_half_mm(), geom.inner_half_mm(), initial,
                               opt, &r, &err)) {
    // Too few fixes: the frames that gave none may say why (the map or the height; not the family,
    // which the fixes that were given show to be right).
    if (diagnosis.cause == localizer::NoFixCause::kMap ||
        diagnosis.cause == localizer::NoFixCause::kScale) {
      err += "; " + std::to_string(no_fix_frames) + " frames gave no fix (" + diagnosis.statuses +
             "): likely cause: " + diagnosis.text;
    }
    return fail(err, 1);
  }

  // The gyro: from the fix headings under the calibrated mounting. The clock offset is
  // solved as gyro clock - camera clock = camera.time_offset + imu.time_offset.
  const bool have_gyro = !rec.imu.empty();
  vcal::GyroResult gyro;
  std::string gyro_error;
  bool gyro_ok = false;
  const double odo_offset_s = r.param("camera.time_offset_ms").determined
                                  ? r.estimate.time_offset_s
                                  : cfg.camera.time_offset_ms * 1e-3;
  if (have_gyro) {
    std::vector<vcal::GyroSample> samples;
    samples.reserve(rec.imu.size());
    for (const auto& s : rec.imu) samples.push_back({s.t_ns, s.gyro_z_radps});
    vcal::GyroOptions gopt;
    gopt.noise_density_radps_rthz = cfg.fusion.gyro.noise_density_radps_per_sqrt_hz;
    gyro_ok = vcal::calibrate_gyro(
        samples, obs, map, geom.outer_half_mm(), geom.inner_half_mm(), r.estimate.mount,
        cfg.imu.scale, odo_offset_s + cfg.imu.time_offset_ms * 1e-3, gopt, &gyro, &gyro_error);
  }
  const double gyro_offset_ms = (gyro.clock_offset_s - odo_offset_s) * 1e3;
  std::vector<std::string> gyro_out_of_range;
  if (gyro_ok) {
    if (gyro.scale_determined)
      gyro_out_of_range.push_back(outside_key_range("imu.scale", gyro.scale));
    if (gyro.bias_determined) {
      gyro_out_of_range.push_back(outside_key_range("imu.bias_degps", rad_to_deg(gyro.bias_radps)));
    }
    if (gyro.clock_offset_determined) {
      gyro_out_of_range.push_back(outside_key_range("imu.time_offset_ms", gyro_offset_ms));
    }
  }

  // Results the configuration would reject (the key table's ranges) are errors, not "ok": the
  // snippet is not written, --check-config would refuse it anyway.
  const bool wheels = cfg.can.odometry_mode == "wheels";
  std::vector<std::string> out_of_range(r.params.size());
  for (size_t i = 0; i < r.params.size(); ++i) {
    const auto& p = r.params[i];
    if (!p.determined) continue;
    out_of_range[i] = wheels && p.name == "odometry.yaw_rate_scale"
                          ? outside_key_range("can.odometry.track_width_mm",
                                              cfg.fusion.slip.wheel_track_mm / p.value)
                          : outside_key_range(p.name, p.value);
  }
  for (const auto& e : gyro_out_of_range) out_of_range.push_back(e);
  const bool any_out_of_range = std::any_of(out_of_range.begin(), out_of_range.end(),
                                            [](const auto& e) { return !e.empty(); });

  std::ostringstream rep;
  rep << "agvloc-desk calibrate vehicle " << rec_dir << " --map " << map_path << "\n"
      << "frames " << rec.frames.size() << ", landmark fixes " << fixes << ", corner observations "
      << obs.size() << ", used " << r.frames_used << " in " << r.passes.size()
      << " landmark passes; Ceres iterations " << r.iterations << "\n"
      << "corner residual RMS " << fmt("%.3f", r.rms_before_px) << " px before, "
      << fmt("%.3f", r.rms_after_px) << " px after\n\n";
  if (!failures.empty()) {
    rep << "frames with a landmark but no fix (not used): " << failures << "\n";
    if (!misprint_warning.empty()) rep << "warning: " << misprint_warning << "\n";
    rep << "\n";
  }
  rep << "parameter                       initial        estimate        sigma   status\n";
  for (size_t i = 0; i < r.params.size(); ++i) {
    const auto& p = r.params[i];
    char b[200];
    std::snprintf(b, sizeof b, "%-28s %12.5f %14.5f %12.5f   %s %s\n", p.name.c_str(), p.initial,
                  p.value, p.sigma,
                  !out_of_range[i].empty() ? "OUT OF RANGE"
                  : p.determined           ? "ok"
                                           : "NOT DETERMINED",
                  p.unit.c_str());
    rep << b;
  }
  if (have_gyro && gyro_ok) {
    auto row = [&](const char* name, double init, double v, double sg, bool det,
                   const std::string& range_err, const char* unit) {
      char b[200];
      std::snprintf(b, sizeof b, "%-28s %12.5f %14.5f %12.5f   %s %s\n", name, init, v, sg,
                    !range_err.empty() ? "OUT OF RANGE"
                    : det              ? "ok"
                                       : "NOT DETERMINED",
                    unit);
      rep << b;
    };
    row("imu.scale", cfg.imu.scale, gyro.scale, gyro.scale_sigma, gyro.scale_determined,
        gyro.scale_determined ? gyro_out_of_range[0] : std::string(), "");
    const size_t bi = gyro.scale_determined ? 1 : 0;
    row("imu.bias_degps", rad_to_deg(cfg.imu.bias_radps), rad_to_deg(gyro.bias_radps),
        rad_to_deg(gyro.bias_sigma_radps), gyro.bias_determined,
        gyro.bias_determined ? gyro_out_of_range[bi] : std::string(), "deg/s");
    row("imu.time_offset_ms", cfg.imu.time_offset_ms, gyro_offset_ms,
        gyro.clock_offset_sigma_s * 1e3, gyro.clock_offset_determined,
        gyro.clock_offset_determined ? gyro_out_of_range.back() : std::string(), "ms");
  }
  for (const auto& e : out_of_range) {
    if (!e.empty()) rep << "error: " << e << "\n";
  }
  if (have_gyro) {
    rep << "\ngyro (imu.csv, " << rec.imu.size() << " samples): ";
    if (!gyro_ok) {
      rep << "not calibrated: " << gyro_error << "\n";
    } else {
      rep << gyro.frames_used << " of " << gyro.frames
          << " landmark frames used, fix heading noise " << fmt("%.4f", gyro.heading_sigma_deg)
          << " deg, heading change seen " << fmt("%.0f", gyro.turned_deg) << " deg, chi2/frame "
          << fmt("%.2f", gyro.chi2_per_frame) << "\n";
      if (!gyro.scale_determined) rep << "  imu.scale not determined: " << gyro.why_scale << "\n";
      if (gyro.scale_fixed) {
        rep << "  imu.bias_degps solved with imu.scale fixed at " << fmt("%.6f", cfg.imu.scale)
            << "\n";
      }
      if (!gyro.bias_determined)
        rep << "  imu.bias_degps not determined: " << gyro.why_bias << "\n";
      if (!gyro.clock_offset_determined) {
        rep << "  imu.time_offset_ms not determined: " << gyro.why_clock_offset << "\n";
      }
      rep << "  filter priors written: fusion.gyro_init_scale_sigma "
          << fmt("%.4f", gyro.prior_scale_sigma) << ", fusion.gyro_init_bias_sigma_degps "
          << fmt("%.3f", gyro.prior_bias_sigma_degps) << " (3 sigma, at least 0.0005 and 0.05)\n";
    }
  }
  const std::vector<vcal::FilterPrior> wheel_priors = vcal::odometry_priors(r);
  if (!wheel_priors.empty()) {
    rep << "\nodometry filter priors written:";
    for (const vcal::FilterPrior& p : wheel_priors)
      rep << " fusion." << p.key << " " << fmt("%.4f", p.value);
    rep << " (3 sigma, at least " << fmt("%.3f", vcal::kMinPriorScale) << " for the scales, "
        << fmt("%.2f", vcal::kMinPriorDegps) << " deg/s, " << fmt("%.2f", vcal::kMinPriorDegpm)
        << " deg/m)\n";
  }
  rep << "\n" << vcal::landmark_table(r);
  rep << "\nper landmark pass (corner residual RMS, px):\n"
      << "pass  landmark  t_start_s  t_end_s  frames   before    after\n";
  for (const auto& p : r.passes) {
    char b[160];
    std::snprintf(b, sizeof b, "%4d  %8u  %9.2f  %7.2f  %6d  %7.3f  %7.3f\n", p.index,
                  p.landmark_id, p.t_start_s, p.t_end_s, p.frames, p.rms_before_px, p.rms_after_px);
    rep << b;
  }
  if (!r.warnings.empty()) rep << "\nwarnings:\n";
  for (const auto& w : r.warnings) rep << "  - " << w << "\n";
  if (gyro_ok && r.warnings.empty() && !gyro.warnings.empty()) rep << "\nwarnings:\n";
  for (const auto& w : gyro.warnings) rep << "  - " << w << "\n";

  // Snippet: only determined values; mounting keys of docs/guide/config.md.
  std::ostringstream snip;
  snip << "# agvloc-desk calibrate vehicle " << rec_dir << " (docs/guide/config.md keys)\n"
       << "# Only parameters the drive determined are written; the others keep their value.\n";
  bool any_mount = false;
  std::ostringstream mount;
  for (size_t i = 0; i < 6; ++i) {
    const auto& p = r.params[i];
    const std::string key = p.name.substr(std::string("mounting.").size());
    if (p.determined) {
      mount << "  " << key << ": " << fmt("%.4f", p.value) << "  # sigma " << fmt("%.4f", p.sigma)
            << " " << p.unit << "\n";
      any_mount = true;
    } else {
      mount << "  # " << key << ": not determined (" << p.why << ")\n";
    }
  }
  if (any_mount) snip << "mounting:\n";
  snip << mount.str();
  // Odometry and timing: keys `odometry.*` (applied to the decoded samples before fusion, the
  // model's equations). Wheels mode: the yaw-rate scale becomes the track width the recording's
  // samples were decoded with divided by the scale (omega = (r - l) / track).
  std::ostringstream odo, can, clock;
  bool any_odo = false;
  for (size_t i = 6; i < r.params.size(); ++i) {
    const auto& p = r.params[i];
    if (p.name == "camera.time_offset_ms") {  // the camera's clock onto the vehicle's
      if (p.determined) {
        clock << "camera:\n  time_offset_ms: " << fmt("%.4f", p.value) << "  # sigma "
              << fmt("%.4f", p.sigma) << " " << p.unit << "\n";
      } else {
        clock << "# camera.time_offset_ms: not determined (" << p.why << ")\n";
      }
      continue;
    }
    const std::string key = p.name.substr(std::string("odometry.").size());
    if (!p.determined) {
      odo << "  # " << key << ": not determined (" << p.why << ")\n";
      continue;
    }
    if (wheels && key == "yaw_rate_scale") {
      const double track = cfg.fusion.slip.wheel_track_mm / p.value;
      can << "can:\n  odometry:\n    track_width_mm: " << fmt("%.2f", track) << "  # was "
          << fmt("%.2f", cfg.fusion.slip.wheel_track_mm) << " / yaw-rate scale "
          << fmt("%.6f", p.value) << " (sigma "
          << fmt("%.2f", cfg.fusion.slip.wheel_track_mm * p.sigma / (p.value * p.value))
          << " mm)\n";
      odo << "  yaw_rate_scale: 1  # folded into can.odometry.track_width_mm\n";
      any_odo = true;
      continue;
    }
    const bool scale = key == "speed_scale" || key == "yaw_rate_scale";
    odo << "  " << key << ": " << (scale ? fmt("%.6f", p.value) : fmt("%.4f", p.value))
        << "  # sigma " << (scale ? fmt("%.6f", p.sigma) : fmt("%.4f", p.sigma))
        << (p.unit.empty() ? "" : " ") << p.unit << "\n";
    any_odo = true;
  }
  if (any_odo) snip << "odometry:\n";
  snip << odo.str() << can.str() << clock.str();
  // The filter's priors for what the calibration leaves, written with the gyro's below in one
  // fusion: mapping.
  std::ostringstream fus;
  for (const vcal::FilterPrior& p : wheel_priors) {
    fus << "  " << p.key << ": " << fmt("%.4f", p.value)
        << "  # 3 x the calibration's sigma, at least what may change before the next start\n";
  }
  if (wheels && !r.param("odometry.yaw_rate_scale").determined) {
    snip << "# can.odometry.track_width_mm: not changed (yaw-rate scale not determined)\n";
  }

  // The gyro: keys imu.* (localizer::GyroCorrection: rate' = scale * rate + bias, gyro clock =
  // vehicle clock + time_offset) and the filter's priors for what is left after them.
  if (have_gyro && gyro_ok) {
    std::ostringstream imu;
    bool any_imu = false;
    if (gyro.scale_determined) {
      imu << "  scale: " << fmt("%.6f", gyro.scale) << "  # sigma " << fmt("%.6f", gyro.scale_sigma)
          << "\n";
      any_imu = true;
    } else {
      imu << "  # scale: not determined (" << gyro.why_scale << ")\n";
    }
    if (gyro.bias_determined) {
      imu << "  bias_degps: " << fmt("%.4f", rad_to_deg(gyro.bias_radps)) << "  # sigma "
          << fmt("%.4f", rad_to_deg(gyro.bias_sigma_radps)) << " deg/s"
          << (gyro.scale_fixed ? " (with the configured scale)" : "") << "\n";
      any_imu = true;
    } else {
      imu << "  # bias_degps: not determined (" << gyro.why_bias << ")\n";
    }
    if (gyro.clock_offset_determined) {
      imu << "  time_offset_ms: " << fmt("%.2f", gyro_offset_ms) << "  # sigma "
          << fmt("%.2f", gyro.clock_offset_sigma_s * 1e3) << " ms\n";
      any_imu = true;
    } else {
      imu << "  # time_offset_ms: not determined (" << gyro.why_clock_offset << ")\n";
    }
    if (any_imu) snip << "imu:\n";
    snip << imu.str();
    if (gyro.scale_determined) {
      fus << "  gyro_init_scale_sigma: " << fmt("%.4f", gyro.prior_scale_sigma)
          << "  # 3 x the calibration's sigma, at least 0.0005\n";
    }
    if (gyro.bias_determined) {
      fus << "  gyro_init_bias_sigma_degps: " << fmt("%.3f", gyro.prior_bias_sigma_degps)
          << "  # 3 x the calibration's sigma, at least 0.05 (turn-on bias repeatability)\n";
    }
  } else if (have_gyro) {
    snip << "# imu.*: not calibrated (" << gyro_error << ")\n";
  }
  if (!fus.str().empty()) snip << "fusion:\n" << fus.str();

  std::error_code ec;
  fs::create_directories(out_dir, ec);
  if (ec) return fail("cannot create " + out_dir + ": " + ec.message(), 1);
  const std::pair<const char*, std::string> files[] = {{"vehicle_calibration.yaml", snip.str()},
                                                       {"report.txt", rep.str()},
                                                       {"residuals.svg", residual_svg(r)}};
  if (any_out_of_range) {
    // Not even a stale snippet of an earlier run may be left to merge.
    fs::remove(fs::path(out_dir) / "vehicle_calibration.yaml", ec);
    for (const auto& [name, text] : files) {
      if (std::string(name) == "vehicle_calibration.yaml") continue;
      std::ofstream f(fs::path(out_dir) / name, std::ios::binary | std::ios::trunc);
      f << text;
    }
    std::fputs(rep.str().c_str(), stdout);
    for (const auto& e : out_of_range) {
      if (!e.empty()) std::fprintf(stderr, "agvloc-desk calibrate vehicle: %s\n", e.c_str());
    }
    return fail(
        "result outside the configuration's accepted ranges (the drive, the odometry "
        "decoding or the clocks are wrong): vehicle_calibration.yaml not written; " +
            out_dir + "/report.txt has the details",
        1);
  }
  for (const auto& [name, text] : files) {
    std::ofstream f(fs::path(out_dir) / name, std::ios::binary | std::ios::trunc);
    f << text;
    if (!f) return fail("cannot write " + (fs::path(out_dir) / name).string(), 1);
  }
  std::fputs(rep.str().c_str(), stdout);
  std::printf("\nwrote %s/{vehicle_calibration.yaml,report.txt,residuals.svg}\n", out_dir.c_str());
  int undetermined = 0;
  for (const auto& p : r.params) undetermined += p.determined ? 0 : 1;
  if (have_gyro) {
    // The gyro's clock offset is written when determined but not required (the fusion is
    // much less sensitive to it than to the scale).
    undetermined += !gyro_ok ? 1 : (gyro.scale_determined ? 0 : 1) + (gyro.bias_determined ? 0 : 1);
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

}  // namespace agv::desk
