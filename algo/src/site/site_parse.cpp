// The site file's reader: YAML -> Site with every key typed and range-checked (schema:
// docs/guide/site.md). The semantic checks follow in site_check.cpp.
#include <Eigen/Eigenvalues>
#include <array>
#include <cmath>
#include <exception>
#include <utility>

#include "agv/site/site_file.hpp"
#include "agv/site/site_geometry.hpp"
#include "site_yaml.hpp"

namespace agv::site {

namespace detail {

void ErrorList::add(const std::string& key, int line, const std::string& message) {
  if (full_) return;
  if (out_->size() >= max_) {
    out_->push_back({"site", 0, "more errors not shown (at most " + std::to_string(max_) + ")"});
    full_ = true;
    return;
  }
  out_->push_back({key, line, message});
}

namespace {

constexpr double kDegToRad = M_PI / 180.0;
// Heights, sizes and camera positions: a warehouse is not taller than this.
constexpr double kMaxHeightMm = 100000.0;
// A tray tilted further is not a tray a tag can be read on from above.
constexpr double kMaxTrayTiltDeg = 15.0;
// A calibration this uncertain is not one: the tracker's fixes would be metres wide.
constexpr double kMaxPoseSigmaMm = 1000.0;
constexpr double kMaxPoseSigmaDeg = 10.0;

void read_obstacle(ReadContext* c, const YAML::Node& n, const std::string& path, Obstacle* o,
                   int* outline_line) {
  Fields f(c, n, path, {"id", "kind", "height_mm", "outline_mm", "box_mm"});
  if (!f.is_map()) return;
  f.require("id");
  f.text("id", &o->id);
  f.require("kind");
  std::string kind;
  if (f.text("kind", &kind) && !parse_obstacle_kind(kind, &o->kind)) {
    c->errors->add(f.path("kind"), line_of(f.get("kind")),
                   "'" + kind + "' is not one of: rack, pillar, conveyor, wall, other");
  }
  f.number("height_mm", 0.0, kMaxHeightMm, &o->height_mm, true);
  const bool has_outline = f.has("outline_mm"), has_box = f.has("box_mm");
  if (has_outline == has_box) {
    c->errors->add(path, f.line(), "give exactly one of outline_mm and box_mm");
    return;
  }
  if (has_outline) {
    *outline_line = line_of(f.get("outline_mm"));
    read_polygon(c, f.get("outline_mm"), f.path("outline_mm"), &o->outline);
    return;
  }
  *outline_line = line_of(f.get("box_mm"));
  Fields b(c, f.get("box_mm"), f.path("box_mm"), {"x_min", "y_min", "x_max", "y_max"});
  if (!b.is_map()) return;
  const double e = c->limits->max_extent_mm;
  double v[4] = {0, 0, 0, 0};
  const char* names[4] = {"x_min", "y_min", "x_max", "y_max"};
  bool ok = true;
  for (int i = 0; i < 4; ++i) ok &= b.require(names[i]) && b.number(names[i], -e, e, &v[i]);
  if (!ok) return;
  if (!(v[2] > v[0]) || !(v[3] > v[1])) {
    c->errors->add(f.path("box_mm"), b.line(), "needs x_max > x_min and y_max > y_min");
    return;
  }
  o->outline.vertices_mm = {{v[0], v[1]}, {v[2], v[1]}, {v[2], v[3]}, {v[0], v[3]}};
}

void read_wall_landmark(ReadContext* c, const YAML::Node& n, const std::string& path,
                        WallLandmark* w) {
  Fields f(c, n, path, {"id", "family", "x_mm", "y_mm", "z_mm", "facing_deg", "size_mm"});
  if (!f.is_map()) return;
  for (const char* k : {"id", "family", "x_mm", "y_mm", "z_mm", "facing_deg"}) f.require(k);
  std::string family;
  if (f.text("family", &family) && !parse_landmark_family(family, &w->family)) {
    c->errors->add(f.path("family"), line_of(f.get("family")),
                   "'" + family + "' is not one of: tag36h11, agvloc");
  }
  // tag36h11 has 587 codes; the agvloc (QR) landmark's payload carries ids 1..65535.
  const bool tag = w->family == LandmarkFamily::kTag36h11;
  std::int64_t id = 0;
  if (f.integer("id", tag ? 0 : 1, tag ? kTag36h11MaxId : 65535, &id)) {
    w->id = static_cast<std::uint32_t>(id);
  }
  const double e = c->limits->max_extent_mm;
  f.number("x_mm", -e, e, &w->x_mm);
  f.number("y_mm", -e, e, &w->y_mm);
  f.number("z_mm", 0.0, kMaxHeightMm, &w->z_mm);
  double facing_deg = 0.0;
  if (f.number("facing_deg", -360.0, 360.0, &facing_deg)) w->facing_rad = facing_deg * kDegToRad;
  f.number("size_mm", 0.0, 5000.0, &w->size_mm, true);
}

void read_intrinsics(ReadContext* c, const YAML::Node& n, const std::string& path,
                     CameraIntrinsics* k) {
  Fields f(c, n, path,
           {"width_px", "height_px", "fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2", "k3"});
  if (!f.is_map()) return;
  for (const char* key : {"width_px", "height_px", "fx", "fy", "cx", "cy"}) f.require(key);
  std::int64_t w = 0, h = 0;
  if (f.integer("width_px", 2, 16384, &w)) k->width_px = static_cast<int>(w);
  if (f.integer("height_px", 2, 16384, &h)) k->height_px = static_cast<int>(h);
  f.number("fx", 1.0, 1e6, &k->fx);
  f.number("fy", 1.0, 1e6, &k->fy);
  f.number("cx", 0.0, k->width_px, &k->cx);
  f.number("cy", 0.0, k->height_px, &k->cy);
  for (auto [key, v] : {std::pair{"k1", &k->k1}, std::pair{"k2", &k->k2}, std::pair{"p1", &k->p1},
                        std::pair{"p2", &k->p2}, std::pair{"k3", &k->k3}}) {
    f.number(key, -1000.0, 1000.0, v);
  }
}

// pose: x_mm, y_mm, z_mm and either yaw/pitch/roll_deg or r_site_cam (9 numbers, row-major).
void read_camera_pose(ReadContext* c, const YAML::Node& n, const std::string& path,
                      CeilingCamera* cam) {
  Fields f(c, n, path, {"x_mm", "y_mm", "z_mm", "yaw_deg", "pitch_deg", "roll_deg", "r_site_cam"});
  if (!f.is_map()) return;
  for (const char* key : {"x_mm", "y_mm", "z_mm"}) f.require(key);
  const double e = c->limits->max_extent_mm;
  f.number("x_mm", -e, e, &cam->t_site_cam_mm[0]);
  f.number("y_mm", -e, e, &cam->t_site_cam_mm[1]);
  f.number("z_mm", 0.0, kMaxHeightMm, &cam->t_site_cam_mm[2], true);
  const bool angles = f.has("yaw_deg") || f.has("pitch_deg") || f.has("roll_deg");
  if (!f.has("r_site_cam")) {
    double yaw = 0.0, pitch = 0.0, roll = 0.0;
    f.number("yaw_deg", -360.0, 360.0, &yaw);
    f.number("pitch_deg", -90.0, 90.0, &pitch);
    f.number("roll_deg", -90.0, 90.0, &roll);
    cam->r_site_cam =
        camera_rotation_from_angles(yaw * kDegToRad, pitch * kDegToRad, roll * kDegToRad);
    return;
  }
  const std::string rp = f.path("r_site_cam");
  const YAML::Node r = f.get("r_site_cam");
  if (angles) {
    c->errors->add(rp, line_of(r), "give either r_site_cam or yaw/pitch/roll_deg, not both");
    return;
  }
  if (!r.IsSequence() || r.size() != 9) {
    c->errors->add(rp, line_of(r), "expected 9 numbers (row-major rotation matrix)");
    return;
  }
  std::array<double, 9> m{};
  bool ok = true;
  for (std::size_t i = 0; i < 9; ++i) {
    ok &= read_number(c, r[i], rp + "[" + std::to_string(i) + "]", -1.000001, 1.000001, &m[i]);
  }
  if (!ok) return;
  // Orthonormal with determinant +1, to the digits a person or a writer keeps.
  double worst = 0.0;
  for (int i = 0; i < 3; ++i) {
    for (int j = 0; j < 3; ++j) {
      const double dot = m[i] * m[j] + m[3 + i] * m[3 + j] + m[6 + i] * m[6 + j];
      worst = std::max(worst, std::abs(dot - (i == j ? 1.0 : 0.0)));
    }
  }
  const double det = m[0] * (m[4] * m[8] - m[5] * m[7]) - m[1] * (m[3] * m[8] - m[5] * m[6]) +
                     m[2] * (m[3] * m[7] - m[4] * m[6]);
  if (worst > 1e-6 || det < 0.0) {
    c->errors->add(rp, line_of(r), "not a rotation matrix (columns must be orthonormal, det +1)");
    return;
  }
  cam->r_site_cam = m;
}

// pose_sigma.correlation: 15 coefficients in [-1, 1] that make a correlation matrix (positive
// semi-definite, to the digits a writer keeps).
void read_pose_correlation(ReadContext* c, const YAML::Node& n, const std::string& path,
                           CeilingCamera* cam) {
  if (!n.IsSequence() || n.size() != 15) {
    c->errors->add(path, line_of(n), "expected 15 numbers (the upper triangle, row by row)");
    return;
  }
  std::array<double, 15> r{};
  bool ok = true;
  for (std::size_t i = 0; i < 15; ++i) {
    ok &= read_number(c, n[i], path + "[" + std::to_string(i) + "]", -1.0, 1.0, &r[i]);
  }
  if (!ok) return;
  CeilingCamera probe;
  probe.pose_correlation = r;
  Eigen::Matrix<double, 6, 6> m;
  for (int p = 0; p < 6; ++p) {
    for (int q = 0; q < 6; ++q) m(p, q) = pose_correlation_at(probe, p, q);
  }
  if (Eigen::SelfAdjointEigenSolver<Eigen::Matrix<double, 6, 6>>(m).eigenvalues().minCoeff() <
      -1e-6) {
    c->errors->add(path, line_of(n), "not a correlation matrix (not positive semi-definite)");
    return;
  }
  cam->pose_correlation = r;
}

// pose_sigma: the calibration's 1-sigma per pose parameter, each optional (default 0), and their
// correlation (optional, default independent).
void read_camera_pose_sigma(ReadContext* c, const YAML::Node& n, const std::string& path,
                            CeilingCamera* cam) {
  Fields f(c, n, path,
           {"x_mm", "y_mm", "z_mm", "roll_deg", "pitch_deg", "yaw_deg", "correlation", "floor_mm"});
  if (!f.is_map()) return;
  f.number("floor_mm", 0.0, kMaxPoseSigmaMm, &cam->floor_sigma_mm);
  if (f.has("correlation"))
    read_pose_correlation(c, f.get("correlation"), f.path("correlation"), cam);
  const char* mm[3] = {"x_mm", "y_mm", "z_mm"};
  const char* deg[3] = {"roll_deg", "pitch_deg", "yaw_deg"};
  for (std::size_t i = 0; i < 3; ++i) {
    f.number(mm[i], 0.0, kMaxPoseSigmaMm, &cam->position_sigma_mm[i]);
    double d = 0.0;
    if (f.number(deg[i], 0.0, kMaxPoseSigmaDeg, &d)) cam->angle_sigma_rad[i] = d * kDegToRad;
  }
}

void read_camera(ReadContext* c, const YAML::Node& n, const std::string& path, CeilingCamera* cam) {
  Fields f(c, n, path, {"id", "intrinsics", "pose", "pose_sigma"});
  if (!f.is_map()) return;
  for (const char* key : {"id", "intrinsics", "pose"}) f.require(key);
  f.text("id", &cam->id);
  if (f.has("intrinsics"))
    read_intrinsics(c, f.get("intrinsics"), f.path("intrinsics"), &cam->intrinsics);
  if (f.has("pose")) read_camera_pose(c, f.get("pose"), f.path("pose"), cam);
  if (f.has("pose_sigma")) {
    read_camera_pose_sigma(c, f.get("pose_sigma"), f.path("pose_sigma"), cam);
  }
}

void read_fleet_agv(ReadContext* c, const YAML::Node& n, const std::string& path, FleetAgv* a,
                    int* footprint_line) {
  Fields f(c, n, path, {"id", "tag_id", "tag_size_mm", "tray", "footprint_mm", "radius_mm"});
  if (!f.is_map()) return;
  f.require("id");
  f.require("tag_id");
  f.text("id", &a->id);
  std::int64_t tag = 0;
  if (f.integer("tag_id", 0, kTag36h11MaxId, &tag)) a->tag_id = static_cast<std::uint32_t>(tag);
  f.number("tag_size_mm", 0.0, 5000.0, &a->tag_size_mm, true);
  if (f.has("tray")) {
    Fields t(c, f.get("tray"), f.path("tray"),
             {"length_mm", "width_mm", "height_mm", "roll_deg", "pitch_deg"});
    t.number("length_mm", 0.0, 20000.0, &a->tray_length_mm, true);
    t.number("width_mm", 0.0, 20000.0, &a->tray_width_mm, true);
    t.number("height_mm", 0.0, kMaxHeightMm, &a->tray_height_mm);
    double roll_deg = 0.0, pitch_deg = 0.0;
    t.number("roll_deg", -kMaxTrayTiltDeg, kMaxTrayTiltDeg, &roll_deg);
    t.number("pitch_deg", -kMaxTrayTiltDeg, kMaxTrayTiltDeg, &pitch_deg);
    a->tray_roll_rad = roll_deg * kDegToRad;
    a->tray_pitch_rad = pitch_deg * kDegToRad;
  }
  *footprint_line = f.line();
  if (f.has("footprint_mm")) {
    *footprint_line = line_of(f.get("footprint_mm"));
    read_polygon(c, f.get("footprint_mm"), f.path("footprint_mm"), &a->footprint);
  } else {
    // The tray's rectangle, centred on the reference point.
    const double l = a->tray_length_mm / 2, w = a->tray_width_mm / 2;
    a->footprint.vertices_mm = {{-l, -w}, {l, -w}, {l, w}, {-l, w}};
  }
  double r = 0.0;
  for (const Vec2& v : a->footprint.vertices_mm) r = std::max(r, std::hypot(v.x, v.y));
  a->radius_mm = r;
  f.number("radius_mm", 0.0, 20000.0, &a->radius_mm, true);
}

template <typename T, typename ReadOne>
void read_items(ReadContext* c, const Fields& root, const char* key, std::size_t max,
                std::vector<T>* out, std::vector<int>* lines, ReadOne read_one) {
  if (!root.has(key)) return;
  const YAML::Node list = root.get(key);
  if (!read_list(c, list, key, max) || !list.IsSequence()) return;
  out->resize(list.size());
  lines->resize(list.size());
  for (std::size_t i = 0; i < list.size() && !c->errors->full(); ++i) {
    const YAML::Node item = list[i];
    (*lines)[i] = line_of(item);
    read_one(item, std::string(key) + "[" + std::to_string(i) + "]", &(*out)[i], i);
  }
}

void read_floor_map(ReadContext* c, const Fields& root, std::string_view floor_map_text, Site* s,
                    SiteLines* lines) {
  if (!root.has("floor_map")) return;
  Fields f(c, root.get("floor_map"), "floor_map", {"file"});
  lines->floor_map = f.line();
  if (!f.is_map() || !f.require("file") || !f.text("file", &s->floor_map_file)) return;
  std::string error;
  if (!parse_landmark_map(floor_map_text, &s->floor_map, &error)) {
    c->errors->add("floor_map.file", line_of(f.get("file")),
                   "'" + s->floor_map_file + "': " + error);
  }
}

}  // namespace

void read_site_yaml(std::string_view yaml_text, std::string_view floor_map_text,
                    const SiteLimits& limits, Site* s, SiteLines* lines, ErrorList* errors) {
  ReadContext c{errors, &limits, 0};
  if (yaml_text.size() > limits.max_text_bytes) {
    errors->add("site", 0,
                "file of " + std::to_string(yaml_text.size()) + " bytes, at most " +
                    std::to_string(limits.max_text_bytes));
    return;
  }
  YAML::Node root;
  try {
    root = YAML::Load(std::string(yaml_text));
  } catch (const YAML::Exception& e) {
    errors->add("site", e.mark.is_null() ? 0 : e.mark.line + 1, "YAML syntax error: " + e.msg);
    return;
  }
  Fields f(&c, root, "",
           {"name", "clearance_mm", "outline_mm", "floor_map", "obstacles", "wall_landmarks",
            "cameras", "fleet"});
  if (!f.is_map()) return;
  lines->root = f.line();
  f.require("name");
  f.text("name", &s->name);
  f.number("clearance_mm", 0.0, 10000.0, &s->clearance_mm);
  if (f.require("outline_mm")) {
    lines->outline = line_of(f.get("outline_mm"));
    read_polygon(&c, f.get("outline_mm"), "outline_mm", &s->outline);
  }
  read_floor_map(&c, f, floor_map_text, s, lines);
  lines->obstacle_outlines.clear();
  read_items(&c, f, "obstacles", limits.max_obstacles, &s->obstacles, &lines->obstacles,
             [&](const YAML::Node& n, const std::string& p, Obstacle* o, std::size_t i) {
               lines->obstacle_outlines.resize(s->obstacles.size());
               read_obstacle(&c, n, p, o, &lines->obstacle_outlines[i]);
             });
  read_items(&c, f, "wall_landmarks", limits.max_wall_landmarks, &s->wall_landmarks,
             &lines->wall_landmarks,
             [&](const YAML::Node& n, const std::string& p, WallLandmark* w, std::size_t) {
               read_wall_landmark(&c, n, p, w);
             });
  read_items(&c, f, "cameras", limits.max_cameras, &s->cameras, &lines->cameras,
             [&](const YAML::Node& n, const std::string& p, CeilingCamera* cam, std::size_t) {
               read_camera(&c, n, p, cam);
             });
  read_items(&c, f, "fleet", limits.max_fleet, &s->fleet, &lines->fleet,
             [&](const YAML::Node& n, const std::string& p, FleetAgv* a, std::size_t i) {
               lines->fleet_footprints.resize(s->fleet.size());
               read_fleet_agv(&c, n, p, a, &lines->fleet_footprints[i]);
             });
}

}  // namespace detail

std::string SiteError::to_string() const {
  return key + (line > 0 ? " (line " + std::to_string(line) + ")" : "") + ": " + message;
}

bool parse_site(std::string_view yaml_text, std::string_view floor_map_text, Site* out,
                std::vector<SiteError>* errors, const SiteLimits& limits) {
  errors->clear();
  detail::ErrorList list(errors, limits.max_errors);
  Site site;
  detail::SiteLines lines;
  try {
    detail::read_site_yaml(yaml_text, floor_map_text, limits, &site, &lines, &list);
    if (list.empty()) detail::check_site(limits, lines, &site, &list);
  } catch (const std::exception& e) {
    // Nothing above is meant to throw; should a yaml-cpp or Boost.Geometry version do so on
    // some input, that is still a bad site file, not an abort.
    list.add("site", 0, std::string("cannot read the site: ") + e.what());
  }
  if (!errors->empty()) return false;
  *out = std::move(site);
  return true;
}

bool site_floor_map_file(std::string_view yaml_text, std::string* file, std::string* error) {
  file->clear();
  try {
    // The entries are walked, not looked up: a lookup of an absent key on a const node gives a
    // node that throws on use. The first of a twice-given key, as Fields reads it.
    const YAML::Node root = YAML::Load(std::string(yaml_text));
    auto first = [](const YAML::Node& map, const char* key) {
      if (map.IsMap()) {
        for (const auto& kv : map) {
          if (kv.first.IsScalar() && kv.first.Scalar() == key) return YAML::Node(kv.second);
        }
      }
      return YAML::Node(YAML::NodeType::Undefined);
    };
    const YAML::Node f = first(first(root, "floor_map"), "file");
    if (f.IsDefined() && f.IsScalar()) *file = f.Scalar();
    return true;
  } catch (const YAML::Exception& e) {
    *error = "YAML syntax error at line " + std::to_string(e.mark.line + 1) + ": " + e.msg;
    return false;
  }
}

}  // namespace agv::site
