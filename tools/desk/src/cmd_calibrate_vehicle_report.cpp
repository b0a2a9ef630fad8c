// agvloc-desk calibrate vehicle: the texts it writes (report.txt, vehicle_calibration.yaml,
// residuals.svg) from the solves' results (cmd_calibrate_vehicle.cpp).
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <sstream>

#include "cmd_calibrate_vehicle.hpp"

namespace agv::desk::vehicle_cmd {

namespace {

const char* status_text(bool out_of_range, bool determined) {
  return out_of_range ? "OUT OF RANGE" : determined ? "ok" : "NOT DETERMINED";
}

void report_head(const Inputs& in, const Observed& seen, const vcal::Result& r,
                 std::ostringstream& rep) {
  rep << "agvloc-desk calibrate vehicle " << in.rec_dir << " --map " << in.map_path << "\n"
      << "frames " << in.rec.frames.size() << ", landmark fixes " << seen.fixes
      << ", corner observations " << seen.obs.size() << ", used " << r.frames_used << " in "
      << r.passes.size() << " landmark passes; Ceres iterations " << r.iterations << "\n"
      << "corner residual RMS " << fmt("%.3f", r.rms_before_px) << " px before, "
      << fmt("%.3f", r.rms_after_px) << " px after\n\n";
  if (!seen.failures.empty()) {
    rep << "frames with a landmark but no fix (not used): " << seen.failures << "\n";
    if (!seen.misprint_warning.empty()) rep << "warning: " << seen.misprint_warning << "\n";
    rep << "\n";
  }
}

void parameter_table(const Inputs& in, const Outcome& o, std::ostringstream& rep) {
  auto row = [&](const char* name, double init, double v, double sg, bool det,
                 const std::string& range_err, const char* unit) {
    char b[200];
    std::snprintf(b, sizeof b, "%-28s %12.5f %14.5f %12.5f   %s %s\n", name, init, v, sg,
                  status_text(!range_err.empty(), det), unit);
    rep << b;
  };
  rep << "parameter                       initial        estimate        sigma   status\n";
  for (size_t i = 0; i < o.r.params.size(); ++i) {
    const auto& p = o.r.params[i];
    row(p.name.c_str(), p.initial, p.value, p.sigma, p.determined, o.out_of_range[i],
        p.unit.c_str());
  }
  if (o.gyro.have && o.gyro.ok) {
    const vcal::GyroResult& gyro = o.gyro.result;
    const config::Config& cfg = in.cfg;
    const std::vector<std::string>& range = o.gyro.out_of_range;
    row("imu.scale", cfg.imu.scale, gyro.scale, gyro.scale_sigma, gyro.scale_determined,
        gyro.scale_determined ? range[0] : std::string(), "");
    const size_t bi = gyro.scale_determined ? 1 : 0;
    row("imu.bias_degps", rad_to_deg(cfg.imu.bias_radps), rad_to_deg(gyro.bias_radps),
        rad_to_deg(gyro.bias_sigma_radps), gyro.bias_determined,
        gyro.bias_determined ? range[bi] : std::string(), "deg/s");
    row("imu.time_offset_ms", cfg.imu.time_offset_ms, o.gyro.offset_ms,
        gyro.clock_offset_sigma_s * 1e3, gyro.clock_offset_determined,
        gyro.clock_offset_determined ? range.back() : std::string(), "ms");
  }
  for (const auto& e : o.out_of_range) {
    if (!e.empty()) rep << "error: " << e << "\n";
  }
}

void gyro_section(const Inputs& in, const GyroOutcome& g, std::ostringstream& rep) {
  if (!g.have) return;
  const vcal::GyroResult& gyro = g.result;
  rep << "\ngyro (imu.csv, " << in.rec.imu.size() << " samples): ";
  if (!g.ok) {
    rep << "not calibrated: " << g.error << "\n";
    return;
  }
  rep << gyro.frames_used << " of " << gyro.frames << " landmark frames used, fix heading noise "
      << fmt("%.4f", gyro.heading_sigma_deg) << " deg, heading change seen "
      << fmt("%.0f", gyro.turned_deg) << " deg, chi2/frame " << fmt("%.2f", gyro.chi2_per_frame)
      << "\n";
  if (!gyro.scale_determined) rep << "  imu.scale not determined: " << gyro.why_scale << "\n";
  if (gyro.scale_fixed) {
    rep << "  imu.bias_degps solved with imu.scale fixed at " << fmt("%.6f", in.cfg.imu.scale)
        << "\n";
  }
  if (!gyro.bias_determined) rep << "  imu.bias_degps not determined: " << gyro.why_bias << "\n";
  if (!gyro.clock_offset_determined) {
    rep << "  imu.time_offset_ms not determined: " << gyro.why_clock_offset << "\n";
  }
  rep << "  filter priors written: fusion.gyro_init_scale_sigma "
      << fmt("%.4f", gyro.prior_scale_sigma) << ", fusion.gyro_init_bias_sigma_degps "
      << fmt("%.3f", gyro.prior_bias_sigma_degps) << " (3 sigma, at least 0.0005 and 0.05)\n";
}

void passes_and_warnings(const Outcome& o, std::ostringstream& rep) {
  const vcal::Result& r = o.r;
  if (!o.wheel_priors.empty()) {
    rep << "\nodometry filter priors written:";
    for (const vcal::FilterPrior& p : o.wheel_priors)
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
  if (o.gyro.ok && r.warnings.empty() && !o.gyro.result.warnings.empty()) rep << "\nwarnings:\n";
  for (const auto& w : o.gyro.result.warnings) rep << "  - " << w << "\n";
}

// Mounting keys of docs/guide/config.md, determined values only.
void snippet_mounting(const vcal::Result& r, std::ostringstream& snip) {
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
}

// Odometry and timing: keys `odometry.*` (applied to the decoded samples before fusion, the
// model's equations). Wheels mode: the yaw-rate scale becomes the track width the recording's
// samples were decoded with divided by the scale (omega = (r - l) / track).
void snippet_odometry(const Inputs& in, const Outcome& o, std::ostringstream& snip) {
  const double track_mm = in.cfg.fusion.slip.wheel_track_mm;
  std::ostringstream odo, can, clock;
  bool any_odo = false;
  for (size_t i = 6; i < o.r.params.size(); ++i) {
    const auto& p = o.r.params[i];
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
    if (o.wheels && key == "yaw_rate_scale") {
      const double track = track_mm / p.value;
      can << "can:\n  odometry:\n    track_width_mm: " << fmt("%.2f", track) << "  # was "
          << fmt("%.2f", track_mm) << " / yaw-rate scale " << fmt("%.6f", p.value) << " (sigma "
          << fmt("%.2f", track_mm * p.sigma / (p.value * p.value)) << " mm)\n";
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
}

// The gyro: keys imu.* (localizer::GyroCorrection: rate' = scale * rate + bias, gyro clock =
// vehicle clock + time_offset) and the filter's priors for what is left after them (*fus).
void snippet_gyro(const GyroOutcome& g, std::ostringstream& snip, std::ostringstream& fus) {
  if (!g.have) return;
  if (!g.ok) {
    snip << "# imu.*: not calibrated (" << g.error << ")\n";
    return;
  }
  const vcal::GyroResult& gyro = g.result;
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
    imu << "  time_offset_ms: " << fmt("%.2f", g.offset_ms) << "  # sigma "
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
}

}  // namespace

std::string fmt(const char* f, double v) {
  char b[64];
  std::snprintf(b, sizeof b, f, v);
  return b;
}

std::string report_text(const Inputs& in, const Observed& seen, const Outcome& o) {
  std::ostringstream rep;
  report_head(in, seen, o.r, rep);
  parameter_table(in, o, rep);
  gyro_section(in, o.gyro, rep);
  passes_and_warnings(o, rep);
  return rep.str();
}

std::string snippet_text(const Inputs& in, const Outcome& o) {
  std::ostringstream snip;
  snip << "# agvloc-desk calibrate vehicle " << in.rec_dir << " (docs/guide/config.md keys)\n"
       << "# Only parameters the drive determined are written; the others keep their value.\n";
  snippet_mounting(o.r, snip);
  snippet_odometry(in, o, snip);
  // The filter's priors for what the calibration leaves, written with the gyro's below in one
  // fusion: mapping.
  std::ostringstream fus;
  for (const vcal::FilterPrior& p : o.wheel_priors) {
    fus << "  " << p.key << ": " << fmt("%.4f", p.value)
        << "  # 3 x the calibration's sigma, at least what may change before the next start\n";
  }
  if (o.wheels && !o.r.param("odometry.yaw_rate_scale").determined) {
    snip << "# can.odometry.track_width_mm: not changed (yaw-rate scale not determined)\n";
  }
  snippet_gyro(o.gyro, snip, fus);
  if (!fus.str().empty()) snip << "fusion:\n" << fus.str();
  return snip.str();
}

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

}  // namespace agv::desk::vehicle_cmd
