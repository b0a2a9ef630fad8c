// The intrinsics calibration's texts and pictures (calib_intrinsics.hpp): the coverage SVG, the
// report and the configuration snippet.
#include <cmath>
#include <sstream>

#include "calib_intrinsics_internal.hpp"

namespace agv::desk::calib {

using detail::fmt;

std::string coverage_svg(const Result& r) {
  const int w = r.intrinsics.width_px > 0 ? r.intrinsics.width_px
                                          : (r.views.empty() ? 640 : r.views[0].size.width);
  const int h = r.intrinsics.height_px > 0 ? r.intrinsics.height_px
                                           : (r.views.empty() ? 480 : r.views[0].size.height);
  const Coverage& c = r.coverage;
  const int pad = 30;
  std::ostringstream s;
  s << "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"" << w + 2 * pad << "\" height=\""
    << h + 2 * pad + 20 << "\" viewBox=\"" << -pad << " " << -pad - 20 << " " << w + 2 * pad << " "
    << h + 2 * pad + 20 << "\" font-family=\"sans-serif\" font-size=\"12\">\n";
  s << "<text x=\"0\" y=\"-24\">Corners seen in " << r.usable << " used views (" << r.corners
    << " corners), " << fmt("%.0f", 100.0 * c.covered) << " % of the " << c.cols << "x" << c.rows
    << " cells</text>\n";
  s << "<rect x=\"-0.5\" y=\"-0.5\" width=\"" << w << "\" height=\"" << h
    << "\" fill=\"white\" stroke=\"black\"/>\n";
  if (!c.counts.empty()) {
    const double cw = static_cast<double>(w) / c.cols, ch = static_cast<double>(h) / c.rows;
    for (int row = 0; row < c.rows; ++row) {
      for (int col = 0; col < c.cols; ++col) {
        const bool empty = c.counts[static_cast<size_t>(row * c.cols + col)] == 0;
        s << "<rect x=\"" << col * cw - 0.5 << "\" y=\"" << row * ch - 0.5 << "\" width=\"" << cw
          << "\" height=\"" << ch << "\" fill=\"" << (empty ? "#f4c7c3" : "none")
          << "\" stroke=\"#cccccc\" stroke-width=\"0.5\"/>\n";
      }
    }
  }
  // Quadrant lines and the 10 % border bands.
  s << "<g stroke=\"#888888\" stroke-dasharray=\"4 3\" fill=\"none\">\n";
  s << "<line x1=\"" << 0.5 * w - 0.5 << "\" y1=\"-0.5\" x2=\"" << 0.5 * w - 0.5 << "\" y2=\""
    << h - 0.5 << "\"/>\n";
  s << "<line x1=\"-0.5\" y1=\"" << 0.5 * h - 0.5 << "\" x2=\"" << w - 0.5 << "\" y2=\""
    << 0.5 * h - 0.5 << "\"/>\n";
  s << "<rect x=\"" << 0.1 * w - 0.5 << "\" y=\"" << 0.1 * h - 0.5 << "\" width=\"" << 0.8 * w
    << "\" height=\"" << 0.8 * h << "\"/>\n</g>\n";
  int n = 0;
  for (const auto& v : r.views) {
    if (!v.used) continue;
    const int hue = (n++ * 47) % 360;
    s << "<g fill=\"hsl(" << hue << ",80%,40%)\"><title>" << v.name << "</title>";
    for (const auto& p : v.image_points) {
      s << "<circle cx=\"" << fmt("%.1f", static_cast<double>(p.x)) << "\" cy=\""
        << fmt("%.1f", static_cast<double>(p.y)) << "\" r=\"1.8\"/>";
    }
    s << "</g>\n";
  }
  int y = h + 14;
  for (const auto& wmsg : c.warnings) {
    s << "<text x=\"0\" y=\"" << y << "\" fill=\"#b00000\">" << wmsg << "</text>\n";
    y += 14;
  }
  s << "</svg>\n";
  return s.str();
}

std::string report_text(const Result& r) {
  std::ostringstream s;
  s << "views: " << r.views.size() << ", usable " << r.usable << "\n";
  s << "  view                          corners  dropped  blur_px  rms_px  status\n";
  for (const auto& v : r.views) {
    char line[160];
    std::snprintf(line, sizeof line, "  %-30s %7zu  %7d  %7.2f  %6s  ", v.name.c_str(),
                  v.image_points.size(), v.dropped, v.blur_px,
                  v.used && r.corners > 0 ? fmt("%.3f", v.rms_px).c_str() : "-");
    s << line << (v.used ? "used" : "rejected: " + v.reject_reason) << "\n";
  }
  if (r.usable > 0 && r.rms_px > 0.0) {
    const auto& k = r.intrinsics;
    s << "RMS reprojection error: " << fmt("%.4f", r.rms_px) << " px over " << r.corners
      << " corners\n";
    // OpenCV's standard deviation is NaN when the problem is degenerate: say so, not "-nan".
    auto sd = [&](int i) {
      const double v = r.stddev[static_cast<size_t>(i)];
      return std::isfinite(v) ? fmt("%.4f", v) : std::string("(undetermined)");
    };
    s << "fx " << fmt("%.4f", k.fx) << " +- " << sd(0) << "  fy " << fmt("%.4f", k.fy) << " +- "
      << sd(1) << "\n";
    s << "cx " << fmt("%.4f", k.cx) << " +- " << sd(2) << "  cy " << fmt("%.4f", k.cy) << " +- "
      << sd(3) << "\n";
    s << "k1 " << fmt("%.6f", k.k1) << "  k2 " << fmt("%.6f", k.k2) << "  p1 " << fmt("%.6f", k.p1)
      << "  p2 " << fmt("%.6f", k.p2) << "  k3 " << fmt("%.6f", k.k3) << "\n";
    s << "coverage: " << fmt("%.0f", 100.0 * r.coverage.covered) << " % of the " << r.coverage.cols
      << "x" << r.coverage.rows << " image cells hold a corner\n";
  }
  for (const auto& w : r.warnings) s << "warning: " << w << "\n";
  if (!r.ok && !r.error.empty()) s << "error: " << r.error << "\n";
  return s.str();
}

std::string config_snippet(const Result& r, const std::string& source) {
  const auto& k = r.intrinsics;
  std::ostringstream s;
  s << "# Camera calibration by agvloc-desk calibrate intrinsics from " << source << ":\n";
  s << "# " << r.usable << " of " << r.views.size() << " views, " << r.corners
    << " corners, RMS reprojection error " << fmt("%.4f", r.rms_px) << " px.\n";
  s << "# Merge into the configuration (docs/guide/config.md); camera.width/height are the\n";
  s << "# calibrated resolution and must stay so.\n";
  s << "camera:\n";
  s << "  width: " << k.width_px << "\n";
  s << "  height: " << k.height_px << "\n";
  s << "intrinsics:\n";
  s << "  fx: " << fmt("%.12g", k.fx) << "\n";
  s << "  fy: " << fmt("%.12g", k.fy) << "\n";
  s << "  cx: " << fmt("%.12g", k.cx) << "\n";
  s << "  cy: " << fmt("%.12g", k.cy) << "\n";
  s << "  k1: " << fmt("%.12g", k.k1) << "\n";
  s << "  k2: " << fmt("%.12g", k.k2) << "\n";
  s << "  p1: " << fmt("%.12g", k.p1) << "\n";
  s << "  p2: " << fmt("%.12g", k.p2) << "\n";
  s << "  k3: " << fmt("%.12g", k.k3) << "\n";
  return s.str();
}

}  // namespace agv::desk::calib
