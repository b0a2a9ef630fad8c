#include "svg_plot.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <limits>

namespace agv::plot {

bool write_trajectory_svg(const std::string& path, const std::string& title,
                          const std::vector<Series>& series, const std::vector<Marker>& landmarks,
                          std::string* error) {
  double x0 = std::numeric_limits<double>::max(), y0 = x0;
  double x1 = -x0, y1 = -x0;
  auto extend = [&](Vec2 p) {
    if (!std::isfinite(p.x) || !std::isfinite(p.y)) return;
    x0 = std::min(x0, p.x);
    x1 = std::max(x1, p.x);
    y0 = std::min(y0, p.y);
    y1 = std::max(y1, p.y);
  };
  for (const auto& s : series) {
    for (const auto& p : s.points_mm) extend(p);
  }
  for (const auto& m : landmarks) extend(m.p_mm);
  if (x0 > x1) {
    x0 = y0 = -1000.0;
    x1 = y1 = 1000.0;
  }
  const double pad = 0.05 * std::max({x1 - x0, y1 - y0, 500.0});
  x0 -= pad;
  y0 -= pad;
  x1 += pad;
  y1 += pad;
  const double W = 900.0, H_max = 900.0;
  const double scale = std::min(W / (x1 - x0), H_max / (y1 - y0));
  const double w = (x1 - x0) * scale, h = (y1 - y0) * scale;
  const double left = 70.0, top = 40.0, legend_h = 24.0 * static_cast<double>(series.size()) + 20;
  auto X = [&](double x) { return left + (x - x0) * scale; };
  auto Y = [&](double y) { return top + (y1 - y) * scale; };  // world y up

  std::ofstream f(path);
  if (!f) {
    if (error) *error = path + ": cannot open for writing";
    return false;
  }
  char buf[256];
  std::snprintf(buf, sizeof buf,
                "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"%.0f\" height=\"%.0f\" "
                "font-family=\"sans-serif\" font-size=\"12\">\n",
                left + w + 20, top + h + 40 + legend_h);
  f << buf << "<rect width=\"100%\" height=\"100%\" fill=\"white\"/>\n";
  f << "<text x=\"" << left << "\" y=\"24\" font-size=\"15\">" << title << "</text>\n";
  // Grid every 1 m (or 0.5 m for small plots).
  const double span = std::max(x1 - x0, y1 - y0);
  const double step = span > 4000 ? 1000.0 : (span > 1500 ? 500.0 : 100.0);
  for (double gx = std::ceil(x0 / step) * step; gx <= x1; gx += step) {
    std::snprintf(buf, sizeof buf,
                  "<line x1=\"%.1f\" y1=\"%.1f\" x2=\"%.1f\" y2=\"%.1f\" stroke=\"#ddd\"/>"
                  "<text x=\"%.1f\" y=\"%.1f\" text-anchor=\"middle\" fill=\"#666\">%.1f</text>\n",
                  X(gx), top, X(gx), top + h, X(gx), top + h + 14, gx / 1000.0);
    f << buf;
  }
  for (double gy = std::ceil(y0 / step) * step; gy <= y1; gy += step) {
    std::snprintf(buf, sizeof buf,
                  "<line x1=\"%.1f\" y1=\"%.1f\" x2=\"%.1f\" y2=\"%.1f\" stroke=\"#ddd\"/>"
                  "<text x=\"%.1f\" y=\"%.1f\" text-anchor=\"end\" fill=\"#666\">%.1f</text>\n",
                  left, Y(gy), left + w, Y(gy), left - 4, Y(gy) + 4, gy / 1000.0);
    f << buf;
  }
  std::snprintf(buf, sizeof buf,
                "<text x=\"%.1f\" y=\"%.1f\" text-anchor=\"middle\">x [m]</text>"
                "<text x=\"14\" y=\"%.1f\" transform=\"rotate(-90 14 %.1f)\">y [m]</text>\n",
                left + w / 2, top + h + 30, top + h / 2, top + h / 2);
  f << buf;
  for (const auto& m : landmarks) {
    const double s = std::max(3.0, 60.0 * scale);
    std::snprintf(buf, sizeof buf,
                  "<rect x=\"%.1f\" y=\"%.1f\" width=\"%.1f\" height=\"%.1f\" fill=\"none\" "
                  "stroke=\"#444\"/><text x=\"%.1f\" y=\"%.1f\" fill=\"#444\" "
                  "font-size=\"10\">%s</text>\n",
                  X(m.p_mm.x) - s / 2, Y(m.p_mm.y) - s / 2, s, s, X(m.p_mm.x) + s / 2 + 2,
                  Y(m.p_mm.y) - s / 2, m.label.c_str());
    f << buf;
  }
  for (const auto& s : series) {
    if (s.points_mm.empty()) continue;
    f << "<polyline fill=\"none\" stroke=\"" << s.color << "\" stroke-width=\"1.5\""
      << (s.dashed ? " stroke-dasharray=\"6,4\"" : "") << " points=\"";
    // Decimate to keep files small: at most ~4000 points per series.
    const size_t stride = std::max<size_t>(1, s.points_mm.size() / 4000);
    for (size_t i = 0; i < s.points_mm.size(); i += stride) {
      const Vec2 p = s.points_mm[i];
      if (!std::isfinite(p.x) || !std::isfinite(p.y)) continue;
      std::snprintf(buf, sizeof buf, "%.1f,%.1f ", X(p.x), Y(p.y));
      f << buf;
    }
    f << "\"/>\n";
  }
  double ly = top + h + 44;
  for (const auto& s : series) {
    std::snprintf(buf, sizeof buf,
                  "<line x1=\"%.1f\" y1=\"%.1f\" x2=\"%.1f\" y2=\"%.1f\" stroke=\"%s\" "
                  "stroke-width=\"2\"%s/><text x=\"%.1f\" y=\"%.1f\">%s</text>\n",
                  left, ly, left + 30, ly, s.color.c_str(),
                  s.dashed ? " stroke-dasharray=\"6,4\"" : "", left + 36, ly + 4, s.label.c_str());
    f << buf;
    ly += 24;
  }
  f << "</svg>\n";
  if (!f) {
    if (error) *error = path + ": write failed";
    return false;
  }
  return true;
}

}  // namespace agv::plot
