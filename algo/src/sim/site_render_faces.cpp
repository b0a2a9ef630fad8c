// Site renderer: the scene as planar faces (extruded polygons, trays with their tags, wall
// landmarks) and each face's camera-relative form (docs/design/site_render.md).
#include <algorithm>
#include <cmath>
#include <limits>

#include "site_render_internal.hpp"

namespace agv::sim {

Pose2 advance_agv_pose(const AgvState& s, double dt) {
  const double v = s.v_mps * 1000.0, w = s.omega_radps, th = s.pose.theta_rad;
  if (dt == 0.0) return s.pose;
  if (std::abs(w) < 1e-9) {
    return {s.pose.x_mm + v * dt * std::cos(th), s.pose.y_mm + v * dt * std::sin(th), th};
  }
  const double th1 = th + w * dt;
  return {s.pose.x_mm + v / w * (std::sin(th1) - std::sin(th)),
          s.pose.y_mm - v / w * (std::cos(th1) - std::cos(th)), wrap_angle_rad(th1)};
}

}  // namespace agv::sim

namespace agv::sim::site_render_detail {

Pages make_pages(const SiteScene& scene) {
  Pages p;
  for (const site::FleetAgv& a : scene.site.fleet) {
    AprilTagGeometry g;
    g.size_mm = a.tag_size_mm;
    g.margin_mm = a.tag_size_mm / 4.0;  // two modules, as the printed floor tags
    LandmarkPattern pat;
    std::string err;
    if (a.tag_size_mm > 0.0 && LandmarkPattern::make_tag(g, a.tag_id, &pat, &err)) {
      p.store.push_back(std::move(pat));
      p.agv.push_back(&p.store.back());
    } else {
      p.agv.push_back(nullptr);
    }
  }
  for (const site::WallLandmark& w : scene.site.wall_landmarks) {
    LandmarkPattern pat;
    std::string err;
    bool ok = false;
    if (w.family == site::LandmarkFamily::kTag36h11) {
      AprilTagGeometry g;
      g.size_mm = w.size_mm;
      g.margin_mm = w.size_mm / 4.0;
      ok = w.size_mm > 0.0 && LandmarkPattern::make_tag(g, w.id, &pat, &err);
    } else {
      LandmarkGeometry g;
      g.size_mm = w.size_mm;
      LandmarkPayload pl;
      pl.id = w.id;
      pl.has_pose = false;
      ok = w.size_mm > 0.0 && LandmarkPattern::make(g, format_payload(pl), &pat, &err);
    }
    if (ok) {
      p.store.push_back(std::move(pat));
      p.wall.push_back(&p.store.back());
    } else {
      p.wall.push_back(nullptr);
    }
  }
  return p;
}

double face_shade(Vec3 n) {
  // Diffuse light from above plus a weak key light from one side, so box sides differ.
  return 0.62 + 0.38 * std::max(0.0, n.z) + 0.12 * (0.6 * n.x + 0.8 * n.y);
}

namespace {

void set_bounds(Face* f) {
  f->lo = {1e300, 1e300};
  f->hi = {-1e300, -1e300};
  for (const Vec2& p : f->poly) {
    f->lo = {std::min(f->lo.x, p.x), std::min(f->lo.y, p.y)};
    f->hi = {std::max(f->hi.x, p.x), std::max(f->hi.y, p.y)};
  }
}

// The polygon extruded from z0 to z1: side faces and (with_top) the top face, whose index is
// returned (-1 without one or for a degenerate polygon).
int extrude(std::vector<Vec2> poly, double z0, double z1, double grey, bool moving, bool with_top,
            std::vector<Face>* out) {
  if (poly.size() < 3 || !(z1 > z0)) return -1;
  double area2 = 0.0;
  for (size_t i = 0; i < poly.size(); ++i) {
    const Vec2 a = poly[i], b = poly[(i + 1) % poly.size()];
    area2 += a.x * b.y - b.x * a.y;
  }
  if (area2 < 0.0) std::reverse(poly.begin(), poly.end());  // outward side normals need CCW
  for (size_t i = 0; i < poly.size(); ++i) {
    const Vec2 a = poly[i], b = poly[(i + 1) % poly.size()];
    const double len = std::hypot(b.x - a.x, b.y - a.y);
    if (!(len > 1e-9)) continue;
    Face f;
    f.o = {a.x, a.y, z0};
    f.eu = {(b.x - a.x) / len, (b.y - a.y) / len, 0.0};
    f.ev = {0.0, 0.0, 1.0};
    f.n = cross3(f.eu, f.ev);
    f.poly = {{0.0, 0.0}, {len, 0.0}, {len, z1 - z0}, {0.0, z1 - z0}};
    f.grey = grey * face_shade(f.n);
    f.moving = moving;
    set_bounds(&f);
    out->push_back(std::move(f));
  }
  if (!with_top) return -1;
  Face top;
  top.o = {0.0, 0.0, z1};
  top.eu = {1.0, 0.0, 0.0};
  top.ev = {0.0, 1.0, 0.0};
  top.n = {0.0, 0.0, 1.0};
  top.poly = std::move(poly);
  top.grey = grey * face_shade(top.n);
  top.moving = moving;
  set_bounds(&top);
  out->push_back(std::move(top));
  return static_cast<int>(out->size()) - 1;
}

// Rectangle (or, for n > 4, an inscribed n-gon of the ellipse) of length x width centred at c,
// turned by yaw.
std::vector<Vec2> footprint_shape(Vec2 c, double yaw, double length, double width, int n) {
  std::vector<Vec2> p;
  const double cy = std::cos(yaw), sy = std::sin(yaw);
  for (int k = 0; k < n; ++k) {
    double lx, ly;
    if (n == 4) {  // counter-clockwise from the front-right corner
      static constexpr double kSx[4] = {0.5, 0.5, -0.5, -0.5}, kSy[4] = {-0.5, 0.5, 0.5, -0.5};
      lx = kSx[k] * length;
      ly = kSy[k] * width;
    } else {
      const double a = 2.0 * kPi * (k + 0.5) / n;
      lx = 0.5 * length * std::cos(a);
      ly = 0.5 * width * std::sin(a);
    }
    p.push_back({c.x + cy * lx - sy * ly, c.y + sy * lx + cy * ly});
  }
  return p;
}

double obstacle_grey(site::ObstacleKind k) {
  switch (k) {
    case site::ObstacleKind::kRack:
      return 120.0;
    case site::ObstacleKind::kPillar:
      return 175.0;
    case site::ObstacleKind::kConveyor:
      return 95.0;
    case site::ObstacleKind::kWall:
      return 185.0;
    case site::ObstacleKind::kOther:
      return 140.0;
  }
  return 140.0;
}

// Body, tray plate, tray top (with the tag's page) and parcels of vehicle i at pose.
void add_vehicle(const SiteScene& s, const Pages& pages, size_t i, const Pose2& pose,
                 std::vector<Face>* out, FaceIndex* index) {
  const site::FleetAgv& a = s.site.fleet[i];
  const AgvState& st = s.agvs[i];
  const double th = a.tray_height_mm;
  const double plate = std::min(30.0, 0.5 * th);
  const Vec2 c{pose.x_mm, pose.y_mm};
  std::vector<Vec2> body;
  for (const Vec2& v : a.footprint.vertices_mm) body.push_back(transform(pose, v));
  if (body.size() < 3) {
    body = footprint_shape(c, pose.theta_rad, 0.9 * a.tray_length_mm, 0.9 * a.tray_width_mm, 4);
  }
  const double hu = 0.5 * a.tray_width_mm, hv = 0.5 * a.tray_length_mm;
  const double roll = a.tray_roll_rad + st.tray_roll_rad;
  const double pitch = a.tray_pitch_rad + st.tray_pitch_rad;
  // The plate's walls end below the tilted top's lowest edge, so they never hide it.
  const double dip = hv * std::abs(std::sin(pitch)) + hu * std::abs(std::sin(roll));
  extrude(body, 0.0, th - plate - dip, s.body_grey, true, true, out);
  extrude(footprint_shape(c, pose.theta_rad, a.tray_length_mm, a.tray_width_mm, 4),
          th - plate - dip, th - dip, s.tray_grey, true, false, out);
  const double cs = std::cos(pose.theta_rad), sn = std::sin(pose.theta_rad);
  const double cr = std::cos(roll), sr = std::sin(roll), cp = std::cos(pitch), sp = std::sin(pitch);
  // The vehicle's x and y axes turned by Ry(pitch) Rx(roll), then by the heading.
  const Vec3 xv{cp, 0.0, -sp}, yv{sp * sr, cr, cp * sr};
  const auto site_dir = [&](const Vec3& v) {
    return Vec3{cs * v.x - sn * v.y, sn * v.x + cs * v.y, v.z};
  };
  const Vec3 xs = site_dir(xv), ys = site_dir(yv);
  Face tray;
  tray.o = {c.x, c.y, th};
  tray.eu = {-ys.x, -ys.y, -ys.z};  // page right: the vehicle's -y
  tray.ev = {-xs.x, -xs.y, -xs.z};  // page down: the vehicle's -x
  tray.n = cross3(tray.eu, tray.ev);
  tray.poly = {{-hu, -hv}, {hu, -hv}, {hu, hv}, {-hu, hv}};
  tray.shade = face_shade({0, 0, 1});
  tray.grey = s.tray_grey * tray.shade;
  tray.page = pages.agv[i];
  tray.material = tray.page ? Material::kPage : Material::kFlat;
  tray.page_reach_mm = tray.page ? tray.page->reach_mm() : 0.0;
  tray.moving = true;
  set_bounds(&tray);
  out->push_back(std::move(tray));
  index->agv_tag_face[i] = static_cast<int>(out->size()) - 1;
  for (size_t k = 0; k < s.parcels.size(); ++k) {
    const Parcel& p = s.parcels[k];
    if (p.agv != i) continue;
    const Vec2 pc = transform(pose, {p.x_mm, p.y_mm});
    index->parcel_top_face[k] =
        extrude(footprint_shape(pc, pose.theta_rad + p.yaw_rad, p.length_mm, p.width_mm, 4), th,
                th + p.height_mm, p.grey, true, true, out);
  }
}

}  // namespace

void build_faces(const SiteScene& s, const Pages& pages, double dt, std::vector<Face>* out,
                 FaceIndex* index) {
  out->clear();
  index->agv_tag_face.assign(s.site.fleet.size(), -1);
  index->wall_face.assign(s.site.wall_landmarks.size(), -1);
  index->parcel_top_face.assign(s.parcels.size(), -1);
  index->clutter_top_face.assign(s.clutter.size(), -1);
  for (const site::Obstacle& o : s.site.obstacles) {
    extrude(o.outline.vertices_mm, 0.0, o.height_mm, obstacle_grey(o.kind), false, true, out);
  }
  for (size_t k = 0; k < s.clutter.size(); ++k) {
    const Clutter& c = s.clutter[k];
    const int n = c.kind == ClutterKind::kPerson ? 8 : 4;
    index->clutter_top_face[k] =
        extrude(footprint_shape({c.x_mm, c.y_mm}, c.yaw_rad, c.length_mm, c.width_mm, n), 0.0,
                c.height_mm, c.grey, false, true, out);
  }
  for (size_t i = 0; i < s.site.fleet.size() && i < s.agvs.size(); ++i) {
    add_vehicle(s, pages, i, advance_agv_pose(s.agvs[i], dt), out, index);
  }
  for (size_t k = 0; k < s.site.wall_landmarks.size(); ++k) {
    const site::WallLandmark& w = s.site.wall_landmarks[k];
    const LandmarkPattern* page = pages.wall[k];
    if (!page) continue;
    const double c = std::cos(w.facing_rad), sn = std::sin(w.facing_rad);
    Face f;
    // A millimetre proud of the face it is printed on, so the face never wins the depth test.
    f.o = {w.x_mm + c, w.y_mm + sn, w.z_mm};
    f.eu = {-sn, c, 0.0};
    f.ev = {0.0, 0.0, -1.0};
    f.n = cross3(f.eu, f.ev);
    const double r = page->reach_mm();
    f.poly = {{-r, -r}, {r, -r}, {r, r}, {-r, r}};
    f.shade = face_shade({c, sn, 0.0});
    f.grey = s.tray_grey * f.shade;
    f.page = page;
    f.material = Material::kPage;
    f.page_reach_mm = r;
    set_bounds(&f);
    out->push_back(std::move(f));
    index->wall_face[k] = static_cast<int>(out->size()) - 1;
  }
}

CamFace cam_face(const Face& f, const RenderCamera& cam) {
  CamFace cf;
  const auto& r = cam.r_site_cam;
  const Vec3 t{cam.t_site_cam_mm[0], cam.t_site_cam_mm[1], cam.t_site_cam_mm[2]};
  cf.nd = rot3t(r, f.n);
  cf.ud = rot3t(r, f.eu);
  cf.vd = rot3t(r, f.ev);
  const Vec3 to = sub3(f.o, t);
  cf.c = dot3(f.n, to);
  cf.ou = -dot3(to, f.eu);
  cf.ov = -dot3(to, f.ev);
  if (!(std::abs(cf.c) > 1e-9)) return cf;  // seen edge-on
  // The polygon in the camera frame, clipped to the half-space in front of the camera.
  constexpr double kNear = 1.0;
  std::vector<Vec3> in, clip;
  for (const Vec2& p : f.poly) {
    in.push_back(rot3t(r, add3(to, add3(mul3(f.eu, p.x), mul3(f.ev, p.y)))));
  }
  for (size_t i = 0; i < in.size(); ++i) {
    const Vec3 a = in[i], b = in[(i + 1) % in.size()];
    if (a.z >= kNear) clip.push_back(a);
    if ((a.z >= kNear) != (b.z >= kNear)) {
      const double s = (kNear - a.z) / (b.z - a.z);
      clip.push_back(add3(a, mul3(sub3(b, a), s)));
    }
  }
  if (clip.empty()) return cf;
  float x0 = std::numeric_limits<float>::max(), y0 = x0, x1 = -x0, y1 = -x0;
  for (const Vec3& p : clip) {
    const auto x = static_cast<float>(p.x / p.z), y = static_cast<float>(p.y / p.z);
    x0 = std::min(x0, x);
    y0 = std::min(y0, y);
    x1 = std::max(x1, x);
    y1 = std::max(y1, y);
  }
  // Float rounding of the box must never drop a pixel on its edge.
  const float pad =
      1e-5f * (1.0f + std::max(std::abs(x0) + std::abs(x1), std::abs(y0) + std::abs(y1)));
  cf.box[0] = x0 - pad;
  cf.box[1] = y0 - pad;
  cf.box[2] = x1 + pad;
  cf.box[3] = y1 + pad;
  cf.visible = true;
  return cf;
}

}  // namespace agv::sim::site_render_detail
