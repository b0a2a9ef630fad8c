// The site file's semantic checks (docs/guide/site.md, "Checks"): polygons, obstacles against
// each other and the outline, wall landmarks against the obstacles' faces, cameras' view of the
// floor, the fleet's ids and footprints. Runs on a file that read without error.
#include <algorithm>
#include <cmath>
#include <map>
#include <numeric>
#include <set>
#include <utility>

#include "agv/site/site_geometry.hpp"
#include "site_check_geometry.hpp"
#include "site_internal.hpp"

namespace agv::site::detail {

namespace {

// A landmark's centre this close to a face sits on it (printing, measuring).
constexpr double kFaceToleranceMm = 1.0;
// How far out along its facing a landmark's normal is probed: inside a thin panel's thickness.
constexpr double kFacingProbeMm = 5.0;
// A ceiling camera tilted further than this from straight down sees the floor at grazing angles.
constexpr double kMaxCameraTiltDeg = 80.0;

std::string indexed(const char* list, std::size_t i) {
  return std::string(list) + "[" + std::to_string(i) + "]";
}

int at(const std::vector<int>& lines, std::size_t i) { return i < lines.size() ? lines[i] : 0; }

// Duplicate names in a list: error at the later one, naming the first's line.
template <typename T, typename Key>
void check_unique(const std::vector<T>& items, const char* list, const char* field,
                  const std::vector<int>& lines, Key key_of, ErrorList* errors) {
  std::map<decltype(key_of(items[0])), std::size_t> first;
  for (std::size_t i = 0; i < items.size(); ++i) {
    const auto [it, inserted] = first.emplace(key_of(items[i]), i);
    if (inserted) continue;
    errors->add(indexed(list, i) + "." + field, at(lines, i),
                std::string("duplicate ") + field + " (also " + indexed(list, it->second) +
                    ", line " + std::to_string(at(lines, it->second)) + ")");
  }
}

struct Shapes {
  BgPolygon outline;
  bool outline_ok = false;
  std::vector<BgPolygon> obstacles;
  std::vector<bool> obstacle_ok;
  std::vector<BgBox> envelopes;  // of the valid obstacles
};

BgBox envelope_of(const Polygon& p) {
  BgBox b(BgPoint(p.vertices_mm[0].x, p.vertices_mm[0].y),
          BgPoint(p.vertices_mm[0].x, p.vertices_mm[0].y));
  for (const Vec2& v : p.vertices_mm) {
    b.min_corner().x(std::min(b.min_corner().x(), v.x));
    b.min_corner().y(std::min(b.min_corner().y(), v.y));
    b.max_corner().x(std::max(b.max_corner().x(), v.x));
    b.max_corner().y(std::max(b.max_corner().y(), v.y));
  }
  return b;
}

// Whether p lies within the box grown by margin_mm: a cheap test before the exact ones.
bool near_box(const BgBox& b, Vec2 p, double margin_mm) {
  return p.x >= b.min_corner().x() - margin_mm && p.x <= b.max_corner().x() + margin_mm &&
         p.y >= b.min_corner().y() - margin_mm && p.y <= b.max_corner().y() + margin_mm;
}

void check_obstacles(const SiteLines& lines, Site* s, Shapes* sh, ErrorList* errors) {
  const std::size_t n = s->obstacles.size();
  sh->obstacles.resize(n);
  sh->obstacle_ok.assign(n, false);
  check_unique(
      s->obstacles, "obstacles", "id", lines.obstacles, [](const Obstacle& o) { return o.id; },
      errors);
  std::vector<BgBox>& env = sh->envelopes;
  env.assign(n, BgBox());
  for (std::size_t i = 0; i < n && !errors->full(); ++i) {
    Obstacle& o = s->obstacles[i];
    const std::string why = normalise_polygon(&o.outline);
    if (!why.empty()) {
      errors->add(indexed("obstacles", i) + ".outline_mm", at(lines.obstacle_outlines, i),
                  "obstacle '" + o.id + "': " + why);
      continue;
    }
    sh->obstacles[i] = to_bg(o.outline);
    sh->obstacle_ok[i] = true;
    env[i] = envelope_of(o.outline);
    if (sh->outline_ok && !bg::covered_by(sh->obstacles[i], sh->outline)) {
      errors->add(indexed("obstacles", i) + ".outline_mm", at(lines.obstacle_outlines, i),
                  "obstacle '" + o.id + "' is not inside the site outline");
    }
  }
  // Sweep along x over the envelopes: only pairs whose boxes overlap are tested exactly.
  std::vector<std::size_t> order;
  for (std::size_t i = 0; i < n; ++i) {
    if (sh->obstacle_ok[i]) order.push_back(i);
  }
  std::sort(order.begin(), order.end(), [&](std::size_t a, std::size_t b) {
    return env[a].min_corner().x() < env[b].min_corner().x();
  });
  for (std::size_t k = 0; k < order.size() && !errors->full(); ++k) {
    const std::size_t a = order[k];
    for (std::size_t m = k + 1; m < order.size() && !errors->full(); ++m) {
      const std::size_t b = order[m];
      if (env[b].min_corner().x() >= env[a].max_corner().x()) break;
      if (env[b].min_corner().y() >= env[a].max_corner().y() ||
          env[a].min_corner().y() >= env[b].max_corner().y()) {
        continue;
      }
      if (!interiors_intersect(sh->obstacles[a], sh->obstacles[b])) continue;
      const auto [i, j] = std::minmax(a, b);
      errors->add(indexed("obstacles", j) + ".outline_mm", at(lines.obstacle_outlines, j),
                  "obstacle '" + s->obstacles[j].id + "' overlaps obstacle '" + s->obstacles[i].id +
                      "' (" + indexed("obstacles", i) + ", line " +
                      std::to_string(at(lines.obstacles, i)) + ")");
    }
  }
}

void check_wall_landmarks(const SiteLines& lines, const Site& s, const Shapes& sh,
                          ErrorList* errors) {
  check_unique(
      s.wall_landmarks, "wall_landmarks", "id", lines.wall_landmarks,
      [](const WallLandmark& w) { return std::make_pair(w.family, w.id); }, errors);
  for (std::size_t i = 0; i < s.wall_landmarks.size() && !errors->full(); ++i) {
    const WallLandmark& w = s.wall_landmarks[i];
    const std::string key = indexed("wall_landmarks", i);
    const int line = at(lines.wall_landmarks, i);
    const Vec2 c{w.x_mm, w.y_mm};
    const BgPoint pc(c.x, c.y);
    const BgPoint probe(c.x + kFacingProbeMm * std::cos(w.facing_rad),
                        c.y + kFacingProbeMm * std::sin(w.facing_rad));
    const std::string name = std::string(to_string(w.family)) + " " + std::to_string(w.id);
    if (sh.outline_ok) {
      if (!bg::covered_by(pc, sh.outline) &&
          boundary_distance_mm(sh.outline, c) > kFaceToleranceMm) {
        errors->add(key, line, "landmark " + name + " is outside the site outline");
      } else if (!bg::covered_by(probe, sh.outline)) {
        errors->add(key + ".facing_deg", line,
                    "landmark " + name + " faces out of the site, into the outline's wall");
      }
    }
    for (std::size_t k = 0; k < sh.obstacles.size() && !errors->full(); ++k) {
      if (!sh.obstacle_ok[k] || !near_box(sh.envelopes[k], c, 2 * kFacingProbeMm)) continue;
      const std::string obstacle = "obstacle '" + s.obstacles[k].id + "'";
      const double d = boundary_distance_mm(sh.obstacles[k], c);
      if (d > kFaceToleranceMm) {
        if (bg::within(pc, sh.obstacles[k])) {
          errors->add(key, line,
                      "landmark " + name + " is inside " + obstacle + " (" + fmt_number(d) +
                          " mm from its faces; a wall landmark sits on a face)");
        }
      } else if (bg::within(probe, sh.obstacles[k])) {
        errors->add(key + ".facing_deg", line,
                    "landmark " + name + " faces into " + obstacle + " (it sits on its face)");
      }
    }
  }
}

void check_cameras(const SiteLines& lines, const Site& s, const Shapes& sh, ErrorList* errors) {
  check_unique(
      s.cameras, "cameras", "id", lines.cameras, [](const CeilingCamera& c) { return c.id; },
      errors);
  const FleetAgv* tallest = nullptr;
  for (const FleetAgv& a : s.fleet) {
    if (!tallest || a.tray_height_mm > tallest->tray_height_mm) tallest = &a;
  }
  for (std::size_t i = 0; i < s.cameras.size() && !errors->full(); ++i) {
    const CeilingCamera& cam = s.cameras[i];
    const std::string key = indexed("cameras", i);
    const int line = at(lines.cameras, i);
    if (tallest && !(cam.t_site_cam_mm[2] > tallest->tray_height_mm)) {
      errors->add(key + ".pose.z_mm", line,
                  "camera '" + cam.id + "' at " + fmt_number(cam.t_site_cam_mm[2]) +
                      " mm is not above the tray of AGV '" + tallest->id + "' (" +
                      fmt_number(tallest->tray_height_mm) + " mm)");
    }
    const double tilt_deg = camera_tilt_rad(cam) * 180.0 / M_PI;
    if (tilt_deg > kMaxCameraTiltDeg) {
      errors->add(key + ".pose", line,
                  "camera '" + cam.id + "' does not look down enough: optical axis " +
                      fmt_number(std::round(tilt_deg * 10) / 10) +
                      " deg from straight down, at most " + fmt_number(kMaxCameraTiltDeg));
      continue;
    }
    if (!sh.outline_ok) continue;
    const double w = cam.intrinsics.width_px - 1.0, h = cam.intrinsics.height_px - 1.0;
    const Vec2 rays[5] = {{cam.intrinsics.cx, cam.intrinsics.cy}, {0, 0}, {w, 0}, {w, h}, {0, h}};
    bool sees_floor = false;
    for (const Vec2& px : rays) {
      Vec2 f;
      if (camera_pixel_to_floor(cam, px, &f) && bg::covered_by(BgPoint(f.x, f.y), sh.outline)) {
        sees_floor = true;
        break;
      }
    }
    if (!sees_floor) {
      errors->add(key + ".pose", line,
                  "camera '" + cam.id +
                      "' has no view of the floor: neither its image centre nor a corner sees "
                      "the floor inside the outline");
    }
  }
}

void check_fleet(const SiteLines& lines, Site* s, ErrorList* errors) {
  check_unique(
      s->fleet, "fleet", "id", lines.fleet, [](const FleetAgv& a) { return a.id; }, errors);
  check_unique(
      s->fleet, "fleet", "tag_id", lines.fleet, [](const FleetAgv& a) { return a.tag_id; }, errors);
  for (std::size_t i = 0; i < s->fleet.size() && !errors->full(); ++i) {
    FleetAgv& a = s->fleet[i];
    const std::string key = indexed("fleet", i);
    const int line = at(lines.fleet, i);
    if (a.tag_size_mm > std::min(a.tray_length_mm, a.tray_width_mm)) {
      errors->add(key + ".tag_size_mm", line,
                  "AGV '" + a.id + "': a tag of " + fmt_number(a.tag_size_mm) +
                      " mm does not fit on its tray (" + fmt_number(a.tray_length_mm) + " x " +
                      fmt_number(a.tray_width_mm) + " mm)");
    }
    const std::string why = normalise_polygon(&a.footprint);
    if (!why.empty()) {
      errors->add(key + ".footprint_mm", at(lines.fleet_footprints, i),
                  "AGV '" + a.id + "': " + why);
      continue;
    }
    if (!bg::covered_by(BgPoint(0.0, 0.0), to_bg(a.footprint))) {
      errors->add(key + ".footprint_mm", at(lines.fleet_footprints, i),
                  "AGV '" + a.id +
                      "': the footprint does not contain the vehicle's reference "
                      "point (0, 0)");
    }
    double r = 0.0;
    for (const Vec2& v : a.footprint.vertices_mm) r = std::max(r, std::hypot(v.x, v.y));
    if (r > a.radius_mm * (1.0 + 1e-12)) {
      errors->add(key + ".radius_mm", line,
                  "AGV '" + a.id + "': the footprint reaches " + fmt_number(r) +
                      " mm from the centre, beyond radius_mm " + fmt_number(a.radius_mm));
    }
  }
}

}  // namespace

void check_site(const SiteLimits& /*limits*/, const SiteLines& lines, Site* s, ErrorList* errors) {
  Shapes sh;
  const std::string why = normalise_polygon(&s->outline);
  if (why.empty()) {
    sh.outline = to_bg(s->outline);
    sh.outline_ok = true;
  } else {
    errors->add("outline_mm", lines.outline, why);
  }
  check_obstacles(lines, s, &sh, errors);
  check_wall_landmarks(lines, *s, sh, errors);
  check_fleet(lines, s, errors);
  check_cameras(lines, *s, sh, errors);
}

}  // namespace agv::site::detail
