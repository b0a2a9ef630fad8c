// Writing a site as site-file YAML (the inverse of site_parse.cpp), and the warnings of a valid
// site. Numbers are written with the fewest digits that read back to the same double, so a
// written site reads back equal (angles: to the last bit or two of the degree conversion).
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <map>
#include <sstream>

#include "agv/site/site_file.hpp"
#include "agv/site/site_geometry.hpp"
#include "site_check_geometry.hpp"
#include "site_internal.hpp"

namespace agv::site {

namespace detail {
std::string fmt_number(double v) {
  char buf[40];
  // Whole numbers as such ("900", not the shortest "9e+02").
  if (std::abs(v) < 1e15 && v == std::trunc(v)) {
    std::snprintf(buf, sizeof buf, "%.0f", v);
    return buf;
  }
  for (int digits = 1; digits <= 17; ++digits) {
    std::snprintf(buf, sizeof buf, "%.*g", digits, v);
    if (std::strtod(buf, nullptr) == v) break;
  }
  return buf;
}

namespace {

std::string quoted(const std::string& s) {
  std::string out = "\"";
  for (char c : s) {
    if (c == '"' || c == '\\') out += '\\';
    out += c;
  }
  return out + "\"";
}

std::string vertices(const Polygon& p) {
  std::string out = "[";
  for (std::size_t i = 0; i < p.vertices_mm.size(); ++i) {
    out += (i ? ", [" : "[") + fmt_number(p.vertices_mm[i].x) + ", " +
           fmt_number(p.vertices_mm[i].y) + "]";
  }
  return out + "]";
}

double deg(double rad) {
  const double d = rad * 180.0 / M_PI;
  return std::abs(d) <= 360.0 ? d : std::remainder(d, 360.0);
}

void write_camera(std::ostringstream& os, const CeilingCamera& c) {
  const CameraIntrinsics& k = c.intrinsics;
  os << "  - id: " << quoted(c.id) << "\n"
     << "    intrinsics: {width_px: " << k.width_px << ", height_px: " << k.height_px
     << ", fx: " << fmt_number(k.fx) << ", fy: " << fmt_number(k.fy) << ", cx: " << fmt_number(k.cx)
     << ", cy: " << fmt_number(k.cy) << ", k1: " << fmt_number(k.k1) << ", k2: " << fmt_number(k.k2)
     << ", p1: " << fmt_number(k.p1) << ", p2: " << fmt_number(k.p2) << ", k3: " << fmt_number(k.k3)
     << "}\n"
     << "    pose:\n"
     << "      x_mm: " << fmt_number(c.t_site_cam_mm[0]) << "\n"
     << "      y_mm: " << fmt_number(c.t_site_cam_mm[1]) << "\n"
     << "      z_mm: " << fmt_number(c.t_site_cam_mm[2]) << "\n";
  double yaw = 0, pitch = 0, roll = 0;
  camera_angles_from_rotation(c.r_site_cam, &yaw, &pitch, &roll);
  // The matrix is what reads back exactly; the angles are for the reader.
  os << "      # yaw_deg " << fmt_number(std::round(deg(yaw) * 1e6) / 1e6) << ", pitch_deg "
     << fmt_number(std::round(deg(pitch) * 1e6) / 1e6) << ", roll_deg "
     << fmt_number(std::round(deg(roll) * 1e6) / 1e6) << "\n"
     << "      r_site_cam: [";
  for (int i = 0; i < 9; ++i) os << (i ? ", " : "") << fmt_number(c.r_site_cam[i]);
  os << "]\n";
  const auto& ps = c.position_sigma_mm;
  const auto& as = c.angle_sigma_rad;
  if (ps[0] > 0 || ps[1] > 0 || ps[2] > 0 || as[0] > 0 || as[1] > 0 || as[2] > 0 ||
      c.floor_sigma_mm > 0) {
    os << "    pose_sigma: {x_mm: " << fmt_number(ps[0]) << ", y_mm: " << fmt_number(ps[1])
       << ", z_mm: " << fmt_number(ps[2]) << ", roll_deg: " << fmt_number(deg(as[0]))
       << ", pitch_deg: " << fmt_number(deg(as[1])) << ", yaw_deg: " << fmt_number(deg(as[2]));
    if (c.floor_sigma_mm > 0) os << ", floor_mm: " << fmt_number(c.floor_sigma_mm);
    const auto& rho = c.pose_correlation;
    if (std::any_of(rho.begin(), rho.end(), [](double v) { return v != 0.0; })) {
      os << ", correlation: [";
      for (std::size_t i = 0; i < rho.size(); ++i) os << (i ? ", " : "") << fmt_number(rho[i]);
      os << "]";
    }
    os << "}\n";
  }
}

}  // namespace
}  // namespace detail

std::string write_site(const Site& s) {
  using detail::deg;
  using detail::fmt_number;
  using detail::quoted;
  using detail::vertices;
  std::ostringstream os;
  os << "# Site file (docs/guide/site.md). Site frame: millimetres, z up.\n"
     << "name: " << quoted(s.name) << "\n"
     << "clearance_mm: " << fmt_number(s.clearance_mm) << "\n"
     << "outline_mm: " << vertices(s.outline) << "\n";
  if (!s.floor_map_file.empty()) os << "floor_map:\n  file: " << quoted(s.floor_map_file) << "\n";
  if (!s.obstacles.empty()) os << "obstacles:\n";
  for (const Obstacle& o : s.obstacles) {
    os << "  - id: " << quoted(o.id) << "\n"
       << "    kind: " << to_string(o.kind) << "\n"
       << "    height_mm: " << fmt_number(o.height_mm) << "\n"
       << "    outline_mm: " << vertices(o.outline) << "\n";
  }
  if (!s.wall_landmarks.empty()) os << "wall_landmarks:\n";
  for (const WallLandmark& w : s.wall_landmarks) {
    os << "  - {id: " << w.id << ", family: " << to_string(w.family)
       << ", x_mm: " << fmt_number(w.x_mm) << ", y_mm: " << fmt_number(w.y_mm)
       << ", z_mm: " << fmt_number(w.z_mm) << ", facing_deg: " << fmt_number(deg(w.facing_rad))
       << ", size_mm: " << fmt_number(w.size_mm) << "}\n";
  }
  if (!s.cameras.empty()) os << "cameras:\n";
  for (const CeilingCamera& c : s.cameras) detail::write_camera(os, c);
  if (!s.fleet.empty()) os << "fleet:\n";
  for (const FleetAgv& a : s.fleet) {
    os << "  - id: " << quoted(a.id) << "\n"
       << "    tag_id: " << a.tag_id << "\n"
       << "    tag_size_mm: " << fmt_number(a.tag_size_mm) << "\n"
       << "    tray: {length_mm: " << fmt_number(a.tray_length_mm)
       << ", width_mm: " << fmt_number(a.tray_width_mm)
       << ", height_mm: " << fmt_number(a.tray_height_mm);
    if (a.tray_roll_rad != 0.0 || a.tray_pitch_rad != 0.0) {
      os << ", roll_deg: " << fmt_number(detail::deg(a.tray_roll_rad))
         << ", pitch_deg: " << fmt_number(detail::deg(a.tray_pitch_rad));
    }
    os << "}\n"
       << "    footprint_mm: " << vertices(a.footprint) << "\n"
       << "    radius_mm: " << fmt_number(a.radius_mm) << "\n";
  }
  return os.str();
}

std::vector<std::string> site_warnings(const Site& s) {
  using detail::fmt_number;
  std::vector<std::string> out;
  // A fleet tag and a wall tag share one code book: a ceiling camera that sees a wall tag
  // could take it for the vehicle. Allowed (a wall tag stands upright, a tray tag lies flat at
  // tray height), but worth knowing.
  std::map<std::uint32_t, std::size_t> wall_tags;
  for (std::size_t i = 0; i < s.wall_landmarks.size(); ++i) {
    if (s.wall_landmarks[i].family == LandmarkFamily::kTag36h11) {
      wall_tags.emplace(s.wall_landmarks[i].id, i);
    }
  }
  for (std::size_t i = 0; i < s.fleet.size(); ++i) {
    const auto it = wall_tags.find(s.fleet[i].tag_id);
    if (it == wall_tags.end()) continue;
    out.push_back("fleet[" + std::to_string(i) + "].tag_id: tag36h11 " +
                  std::to_string(s.fleet[i].tag_id) + " of AGV '" + s.fleet[i].id +
                  "' is also wall_landmarks[" + std::to_string(it->second) + "]");
  }
  if (s.outline.vertices_mm.size() >= 3) {
    const auto outline = detail::to_bg(s.outline);
    for (const auto& [id, e] : s.floor_map.entries) {
      if (!detail::bg::covered_by(detail::BgPoint(e.pose.x_mm, e.pose.y_mm), outline)) {
        out.push_back("floor_map: landmark " + std::to_string(id) + " at (" +
                      fmt_number(e.pose.x_mm) + ", " + fmt_number(e.pose.y_mm) +
                      ") mm is outside the site outline");
      }
    }
  }
  return out;
}

}  // namespace agv::site
