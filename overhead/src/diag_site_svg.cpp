// /site.svg: the site map with the fleet, in site millimetres (x right, y up on the page).
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <string>

#include "agv/common/xml_escape.hpp"
#include "agv/site/site_geometry.hpp"
#include "diag.hpp"

namespace agv::overhead_app {

namespace {

constexpr double kPi = 3.14159265358979323846;
// A footprint ray above the horizon is cut this far from the camera.
constexpr double kFootprintRangeMm = 30000.0;

std::string num(double v) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.1f", v);
  return buf;
}

// SVG points of a site polygon (y flipped: the page's y grows downwards).
std::string points(const std::vector<Vec2>& poly) {
  std::string out;
  for (const Vec2& p : poly) out += (out.empty() ? "" : " ") + num(p.x) + "," + num(-p.y);
  return out;
}

struct Box {
  double x0 = std::numeric_limits<double>::max(), y0 = x0, x1 = -x0, y1 = -x0;
  void add(double x, double y) {
    x0 = std::min(x0, x);
    x1 = std::max(x1, x);
    y0 = std::min(y0, y);
    y1 = std::max(y1, y);
  }
  bool empty() const { return x0 > x1; }
};

const char* state_colour(overhead::TrackState s) {
  switch (s) {
    case overhead::TrackState::kConfirmed:
      return "#16a34a";
    case overhead::TrackState::kTentative:
      return "#ca8a04";
    case overhead::TrackState::kCoasting:
      return "#ea580c";
    default:
      return "#dc2626";
  }
}

// The 3-sigma ellipse of the position covariance: axes and the major axis's angle (deg, site).
void sigma_ellipse(const overhead::TrackOutput& t, double* rx, double* ry, double* angle_deg) {
  const double a = t.cov[0], b = t.cov[1], d = t.cov[4];
  const double mid = 0.5 * (a + d),
               half = std::sqrt(std::max(0.0, 0.25 * (a - d) * (a - d) + b * b));
  *rx = 3.0 * std::sqrt(std::max(0.0, mid + half));
  *ry = 3.0 * std::sqrt(std::max(0.0, mid - half));
  *angle_deg = 0.5 * std::atan2(2.0 * b, a - d) * 180.0 / kPi;
}

void agv_svg(const site::FleetAgv* fleet_agv, const AgvDiag& a, double font_mm, std::string* o) {
  const overhead::TrackOutput& t = a.track;
  const char* state = overhead::to_string(t.state);
  const double x = t.pose.x_mm, y = -t.pose.y_mm;
  const double r = fleet_agv ? fleet_agv->radius_mm : 400.0;
  double rx = 0, ry = 0, angle = 0;
  sigma_ellipse(t, &rx, &ry, &angle);
  *o += "<g class=\"agv\" data-agv=\"" + escape_xml(a.id) + "\" data-state=\"" + state +
        "\" stroke=\"" + state_colour(t.state) + "\"><title>" + escape_xml(a.id) + " " + state +
        " x " + num(t.pose.x_mm) + " y " + num(t.pose.y_mm) + " mm, sigma " + num(t.sigma_xy_mm) +
        " mm</title>";
  *o += "<ellipse cx=\"" + num(x) + "\" cy=\"" + num(y) + "\" rx=\"" + num(std::max(rx, 1.0)) +
        "\" ry=\"" + num(std::max(ry, 1.0)) + "\" transform=\"rotate(" + num(-angle) + " " +
        num(x) + " " + num(y) + ")\" fill=\"none\" stroke-dasharray=\"4 3\"/>";
  *o += "<circle cx=\"" + num(x) + "\" cy=\"" + num(y) + "\" r=\"" + num(r) + "\" fill=\"" +
        state_colour(t.state) + "\" fill-opacity=\"0.25\"/>";
  *o += "<line x1=\"" + num(x) + "\" y1=\"" + num(y) + "\" x2=\"" +
        num(x + r * std::cos(t.pose.theta_rad)) + "\" y2=\"" +
        num(y - r * std::sin(t.pose.theta_rad)) + "\" stroke-width=\"2.5\"/>";
  *o += "<text x=\"" + num(x + r) + "\" y=\"" + num(y - r) + "\" font-size=\"" + num(font_mm) +
        "\" stroke=\"none\" fill=\"#111\">" + escape_xml(a.id) + " " + state + "</text></g>\n";
}

}  // namespace

std::string overhead_site_svg(const site::Site& site, const DiagView& v) {
  Box box;
  for (const Vec2& p : site.outline.vertices_mm) box.add(p.x, p.y);
  for (const site::Obstacle& ob : site.obstacles)
    for (const Vec2& p : ob.outline.vertices_mm) box.add(p.x, p.y);
  for (const AgvDiag& a : v.agvs)
    if (a.track.state != overhead::TrackState::kNone) box.add(a.track.pose.x_mm, a.track.pose.y_mm);
  if (box.empty()) box = Box{0, 0, 10000, 10000};
  const double pad = 0.03 * std::max(box.x1 - box.x0, box.y1 - box.y0) + 500.0;
  const double w = box.x1 - box.x0 + 2 * pad, h = box.y1 - box.y0 + 2 * pad;
  const double font_mm = std::max(w, h) / 70.0;
  std::string o = "<svg xmlns=\"http://www.w3.org/2000/svg\" viewBox=\"" + num(box.x0 - pad) + " " +
                  num(-box.y1 - pad) + " " + num(w) + " " + num(h) + "\" width=\"800\" height=\"" +
                  num(800.0 * h / w) + "\">\n<title>" + escape_xml(site.name) +
                  "</title>\n<g fill=\"none\">";
  o += "<polygon class=\"outline\" points=\"" + points(site.outline.vertices_mm) +
       "\" fill=\"#fcfcfd\" stroke=\"#374151\" stroke-width=\"" + num(font_mm / 6) + "\"/>\n";
  for (const site::Obstacle& ob : site.obstacles) {
    o += "<polygon class=\"obstacle\" points=\"" + points(ob.outline.vertices_mm) +
         "\" fill=\"#9ca3af\" stroke=\"#4b5563\"><title>" + escape_xml(ob.id) +
         "</title></polygon>\n";
  }
  for (const site::CeilingCamera& cam : site.cameras) {
    const std::vector<Vec2> fp = site::camera_floor_footprint(cam, 4, kFootprintRangeMm);
    if (fp.size() < 3) continue;
    o += "<polygon class=\"camera\" points=\"" + points(fp) +
         "\" stroke=\"#2563eb\" stroke-width=\"" + num(font_mm / 8) + "\" stroke-dasharray=\"" +
         num(font_mm / 2) + "\"><title>" + escape_xml(cam.id) + "</title></polygon>\n<text x=\"" +
         num(cam.t_site_cam_mm[0]) + "\" y=\"" + num(-cam.t_site_cam_mm[1]) + "\" font-size=\"" +
         num(font_mm) + "\" fill=\"#2563eb\">" + escape_xml(cam.id) + "</text>\n";
  }
  o += "</g>\n<g stroke-width=\"" + num(font_mm / 6) + "\">\n";
  std::string unseen;
  for (std::size_t i = 0; i < v.agvs.size(); ++i) {
    const AgvDiag& a = v.agvs[i];
    if (a.track.state == overhead::TrackState::kNone) {
      unseen += (unseen.empty() ? "" : ", ") + escape_xml(a.id);
      continue;
    }
    agv_svg(i < site.fleet.size() ? &site.fleet[i] : nullptr, a, font_mm, &o);
  }
  o += "</g>\n";
  if (!unseen.empty()) {
    o += "<text class=\"unseen\" x=\"" + num(box.x0 - pad + font_mm) + "\" y=\"" +
         num(-box.y1 - pad + 1.5 * font_mm) + "\" font-size=\"" + num(font_mm) +
         "\" fill=\"#6b7280\">never seen (none): " + unseen + "</text>\n";
  }
  return o + "</svg>\n";
}

}  // namespace agv::overhead_app
