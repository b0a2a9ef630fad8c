// Drawing a site as SVG or PNG (site_svg.hpp). One list of primitives in output pixels is built
// from the site, then written as SVG elements or rasterised with OpenCV, so both show the same.
#include "site_svg.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <iterator>
#include <opencv2/imgproc.hpp>
#include <sstream>

#include "agv/common/xml_escape.hpp"
#include "agv/site/site_geometry.hpp"

namespace agv::desk {

// Its own namespace: the desk library is a unity build, and the other commands have helpers too.
namespace site_draw {
namespace {

using agv::site::Site;

struct SitePrim {
  enum Kind { kPolygon, kPolyline, kCircle, kText } kind = kPolygon;
  std::vector<Vec2> px;  // output pixels (y down)
  double radius_px = 0.0;
  std::string fill = "none", stroke = "none";
  double fill_opacity = 1.0;
  double stroke_px = 1.0;
  bool dashed = false;
  bool clip_to_outline = false;  // drawn only inside the site outline
  std::string text;
  double text_px = 12.0;
};

struct SiteScene {
  double width_px = 0.0, height_px = 0.0;
  std::vector<Vec2> outline_px;
  std::vector<SitePrim> prims;
};

// Site mm -> output pixels: x right, y up on the page.
struct SiteView {
  double min_x = 0.0, max_y = 0.0, scale = 0.05, margin = 40.0;
  Vec2 operator()(Vec2 mm) const {
    // Far-off points (a camera ray cut at its range) stay representable as ints in OpenCV.
    const double x = std::clamp(margin + (mm.x - min_x) * scale, -1e6, 1e6);
    const double y = std::clamp(margin + (max_y - mm.y) * scale, -1e6, 1e6);
    return {x, y};
  }
};

const char* kind_colour(agv::site::ObstacleKind k) {
  switch (k) {
    case agv::site::ObstacleKind::kRack:
      return "#c89b5a";
    case agv::site::ObstacleKind::kPillar:
      return "#7f7f7f";
    case agv::site::ObstacleKind::kConveyor:
      return "#5b8bd0";
    case agv::site::ObstacleKind::kWall:
      return "#404040";
    case agv::site::ObstacleKind::kOther:
      return "#b070b0";
  }
  return "#000000";
}

const char* kRouteColours[] = {"#1f77b4", "#d62728", "#2ca02c", "#9467bd", "#ff7f0e", "#17becf"};

SitePrim site_text(Vec2 px, const std::string& t, double size_px, const char* colour = "#000000") {
  SitePrim p;
  p.kind = SitePrim::kText;
  p.px = {px};
  p.text = t;
  p.text_px = size_px;
  p.fill = colour;
  return p;
}

SitePrim site_shape(SitePrim::Kind kind, std::vector<Vec2> px, const std::string& fill,
                    const std::string& stroke, double stroke_px) {
  SitePrim p;
  p.kind = kind;
  p.px = std::move(px);
  p.fill = fill;
  p.stroke = stroke;
  p.stroke_px = stroke_px;
  return p;
}

std::vector<Vec2> site_to_px(const SiteView& v, const std::vector<Vec2>& mm) {
  std::vector<Vec2> out;
  out.reserve(mm.size());
  for (const Vec2& p : mm) out.push_back(v(p));
  return out;
}

void add_landmarks(const Site& s, const SiteView& v, SiteScene* sc) {
  for (const auto& [id, e] : s.floor_map.entries) {
    const double h = 60.0;  // a 120 mm marker, whatever the printed size
    const double c = std::cos(e.pose.theta_rad), sn = std::sin(e.pose.theta_rad);
    std::vector<Vec2> sq;
    for (const Vec2 d : {Vec2{h, h}, Vec2{-h, h}, Vec2{-h, -h}, Vec2{h, -h}}) {
      sq.push_back(v({e.pose.x_mm + c * d.x - sn * d.y, e.pose.y_mm + sn * d.x + c * d.y}));
    }
    sc->prims.push_back(site_shape(SitePrim::kPolygon, sq, "#222222", "none", 0));
    sc->prims.push_back(
        site_text(v({e.pose.x_mm + 2 * h, e.pose.y_mm - 2 * h}), std::to_string(id), 9, "#555555"));
  }
  for (const auto& w : s.wall_landmarks) {
    const Vec2 n{std::cos(w.facing_rad), std::sin(w.facing_rad)};
    const Vec2 t{-n.y, n.x};  // along the face
    const double half = w.size_mm / 2, len = std::max(400.0, 2.0 * w.size_mm);
    const Vec2 c{w.x_mm, w.y_mm};
    sc->prims.push_back(site_shape(
        SitePrim::kPolyline,
        {v({c.x - half * t.x, c.y - half * t.y}), v({c.x + half * t.x, c.y + half * t.y})}, "none",
        "#d62728", 4));
    const Vec2 tip{c.x + len * n.x, c.y + len * n.y};
    const double head = len * 0.3;
    sc->prims.push_back(site_shape(
        SitePrim::kPolyline,
        {v(c), v(tip), v({tip.x - head * (n.x - 0.5 * t.x), tip.y - head * (n.y - 0.5 * t.y)}),
         v(tip), v({tip.x - head * (n.x + 0.5 * t.x), tip.y - head * (n.y + 0.5 * t.y)})},
        "none", "#d62728", 1.5));
    const std::string label =
        std::string(w.family == agv::site::LandmarkFamily::kTag36h11 ? "tag " : "qr ") +
        std::to_string(w.id);
    Vec2 at = v({tip.x + 50 * n.x, tip.y + 50 * n.y});
    // Text runs to the right: a label of a landmark facing -x ends at the arrow's tip instead.
    if (n.x < -0.3) at.x -= 0.7 * 10 * label.size();
    sc->prims.push_back(site_text(at, label, 10, "#d62728"));
  }
}

// The floor each camera sees, under the obstacles (which hide it anyway).
void add_camera_views(const Site& s, const SiteView& v, double range_mm, SiteScene* sc) {
  for (const auto& cam : s.cameras) {
    const auto foot = agv::site::camera_floor_footprint(cam, 8, range_mm);
    if (foot.size() < 3) continue;
    SitePrim p = site_shape(SitePrim::kPolygon, site_to_px(v, foot), "#2ca02c", "#2ca02c", 1);
    p.fill_opacity = 0.12;
    p.dashed = true;
    p.clip_to_outline = true;  // the floor beyond the walls is not the site's
    sc->prims.push_back(p);
  }
}

void add_camera_marks(const Site& s, const SiteView& v, SiteScene* sc) {
  for (const auto& cam : s.cameras) {
    const Vec2 at = v({cam.t_site_cam_mm[0], cam.t_site_cam_mm[1]});
    SitePrim dot = site_shape(SitePrim::kCircle, {at}, "#2ca02c", "#ffffff", 1);
    dot.radius_px = 5;
    sc->prims.push_back(dot);
    char z[32];
    std::snprintf(z, sizeof z, " (%.1f m)", cam.t_site_cam_mm[2] / 1000.0);
    sc->prims.push_back(site_text({at.x + 7, at.y - 7}, cam.id + z, 11, "#1b6e1b"));
  }
}

void add_legend(const Site& s, const SiteView& v, double bottom_px, SiteScene* sc) {
  double y = bottom_px + 22;
  const double x = v.margin;
  sc->prims.push_back(site_text({x, y}, "Fleet (" + std::to_string(s.fleet.size()) + " AGVs)", 13));
  for (const auto& a : s.fleet) {
    y += 16;
    char line[160];
    std::snprintf(
        line, sizeof line, " tag36h11 %u (%.0f mm), tray %.0f x %.0f mm at %.0f mm, radius %.0f mm",
        a.tag_id, a.tag_size_mm, a.tray_length_mm, a.tray_width_mm, a.tray_height_mm, a.radius_mm);
    sc->prims.push_back(site_text({x, y}, a.id + line, 11));
    // Hershey glyphs (the PNG) are about 0.8 em wide; the canvas grows to hold the line.
    sc->width_px =
        std::max(sc->width_px, x + 0.8 * 11 * (a.id.size() + std::strlen(line)) + v.margin);
  }
  y += 22;
  double kx = x;
  for (auto k : {agv::site::ObstacleKind::kRack, agv::site::ObstacleKind::kPillar,
                 agv::site::ObstacleKind::kConveyor, agv::site::ObstacleKind::kWall,
                 agv::site::ObstacleKind::kOther}) {
    sc->prims.push_back(site_shape(SitePrim::kPolygon,
                                   {{kx, y - 10}, {kx + 12, y - 10}, {kx + 12, y + 2}, {kx, y + 2}},
                                   kind_colour(k), "#000000", 0.5));
    sc->prims.push_back(site_text({kx + 16, y}, agv::site::to_string(k), 11));
    kx += 90;
  }
  sc->width_px = std::max(sc->width_px, kx + v.margin);
  sc->height_px = y + 16;
}

SiteScene build_site_scene(const Site& s, const std::vector<std::vector<Vec2>>& routes,
                           const std::vector<agv::site::Polygon>& extra, double px_per_m) {
  SiteScene sc;
  SiteView v;
  v.scale = px_per_m / 1000.0;
  double min_x = 0, max_x = 0, min_y = 0, max_y = 0;
  bool any = false;
  auto grow = [&](Vec2 p) {
    min_x = any ? std::min(min_x, p.x) : p.x;
    max_x = any ? std::max(max_x, p.x) : p.x;
    min_y = any ? std::min(min_y, p.y) : p.y;
    max_y = any ? std::max(max_y, p.y) : p.y;
    any = true;
  };
  for (const Vec2& p : s.outline.vertices_mm) grow(p);
  for (const auto& o : s.obstacles) {
    for (const Vec2& p : o.outline.vertices_mm) grow(p);
  }
  for (const auto& r : routes) {
    for (const Vec2& p : r) grow(p);
  }
  if (!any) grow({0, 0});
  v.min_x = min_x;
  v.max_y = max_y;
  sc.width_px = 2 * v.margin + (max_x - min_x) * v.scale;
  const double bottom = v.margin + (max_y - min_y) * v.scale;
  sc.prims.push_back(site_text({v.margin, v.margin - 14}, s.name, 16));
  sc.outline_px = site_to_px(v, s.outline.vertices_mm);
  sc.prims.push_back(site_shape(SitePrim::kPolygon, site_to_px(v, s.outline.vertices_mm), "#f7f7f2",
                                "#000000", 2.5));
  add_camera_views(s, v, 2.0 * std::hypot(max_x - min_x, max_y - min_y) + 1000.0, &sc);
  for (const auto& o : s.obstacles) {
    sc.prims.push_back(site_shape(SitePrim::kPolygon, site_to_px(v, o.outline.vertices_mm),
                                  kind_colour(o.kind), "#000000", 0.8));
    Vec2 c{0, 0};
    for (const Vec2& p : o.outline.vertices_mm) c = {c.x + p.x, c.y + p.y};
    const double n = std::max<std::size_t>(1, o.outline.vertices_mm.size());
    sc.prims.push_back(site_text(v({c.x / n, c.y / n}), o.id, 10, "#ffffff"));
  }
  for (const auto& p : extra) {
    SitePrim e =
        site_shape(SitePrim::kPolygon, site_to_px(v, p.vertices_mm), "none", "#ff7f0e", 1.2);
    e.dashed = true;
    sc.prims.push_back(e);
  }
  add_landmarks(s, v, &sc);
  add_camera_marks(s, v, &sc);
  for (std::size_t i = 0; i < routes.size(); ++i) {
    const char* colour = kRouteColours[i % std::size(kRouteColours)];
    sc.prims.push_back(
        site_shape(SitePrim::kPolyline, site_to_px(v, routes[i]), "none", colour, 2.5));
    if (routes[i].empty()) continue;
    for (const Vec2& end : {routes[i].front(), routes[i].back()}) {
      SitePrim d = site_shape(SitePrim::kCircle, {v(end)}, colour, "none", 0);
      d.radius_px = 4;
      sc.prims.push_back(d);
    }
  }
  // Scale bar: 1 m, or 5 m / 10 m where 1 m is shorter than 40 px.
  double bar_m = 1;
  while (bar_m * px_per_m < 40 && bar_m < 1e6) bar_m *= bar_m == 1 ? 5 : 2;
  const Vec2 b0{sc.width_px - v.margin - bar_m * px_per_m, v.margin - 18};
  sc.prims.push_back(
      site_shape(SitePrim::kPolyline, {b0, {b0.x + bar_m * px_per_m, b0.y}}, "none", "#000000", 3));
  char bar[32];
  std::snprintf(bar, sizeof bar, "%g m", bar_m);
  sc.prims.push_back(site_text({b0.x, b0.y - 6}, bar, 11));
  add_legend(s, v, bottom, &sc);
  return sc;
}

std::string site_points(const std::vector<Vec2>& px) {
  std::string out;
  char buf[64];
  for (const Vec2& p : px) {
    std::snprintf(buf, sizeof buf, "%s%.2f,%.2f", out.empty() ? "" : " ", p.x, p.y);
    out += buf;
  }
  return out;
}

cv::Scalar site_bgr(const std::string& hex) {
  if (hex.size() != 7 || hex[0] != '#') return {0, 0, 0};
  const unsigned v = static_cast<unsigned>(std::stoul(hex.substr(1), nullptr, 16));
  return {static_cast<double>(v & 0xff), static_cast<double>((v >> 8) & 0xff),
          static_cast<double>((v >> 16) & 0xff)};
}

std::vector<cv::Point> site_cv_points(const std::vector<Vec2>& px) {
  std::vector<cv::Point> out;
  for (const Vec2& p : px) out.emplace_back(cvRound(p.x), cvRound(p.y));
  return out;
}

void site_raster(const SitePrim& p, const std::vector<Vec2>& outline_px, cv::Mat* img) {
  const auto pts = site_cv_points(p.px);
  if (p.clip_to_outline && outline_px.size() >= 3 && pts.size() >= 3) {
    // Drawn on a copy, then copied back only inside the outline.
    SitePrim unclipped = p;
    unclipped.clip_to_outline = false;
    cv::Mat layer = img->clone();
    site_raster(unclipped, outline_px, &layer);
    cv::Mat mask = cv::Mat::zeros(img->size(), CV_8UC1);
    cv::fillPoly(mask, std::vector<std::vector<cv::Point>>{site_cv_points(outline_px)},
                 cv::Scalar(255));
    layer.copyTo(*img, mask);
    return;
  }
  const int thick = std::max(1, static_cast<int>(std::lround(p.stroke_px)));
  switch (p.kind) {
    case SitePrim::kPolygon:
      if (pts.size() < 3) return;
      if (p.fill != "none") {
        if (p.fill_opacity >= 1.0) {
          cv::fillPoly(*img, std::vector<std::vector<cv::Point>>{pts}, site_bgr(p.fill),
                       cv::LINE_AA);
        } else {
          cv::Mat layer = img->clone();
          cv::fillPoly(layer, std::vector<std::vector<cv::Point>>{pts}, site_bgr(p.fill),
                       cv::LINE_AA);
          cv::addWeighted(layer, p.fill_opacity, *img, 1.0 - p.fill_opacity, 0.0, *img);
        }
      }
      if (p.stroke != "none")
        cv::polylines(*img, pts, true, site_bgr(p.stroke), thick, cv::LINE_AA);
      return;
    case SitePrim::kPolyline:
      if (pts.size() >= 2) cv::polylines(*img, pts, false, site_bgr(p.stroke), thick, cv::LINE_AA);
      return;
    case SitePrim::kCircle:
      cv::circle(*img, pts[0], static_cast<int>(std::lround(p.radius_px)), site_bgr(p.fill),
                 cv::FILLED, cv::LINE_AA);
      return;
    case SitePrim::kText:
      cv::putText(*img, p.text, pts[0], cv::FONT_HERSHEY_SIMPLEX, p.text_px / 24.0,
                  site_bgr(p.fill), 1, cv::LINE_AA);
      return;
  }
}

}  // namespace
}  // namespace site_draw

std::string site_svg(const agv::site::Site& site, const std::vector<std::vector<Vec2>>& routes,
                     const std::vector<agv::site::Polygon>& extra_polygons, double px_per_m) {
  const site_draw::SiteScene sc =
      site_draw::build_site_scene(site, routes, extra_polygons, px_per_m);
  std::ostringstream os;
  char head[256];
  std::snprintf(head, sizeof head,
                "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"%.0f\" height=\"%.0f\" "
                "viewBox=\"0 0 %.2f %.2f\" font-family=\"sans-serif\">\n",
                std::ceil(sc.width_px), std::ceil(sc.height_px), sc.width_px, sc.height_px);
  os << head << "<rect width=\"100%\" height=\"100%\" fill=\"#ffffff\"/>\n"
     << "<clipPath id=\"site-outline\"><polygon points=\"" << site_draw::site_points(sc.outline_px)
     << "\"/></clipPath>\n";
  for (const site_draw::SitePrim& p : sc.prims) {
    const std::string style =
        "fill=\"" + p.fill + "\" stroke=\"" + p.stroke + "\" stroke-width=\"" +
        std::to_string(p.stroke_px) + "\"" +
        (p.fill_opacity < 1.0 ? " fill-opacity=\"" + std::to_string(p.fill_opacity) + "\"" : "") +
        (p.dashed ? " stroke-dasharray=\"6,4\"" : "") +
        (p.clip_to_outline ? " clip-path=\"url(#site-outline)\"" : "");
    switch (p.kind) {
      case site_draw::SitePrim::kPolygon:
        os << "<polygon points=\"" << site_draw::site_points(p.px) << "\" " << style << "/>\n";
        break;
      case site_draw::SitePrim::kPolyline:
        os << "<polyline points=\"" << site_draw::site_points(p.px) << "\" " << style
           << " stroke-linejoin=\"round\"/>\n";
        break;
      case site_draw::SitePrim::kCircle:
        os << "<circle cx=\"" << p.px[0].x << "\" cy=\"" << p.px[0].y << "\" r=\"" << p.radius_px
           << "\" " << style << "/>\n";
        break;
      case site_draw::SitePrim::kText:
        os << "<text x=\"" << p.px[0].x << "\" y=\"" << p.px[0].y << "\" font-size=\"" << p.text_px
           << "\" fill=\"" << p.fill << "\">" << escape_xml(p.text) << "</text>\n";
        break;
    }
  }
  os << "</svg>\n";
  return os.str();
}

bool site_png(const agv::site::Site& site, const std::vector<std::vector<Vec2>>& routes,
              const std::vector<agv::site::Polygon>& extra_polygons, double px_per_m, cv::Mat* out,
              std::string* error) {
  const site_draw::SiteScene sc =
      site_draw::build_site_scene(site, routes, extra_polygons, px_per_m);
  const double w = std::ceil(sc.width_px), h = std::ceil(sc.height_px);
  if (!(w <= kSiteDrawMaxPngSidePx && h <= kSiteDrawMaxPngSidePx)) {
    char buf[160];
    std::snprintf(buf, sizeof buf,
                  "the image would be %.0f x %.0f px, more than %d on a side; lower --px-per-m", w,
                  h, kSiteDrawMaxPngSidePx);
    *error = buf;
    return false;
  }
  cv::Mat img(static_cast<int>(h), static_cast<int>(w), CV_8UC3, cv::Scalar(255, 255, 255));
  for (const site_draw::SitePrim& p : sc.prims) site_draw::site_raster(p, sc.outline_px, &img);
  *out = img;
  return true;
}

}  // namespace agv::desk
