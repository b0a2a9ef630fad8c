// The site file (docs/guide/site.md): reading (keys, types, ranges, limits, lines), the semantic
// checks, the camera orientation convention and the write/parse round trip.
#include <gtest/gtest.h>

#include <array>
#include <cmath>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include "agv/site/site_file.hpp"
#include "agv/site/site_geometry.hpp"

namespace agv::site {
namespace {

std::string read_file(const std::string& path) {
  std::ifstream f(path);
  std::ostringstream os;
  os << f.rdbuf();
  return os.str();
}

// A valid site of 10 m x 10 m with nothing in it; tests append sections.
const std::string kHead =
    "name: test\n"                                                     // line 1
    "outline_mm: [[0, 0], [10000, 0], [10000, 10000], [0, 10000]]\n";  // line 2

struct Result {
  bool ok = false;
  Site site;
  std::vector<SiteError> errors;
  std::string all;  // every error's text, one per line
};

Result parse(const std::string& text, const std::string& map_text = "",
             const SiteLimits& limits = {}) {
  Result r;
  r.ok = parse_site(text, map_text, &r.site, &r.errors, limits);
  for (const auto& e : r.errors) r.all += e.to_string() + "\n";
  return r;
}

// True when some error has this key and line and its message contains `what`.
bool has_error(const Result& r, const std::string& key, int line, const std::string& what) {
  for (const auto& e : r.errors) {
    if (e.key == key && e.line == line && e.message.find(what) != std::string::npos) return true;
  }
  return false;
}

const std::string kRack =
    "  - {id: r1, kind: rack, height_mm: 2000, box_mm: {x_min: 1000, y_min: 1000, x_max: 5000, "
    "y_max: 2000}}\n";
const std::string kCamera =
    "  - id: c1\n"
    "    intrinsics: {width_px: 640, height_px: 480, fx: 400, fy: 400, cx: 319.5, cy: 239.5}\n"
    "    pose: {x_mm: 5000, y_mm: 5000, z_mm: 5000}\n";
const std::string kAgv = "  - {id: a1, tag_id: 5}\n";

TEST(SiteFile, ExampleSiteParses) {
  const std::string dir = AGV_SOURCE_DIR "/tools/maps/";
  const std::string text = read_file(dir + "example_site.yaml");
  std::string map_file, error;
  ASSERT_TRUE(site_floor_map_file(text, &map_file, &error)) << error;
  EXPECT_EQ(map_file, "default_grid.csv");
  // A site without a floor map, or a text that is not a mapping, names none.
  std::string none = "x";
  ASSERT_TRUE(site_floor_map_file(kHead, &none, &error));
  EXPECT_EQ(none, "");
  ASSERT_TRUE(site_floor_map_file("- a\n- b\n", &none, &error));
  EXPECT_EQ(none, "");
  EXPECT_FALSE(site_floor_map_file("a: [\n", &none, &error));
  EXPECT_NE(error.find("line"), std::string::npos);
  const Result r = parse(text, read_file(dir + map_file));
  ASSERT_TRUE(r.ok) << r.all;
  EXPECT_EQ(r.site.name, "example warehouse");
  EXPECT_EQ(r.site.obstacles.size(), 5u);
  EXPECT_EQ(r.site.wall_landmarks.size(), 7u);
  EXPECT_EQ(r.site.cameras.size(), 2u);
  EXPECT_EQ(r.site.fleet.size(), 3u);
  EXPECT_EQ(r.site.floor_map.entries.size(), 25u);
  EXPECT_TRUE(site_warnings(r.site).empty());
  // Defaults: the footprint is the tray, the radius its farthest corner.
  const FleetAgv& a = r.site.fleet[0];
  EXPECT_EQ(a.footprint.vertices_mm.size(), 4u);
  EXPECT_NEAR(a.radius_mm, std::hypot(300.0, 200.0), 1e-9);
  EXPECT_DOUBLE_EQ(r.site.fleet[1].radius_mm, 400.0);
}

TEST(SiteFile, WriteThenParseGivesTheSameSite) {
  const std::string dir = AGV_SOURCE_DIR "/tools/maps/";
  const std::string map_text = read_file(dir + "default_grid.csv");
  Result a = parse(read_file(dir + "example_site.yaml"), map_text);
  ASSERT_TRUE(a.ok) << a.all;
  // Awkward values: digits that need 17 significant figures, a name that needs quoting.
  a.site.name = "site: \"north\" #2";
  a.site.obstacles[0].height_mm = 0.1 + 0.2;
  a.site.cameras[1].r_site_cam = camera_rotation_from_angles(0.3, 0.2, -0.1);
  a.site.cameras[1].position_sigma_mm = {0.38, 0.55, 0.1};
  a.site.cameras[1].angle_sigma_rad = {8e-5, 1.3e-4, 2e-5};
  a.site.cameras[1].pose_correlation[3] = -0.912345678901;  // x with pitch
  a.site.cameras[1].pose_correlation[7] = 0.1 + 0.2;        // y with pitch
  a.site.cameras[1].floor_sigma_mm = 1.0 / 3.0;
  ASSERT_FALSE(a.site.fleet.empty());
  a.site.fleet[0].tray_roll_rad = 0.0123;
  a.site.fleet[0].tray_pitch_rad = -0.0071;
  const std::string text = write_site(a.site);
  const Result b = parse(text, map_text);
  ASSERT_TRUE(b.ok) << b.all << text;
  const Site& s = a.site;
  const Site& t = b.site;
  EXPECT_EQ(t.name, s.name);
  EXPECT_EQ(t.clearance_mm, s.clearance_mm);
  EXPECT_EQ(t.floor_map_file, s.floor_map_file);
  EXPECT_EQ(t.floor_map.entries.size(), s.floor_map.entries.size());
  auto same_polygon = [](const Polygon& p, const Polygon& q) {
    if (p.vertices_mm.size() != q.vertices_mm.size()) return false;
    for (std::size_t i = 0; i < p.vertices_mm.size(); ++i) {
      if (p.vertices_mm[i].x != q.vertices_mm[i].x || p.vertices_mm[i].y != q.vertices_mm[i].y) {
        return false;
      }
    }
    return true;
  };
  EXPECT_TRUE(same_polygon(t.outline, s.outline));
  ASSERT_EQ(t.obstacles.size(), s.obstacles.size());
  for (std::size_t i = 0; i < s.obstacles.size(); ++i) {
    EXPECT_EQ(t.obstacles[i].id, s.obstacles[i].id);
    EXPECT_EQ(t.obstacles[i].kind, s.obstacles[i].kind);
    EXPECT_EQ(t.obstacles[i].height_mm, s.obstacles[i].height_mm);
    EXPECT_TRUE(same_polygon(t.obstacles[i].outline, s.obstacles[i].outline)) << i;
  }
  ASSERT_EQ(t.wall_landmarks.size(), s.wall_landmarks.size());
  for (std::size_t i = 0; i < s.wall_landmarks.size(); ++i) {
    const WallLandmark &w = s.wall_landmarks[i], &v = t.wall_landmarks[i];
    EXPECT_EQ(v.id, w.id);
    EXPECT_EQ(v.family, w.family);
    EXPECT_EQ(v.x_mm, w.x_mm);
    EXPECT_EQ(v.y_mm, w.y_mm);
    EXPECT_EQ(v.z_mm, w.z_mm);
    EXPECT_EQ(v.size_mm, w.size_mm);
    // Written in degrees: back to the radian within rounding of the conversion.
    EXPECT_NEAR(v.facing_rad, w.facing_rad, 1e-15);
  }
  ASSERT_EQ(t.cameras.size(), s.cameras.size());
  for (std::size_t i = 0; i < s.cameras.size(); ++i) {
    const CeilingCamera &c = s.cameras[i], &d = t.cameras[i];
    EXPECT_EQ(d.id, c.id);
    EXPECT_EQ(d.intrinsics.width_px, c.intrinsics.width_px);
    EXPECT_EQ(d.intrinsics.fx, c.intrinsics.fx);
    EXPECT_EQ(d.intrinsics.cy, c.intrinsics.cy);
    EXPECT_EQ(d.intrinsics.k1, c.intrinsics.k1);
    EXPECT_EQ(d.intrinsics.k2, c.intrinsics.k2);
    EXPECT_EQ(d.r_site_cam, c.r_site_cam);  // the matrix is written, exactly
    EXPECT_EQ(d.t_site_cam_mm, c.t_site_cam_mm);
    EXPECT_EQ(d.position_sigma_mm, c.position_sigma_mm);
    EXPECT_EQ(d.pose_correlation, c.pose_correlation);
    EXPECT_EQ(d.floor_sigma_mm, c.floor_sigma_mm);
    for (std::size_t k = 0; k < 3; ++k) {
      EXPECT_NEAR(d.angle_sigma_rad[k], c.angle_sigma_rad[k], 1e-18);  // written in degrees
    }
  }
  ASSERT_EQ(t.fleet.size(), s.fleet.size());
  for (std::size_t i = 0; i < s.fleet.size(); ++i) {
    const FleetAgv &f = s.fleet[i], &g = t.fleet[i];
    EXPECT_EQ(g.id, f.id);
    EXPECT_EQ(g.tag_id, f.tag_id);
    EXPECT_EQ(g.tag_size_mm, f.tag_size_mm);
    EXPECT_EQ(g.tray_length_mm, f.tray_length_mm);
    EXPECT_EQ(g.tray_width_mm, f.tray_width_mm);
    EXPECT_EQ(g.tray_height_mm, f.tray_height_mm);
    EXPECT_NEAR(g.tray_roll_rad, f.tray_roll_rad, 1e-18);  // written in degrees
    EXPECT_NEAR(g.tray_pitch_rad, f.tray_pitch_rad, 1e-18);
    EXPECT_EQ(g.radius_mm, f.radius_mm);
    EXPECT_TRUE(same_polygon(g.footprint, f.footprint));
  }
  // And writing the read-back site gives the same text.
  EXPECT_EQ(write_site(t), text);
}

TEST(SiteFile, MinimalSiteAndDefaults) {
  const Result r = parse(kHead);
  ASSERT_TRUE(r.ok) << r.all;
  EXPECT_DOUBLE_EQ(r.site.clearance_mm, 100.0);
  EXPECT_TRUE(r.site.obstacles.empty());
  EXPECT_TRUE(r.site.floor_map.entries.empty());
}

TEST(SiteFile, UnknownKeyNamesLineAndSuggests) {
  const Result r = parse(kHead + "obstacle:\n" + kRack);
  EXPECT_FALSE(r.ok);
  EXPECT_TRUE(has_error(r, "obstacle", 3, "did you mean 'obstacles'")) << r.all;
  const Result s = parse(kHead +
                         "obstacles:\n  - {id: r1, kind: rack, heigth_mm: 2, "
                         "box_mm: {x_min: 1, y_min: 1, x_max: 5, y_max: 2}}\n");
  EXPECT_TRUE(has_error(s, "obstacles[0].heigth_mm", 4, "did you mean 'height_mm'")) << s.all;
  const Result t = parse(kHead + "zzz_unrelated: 1\n");
  EXPECT_TRUE(has_error(t, "zzz_unrelated", 3, "unknown key")) << t.all;
  EXPECT_EQ(t.all.find("did you mean"), std::string::npos);
}

// A tagged or quoted empty key is a scalar with no name; the error must still name where.
TEST(SiteFile, EmptyKeyIsNamedByItsMapping) {
  for (const std::string line : {"\"\": 1\n", "!x : 2\n"}) {
    const Result r = parse(kHead + line);
    EXPECT_FALSE(r.ok) << line;
    EXPECT_TRUE(has_error(r, "top level", 3, "empty key")) << line << r.all;
  }
}

TEST(SiteFile, ReportsEveryErrorWithKeyAndLine) {
  const Result r = parse(
      "name: test\n"
      "clearance_mm: lots\n"                                          // 2: not a number
      "outline_mm: [[0, 0], [.nan, 0], [10000, 10000], [0, 1e99]]\n"  // 3: NaN, out of range
      "obstacles:\n"
      "  - {id: r1, kind: shelf, height_mm: -5, box_mm: {x_min: 0, y_min: 0, x_max: 1, "
      "y_max: 1}}\n"  // 5: kind, height
      "fleet:\n"
      "  - {id: a1, tag_id: 587}\n"                                         // 7: tag id range
      "  - {id: a2, tag_id: [1]}\n"                                         // 8: type
      "  - {id: a3, tag_id: 3, tray: {roll_deg: 20, pitch_deg: .nan}}\n");  // 9: tilt
  EXPECT_FALSE(r.ok);
  EXPECT_TRUE(has_error(r, "clearance_mm", 2, "expected a number")) << r.all;
  EXPECT_TRUE(has_error(r, "outline_mm[1].x", 3, "not a finite number")) << r.all;
  EXPECT_TRUE(has_error(r, "outline_mm[3].y", 3, "outside")) << r.all;
  EXPECT_TRUE(has_error(r, "obstacles[0].kind", 5, "'shelf' is not one of")) << r.all;
  EXPECT_TRUE(has_error(r, "obstacles[0].height_mm", 5, "outside (0,")) << r.all;
  EXPECT_TRUE(has_error(r, "fleet[0].tag_id", 7, "outside [0, 586]")) << r.all;
  EXPECT_TRUE(has_error(r, "fleet[1].tag_id", 8, "expected an integer")) << r.all;
  EXPECT_TRUE(has_error(r, "fleet[2].tray.roll_deg", 9, "outside [-15, 15]")) << r.all;
  EXPECT_TRUE(has_error(r, "fleet[2].tray.pitch_deg", 9, "not a finite number")) << r.all;
  EXPECT_EQ(r.errors.size(), 9u) << r.all;
  for (const auto& e : r.errors) EXPECT_GT(e.line, 0) << e.to_string();
}

TEST(SiteFile, MissingRequiredKeysDuplicateKeysAndTypes) {
  const Result r = parse("outline_mm: 5\nname: a\nname: b\n");
  EXPECT_TRUE(has_error(r, "outline_mm", 1, "expected a sequence")) << r.all;
  EXPECT_TRUE(has_error(r, "name", 3, "duplicate key (first at line 2)")) << r.all;
  const Result s = parse(kHead + "cameras:\n  - {id: c1}\n");
  EXPECT_TRUE(has_error(s, "cameras[0].intrinsics", 4, "missing")) << s.all;
  EXPECT_TRUE(has_error(s, "cameras[0].pose", 4, "missing")) << s.all;
  const Result t = parse("- just\n- a list\n");
  EXPECT_TRUE(has_error(t, "top level", 1, "expected a mapping")) << t.all;
  const Result u = parse(kHead + "obstacles: {a: 1}\n");
  EXPECT_TRUE(has_error(u, "obstacles", 3, "expected a sequence")) << u.all;
  const Result v = parse(kHead + "name2: [\n");
  ASSERT_EQ(v.errors.size(), 1u);
  EXPECT_EQ(v.errors[0].key, "site");
  EXPECT_NE(v.errors[0].message.find("YAML syntax error"), std::string::npos);
  EXPECT_GT(v.errors[0].line, 0);
  const Result w = parse("name: \"a\\nb\"\n" + kHead.substr(kHead.find('\n') + 1));
  EXPECT_TRUE(has_error(w, "name", 1, "control character")) << w.all;
}

TEST(SiteFile, LimitsBoundSizes) {
  SiteLimits lim;
  lim.max_obstacles = 1;
  const Result r = parse(kHead + "obstacles:\n" + kRack + kRack, "", lim);
  EXPECT_TRUE(has_error(r, "obstacles", 4, "2 items, at most 1")) << r.all;
  lim = {};
  lim.max_vertices_per_polygon = 3;
  const Result s = parse(kHead, "", lim);
  EXPECT_TRUE(has_error(s, "outline_mm", 2, "4 vertices, at most 3")) << s.all;
  lim = {};
  lim.max_text_bytes = 10;
  EXPECT_TRUE(has_error(parse(kHead, "", lim), "site", 0, "at most 10"));
  // Aliases repeat one polygon without repeating its text: the total is bounded too.
  lim = {};
  lim.max_total_vertices = 10;
  std::string text = kHead +
                     "fleet:\n  - {id: a0, tag_id: 0, footprint_mm: &fp [[-1, -1], "
                     "[1, -1], [1, 1], [-1, 1]]}\n";
  for (int i = 1; i < 5; ++i) {
    text += "  - {id: a" + std::to_string(i) + ", tag_id: " + std::to_string(i) +
            ", footprint_mm: *fp}\n";
  }
  const Result t = parse(text, "", lim);
  // An alias's line is its anchor's.
  EXPECT_TRUE(has_error(t, "fleet[1].footprint_mm", 4, "more than 10 polygon vertices")) << t.all;
  lim = {};
  lim.max_errors = 3;
  const Result u = parse("a: 1\nb: 2\nc: 3\nd: 4\ne: 5\n", "", lim);
  ASSERT_EQ(u.errors.size(), 4u) << u.all;
  EXPECT_NE(u.errors.back().message.find("more errors not shown"), std::string::npos);
}

TEST(SiteFile, PolygonChecks) {
  // A bow tie crosses itself.
  const Result r = parse(kHead +
                         "obstacles:\n  - id: bow\n    kind: other\n"
                         "    outline_mm: [[1000, 1000], [3000, 2000], [3000, 1000], "
                         "[1000, 3000]]\n");
  EXPECT_TRUE(has_error(r, "obstacles[0].outline_mm", 6, "self-intersecting")) << r.all;
  // A symmetric one: its lobes' areas cancel.
  const Result q = parse(kHead +
                         "obstacles:\n  - {id: bow, kind: other, outline_mm: [[1000, "
                         "1000], [2000, 2000], [2000, 1000], [1000, 2000]]}\n");
  EXPECT_TRUE(has_error(q, "obstacles[0].outline_mm", 4, "self-intersecting")) << q.all;
  const Result s = parse(kHead +
                         "obstacles:\n  - {id: two, kind: other, outline_mm: "
                         "[[1000, 1000], [2000, 2000], [1000, 1000]]}\n");
  EXPECT_TRUE(has_error(s, "obstacles[0].outline_mm", 4, "at least 3 distinct vertices")) << s.all;
  const Result t = parse("name: t\noutline_mm: [[0, 0], [5000, 0], [10000, 0]]\n");
  EXPECT_TRUE(has_error(t, "outline_mm", 2, "zero area")) << t.all;
}

TEST(SiteFile, ClockwisePolygonsAreReorientedNotRefused) {
  const Result r = parse(
      "name: cw\n"
      "outline_mm: [[0, 0], [0, 10000], [10000, 10000], [10000, 0], [0, 0]]\n"
      "obstacles:\n"
      "  - {id: r1, kind: rack, outline_mm: [[1000, 1000], [1000, 2000], [3000, 2000], "
      "[3000, 1000]]}\n");
  ASSERT_TRUE(r.ok) << r.all;
  EXPECT_EQ(r.site.outline.vertices_mm.size(), 4u);  // the closing vertex dropped
  EXPECT_GT(signed_area_mm2(r.site.outline), 0.0);
  EXPECT_DOUBLE_EQ(signed_area_mm2(r.site.obstacles[0].outline), 2000.0 * 1000.0);
}

TEST(SiteFile, OverlappingObstaclesNameBothTouchingOnesAreFine) {
  const std::string other =
      "  - {id: r2, kind: rack, box_mm: {x_min: 4000, y_min: 1500, x_max: 6000, y_max: 3000}}\n";
  const Result r = parse(kHead + "obstacles:\n" + kRack + other);
  EXPECT_TRUE(has_error(r, "obstacles[1].outline_mm", 5, "'r2' overlaps obstacle 'r1'")) << r.all;
  EXPECT_NE(r.all.find("line 4"), std::string::npos) << r.all;
  const std::string touching =
      "  - {id: r2, kind: rack, box_mm: {x_min: 5000, y_min: 1000, x_max: 6000, y_max: 3000}}\n"
      "  - {id: r3, kind: pillar, box_mm: {x_min: 1000, y_min: 2000, x_max: 2000, y_max: 2500}}\n";
  const Result s = parse(kHead + "obstacles:\n" + kRack + touching);
  EXPECT_TRUE(s.ok) << s.all;
  // One inside the other: interiors intersect too.
  const std::string inside =
      "  - {id: r2, kind: pillar, box_mm: {x_min: 2000, y_min: 1200, x_max: 2500, y_max: 1800}}\n";
  EXPECT_TRUE(has_error(parse(kHead + "obstacles:\n" + kRack + inside), "obstacles[1].outline_mm",
                        5, "overlaps obstacle 'r1'"));
}

TEST(SiteFile, ObstacleOutsideOutlineAndDuplicateIds) {
  const std::string out =
      "  - {id: r1, kind: rack, box_mm: {x_min: 9000, y_min: 1000, x_max: 11000, y_max: 2000}}\n";
  EXPECT_TRUE(has_error(parse(kHead + "obstacles:\n" + kRack + out), "obstacles[1].outline_mm", 5,
                        "not inside the site outline"));
  const Result r = parse(kHead + "obstacles:\n" + kRack +
                         "  - {id: r1, kind: rack, box_mm: {x_min: 6000, y_min: 1000, x_max: "
                         "7000, y_max: 2000}}\n");
  EXPECT_TRUE(has_error(r, "obstacles[1].id", 5, "duplicate id (also obstacles[0], line 4)"))
      << r.all;
  // A wall along the outline's edge is inside it.
  EXPECT_TRUE(parse(kHead + "obstacles:\n  - {id: w, kind: wall, box_mm: {x_min: 0, y_min: 0, "
                            "x_max: 10000, y_max: 200}}\n")
                  .ok);
}

TEST(SiteFile, WallLandmarkChecks) {
  auto site = [&](const std::string& landmarks) {
    return parse(kHead + "obstacles:\n" + kRack + "wall_landmarks:\n" + landmarks);
  };
  // On the rack's west face (x = 1000), facing out: fine; 0.5 mm inside still counts as on it.
  EXPECT_TRUE(site("  - {id: 1, family: tag36h11, x_mm: 1000, y_mm: 1500, z_mm: 1000, "
                   "facing_deg: 180}\n  - {id: 2, family: tag36h11, x_mm: 1000.5, y_mm: 1400, "
                   "z_mm: 1000, facing_deg: 180}\n")
                  .ok);
  const Result deep =
      site("  - {id: 1, family: tag36h11, x_mm: 1100, y_mm: 1500, z_mm: 1000, facing_deg: 180}\n");
  EXPECT_TRUE(has_error(deep, "wall_landmarks[0]", 6, "is inside obstacle 'r1'")) << deep.all;
  const Result into =
      site("  - {id: 1, family: tag36h11, x_mm: 1000, y_mm: 1500, z_mm: 1000, facing_deg: 0}\n");
  EXPECT_TRUE(has_error(into, "wall_landmarks[0].facing_deg", 6, "faces into obstacle 'r1'"))
      << into.all;
  const Result dup = site(
      "  - {id: 7, family: tag36h11, x_mm: 1000, y_mm: 1500, z_mm: 1000, facing_deg: 180}\n"
      "  - {id: 7, family: agvloc, x_mm: 1000, y_mm: 1200, z_mm: 1000, facing_deg: 180}\n"
      "  - {id: 7, family: tag36h11, x_mm: 1000, y_mm: 1800, z_mm: 1000, facing_deg: 180}\n");
  EXPECT_TRUE(has_error(dup, "wall_landmarks[2].id", 8, "duplicate id (also wall_landmarks[0]"))
      << dup.all;
  EXPECT_EQ(dup.errors.size(), 1u) << dup.all;  // the same id in another family is another tag
  const Result range =
      site("  - {id: 0, family: agvloc, x_mm: 1000, y_mm: 1500, z_mm: 1000, facing_deg: 180}\n");
  EXPECT_TRUE(has_error(range, "wall_landmarks[0].id", 6, "outside [1, 65535]")) << range.all;
  const Result outside =
      site("  - {id: 1, family: tag36h11, x_mm: -100, y_mm: 1500, z_mm: 1000, facing_deg: 180}\n");
  EXPECT_TRUE(has_error(outside, "wall_landmarks[0]", 6, "outside the site outline"))
      << outside.all;
  const Result wall =
      site("  - {id: 1, family: tag36h11, x_mm: 0, y_mm: 1500, z_mm: 1000, facing_deg: 180}\n");
  EXPECT_TRUE(has_error(wall, "wall_landmarks[0].facing_deg", 6, "faces out of the site"))
      << wall.all;
  EXPECT_TRUE(site("  - {id: 1, family: tag36h11, x_mm: 0, y_mm: 1500, z_mm: 1000, "
                   "facing_deg: 0}\n")
                  .ok);
}

TEST(SiteFile, CameraChecks) {
  EXPECT_TRUE(parse(kHead + "cameras:\n" + kCamera).ok);
  const Result dup = parse(kHead + "cameras:\n" + kCamera + kCamera);
  EXPECT_TRUE(has_error(dup, "cameras[1].id", 7, "duplicate id (also cameras[0], line 4)"))
      << dup.all;
  // Tilted 85 degrees: looks at the walls, not the floor.
  const Result tilted =
      parse(kHead + "cameras:\n" + kCamera.substr(0, kCamera.rfind('}')) + ", pitch_deg: 85}\n");
  EXPECT_TRUE(has_error(tilted, "cameras[0].pose", 4, "does not look down enough")) << tilted.all;
  // Above a point 100 m away from the site: sees only floor outside the outline.
  std::string far = kCamera;
  far.replace(far.find("x_mm: 5000"), 10, "x_mm: 100000");
  const Result away = parse(kHead + "cameras:\n" + far);
  EXPECT_TRUE(has_error(away, "cameras[0].pose", 4, "has no view of the floor")) << away.all;
  // Not above the trays (400 mm by default).
  std::string low = kCamera;
  low.replace(low.find("z_mm: 5000"), 10, "z_mm: 300");
  const Result below = parse(kHead + "cameras:\n" + low + "fleet:\n" + kAgv);
  EXPECT_TRUE(has_error(below, "cameras[0].pose.z_mm", 4, "not above the tray of AGV 'a1'"))
      << below.all;
  // The explicit rotation form: a rotation, and not together with the angles.
  const Result bad_r = parse(kHead + "cameras:\n" + kCamera.substr(0, kCamera.rfind('}')) +
                             ", r_site_cam: [1, 0, 0, 0, 1, 0, 0, 0, -1]}\n");
  EXPECT_TRUE(has_error(bad_r, "cameras[0].pose.r_site_cam", 6, "not a rotation")) << bad_r.all;
  const Result both = parse(kHead + "cameras:\n" + kCamera.substr(0, kCamera.rfind('}')) +
                            ", yaw_deg: 3, r_site_cam: [1, 0, 0, 0, -1, 0, 0, 0, -1]}\n");
  EXPECT_TRUE(has_error(both, "cameras[0].pose.r_site_cam", 6, "not both")) << both.all;
  const Result cx = parse(kHead +
                          "cameras:\n  - id: c\n    intrinsics: {width_px: 640, "
                          "height_px: 480, fx: 400, fy: 400, cx: 900, cy: 239.5}\n"
                          "    pose: {x_mm: 1, y_mm: 1, z_mm: 5000}\n");
  EXPECT_TRUE(has_error(cx, "cameras[0].intrinsics.cx", 5, "outside [0, 640]")) << cx.all;
  // The calibration's pose sigma: optional, each parameter >= 0 and bounded.
  const Result sigma = parse(kHead + "cameras:\n" + kCamera +
                             "    pose_sigma: {x_mm: 0.4, z_mm: 0.1, pitch_deg: 0.01}\n");
  ASSERT_TRUE(sigma.ok) << sigma.all;
  const CeilingCamera& sc = sigma.site.cameras[0];
  EXPECT_EQ(sc.position_sigma_mm, (std::array<double, 3>{0.4, 0.0, 0.1}));
  EXPECT_NEAR(sc.angle_sigma_rad[1], 0.01 * M_PI / 180.0, 1e-15);
  EXPECT_EQ(sc.angle_sigma_rad[0], 0.0);
  EXPECT_EQ(parse(kHead + "cameras:\n" + kCamera).site.cameras[0].position_sigma_mm,
            (std::array<double, 3>{0.0, 0.0, 0.0}));
  const Result negative =
      parse(kHead + "cameras:\n" + kCamera + "    pose_sigma: {y_mm: -1, yaw_deg: 45}\n");
  EXPECT_TRUE(has_error(negative, "cameras[0].pose_sigma.y_mm", 7, "outside")) << negative.all;
  EXPECT_TRUE(has_error(negative, "cameras[0].pose_sigma.yaw_deg", 7, "outside")) << negative.all;
  const Result unknown = parse(kHead + "cameras:\n" + kCamera + "    pose_sigma: {yaw_rad: 0.1}\n");
  EXPECT_TRUE(has_error(unknown, "cameras[0].pose_sigma.yaw_rad", 7, "unknown key")) << unknown.all;
  // Their correlation: 15 coefficients that make a correlation matrix, else a named error.
  const std::string zeros13 = "0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0";
  const Result rho =
      parse(kHead + "cameras:\n" + kCamera +
            "    pose_sigma: {x_mm: 1, pitch_deg: 0.01, correlation: [0, 0, 0, -0.9, " +
            zeros13.substr(6) + "]}\n");
  ASSERT_TRUE(rho.ok) << rho.all;
  EXPECT_EQ(pose_correlation_at(rho.site.cameras[0], 0, 3), 0.0);
  EXPECT_EQ(pose_correlation_at(rho.site.cameras[0], 4, 0), -0.9);
  EXPECT_EQ(pose_correlation_at(rho.site.cameras[0], 2, 2), 1.0);
  EXPECT_EQ(rho.site.cameras[0].floor_sigma_mm, 0.0);  // not given: none
  const Result floor = parse(kHead + "cameras:\n" + kCamera + "    pose_sigma: {floor_mm: 2.5}\n");
  ASSERT_TRUE(floor.ok) << floor.all;
  EXPECT_EQ(floor.site.cameras[0].floor_sigma_mm, 2.5);
  const Result floor_neg =
      parse(kHead + "cameras:\n" + kCamera + "    pose_sigma: {floor_mm: -1}\n");
  EXPECT_TRUE(has_error(floor_neg, "cameras[0].pose_sigma.floor_mm", 7, "outside"))
      << floor_neg.all;
  const Result short_list =
      parse(kHead + "cameras:\n" + kCamera + "    pose_sigma: {correlation: [0.5, 0.1]}\n");
  EXPECT_TRUE(has_error(short_list, "cameras[0].pose_sigma.correlation", 7, "15 numbers"))
      << short_list.all;
  // x~y 0.9, x~z 0.9, y~z -0.9: no such three variables.
  const Result not_psd = parse(kHead + "cameras:\n" + kCamera +
                               "    pose_sigma: {correlation: [0.9, 0.9, 0, 0, 0, -0.9, " +
                               zeros13.substr(12) + "]}\n");
  EXPECT_TRUE(has_error(not_psd, "cameras[0].pose_sigma.correlation", 7, "not a correlation"))
      << not_psd.all;
  const Result beyond = parse(kHead + "cameras:\n" + kCamera +
                              "    pose_sigma: {correlation: [1.5, " + zeros13 + ", 0]}\n");
  EXPECT_TRUE(has_error(beyond, "cameras[0].pose_sigma.correlation[0]", 7, "outside"))
      << beyond.all;
}

TEST(SiteFile, FleetChecks) {
  const Result dup = parse(kHead + "fleet:\n" + kAgv + kAgv);
  EXPECT_TRUE(has_error(dup, "fleet[1].id", 5, "duplicate id")) << dup.all;
  EXPECT_TRUE(has_error(dup, "fleet[1].tag_id", 5, "duplicate tag_id (also fleet[0], line 4)"))
      << dup.all;
  const Result centre = parse(kHead +
                              "fleet:\n  - {id: a, tag_id: 1, footprint_mm: [[100, -300], "
                              "[500, -300], [500, 300], [100, 300]], radius_mm: 600}\n");
  EXPECT_TRUE(has_error(centre, "fleet[0].footprint_mm", 4, "does not contain")) << centre.all;
  const Result radius = parse(kHead + "fleet:\n  - {id: a, tag_id: 1, radius_mm: 300}\n");
  EXPECT_TRUE(has_error(radius, "fleet[0].radius_mm", 4, "beyond radius_mm 300")) << radius.all;
  const Result tag = parse(kHead + "fleet:\n  - {id: a, tag_id: 1, tag_size_mm: 450}\n");
  EXPECT_TRUE(has_error(tag, "fleet[0].tag_size_mm", 4, "does not fit on its tray")) << tag.all;
}

TEST(SiteFile, FleetTagSharedWithAWallTagIsAWarningOnly) {
  const Result r = parse(kHead + "obstacles:\n" + kRack +
                         "wall_landmarks:\n  - {id: 5, family: tag36h11, x_mm: 1000, y_mm: "
                         "1500, z_mm: 1000, facing_deg: 180}\n"
                         "  - {id: 6, family: agvloc, x_mm: 1000, y_mm: 1200, z_mm: 1000, "
                         "facing_deg: 180}\n"
                         "fleet:\n" +
                         kAgv + "  - {id: a2, tag_id: 6}\n");
  ASSERT_TRUE(r.ok) << r.all;
  const auto w = site_warnings(r.site);
  ASSERT_EQ(w.size(), 1u);  // tag 6 is a QR landmark's id: another code book
  EXPECT_NE(w[0].find("fleet[0].tag_id: tag36h11 5 of AGV 'a1' is also wall_landmarks[0]"),
            std::string::npos)
      << w[0];
}

TEST(SiteFile, FloorMapIsParsedAndItsErrorsNamed) {
  const std::string text = kHead + "floor_map:\n  file: grid.csv\n";
  const Result r = parse(text, "id,x_mm,y_mm,heading_deg\n1,100,200,90\n");
  ASSERT_TRUE(r.ok) << r.all;
  EXPECT_EQ(r.site.floor_map_file, "grid.csv");
  ASSERT_EQ(r.site.floor_map.entries.size(), 1u);
  EXPECT_DOUBLE_EQ(r.site.floor_map.entries.at(1).pose.y_mm, 200.0);
  const Result bad = parse(text, "id,x_mm,y_mm,heading_deg\n1,oops,200,90\n");
  EXPECT_TRUE(has_error(bad, "floor_map.file", 4, "'grid.csv': line")) << bad.all;
  const Result outside = parse(text, "id,x_mm,y_mm,heading_deg\n1,-100,200,90\n");
  ASSERT_TRUE(outside.ok);
  ASSERT_EQ(site_warnings(outside.site).size(), 1u);
  EXPECT_NE(site_warnings(outside.site)[0].find("outside the site outline"), std::string::npos);
}

TEST(SiteFile, ObstacleNeedsOneShape) {
  const Result r = parse(kHead + "obstacles:\n  - {id: r, kind: rack}\n");
  EXPECT_TRUE(has_error(r, "obstacles[0]", 4, "exactly one of outline_mm and box_mm")) << r.all;
  const Result s = parse(kHead +
                         "obstacles:\n  - {id: r, kind: rack, box_mm: {x_min: 5, "
                         "y_min: 1, x_max: 2, y_max: 3}}\n");
  EXPECT_TRUE(has_error(s, "obstacles[0].box_mm", 4, "x_max > x_min")) << s.all;
}

TEST(SiteGeometry, CameraAnglesConvention) {
  // Straight down: image right = site +x, image down = site -y, optical axis -z.
  const auto down = camera_rotation_from_angles(0, 0, 0);
  EXPECT_EQ(down, (std::array<double, 9>{1, 0, 0, 0, -1, 0, 0, 0, -1}));
  CeilingCamera cam;
  cam.intrinsics = {640, 480, 400, 400, 319.5, 239.5};
  cam.t_site_cam_mm = {1000, 2000, 4000};
  // Pitch tilts the optical axis towards the image top (+y at yaw 0), roll towards its right.
  cam.r_site_cam = camera_rotation_from_angles(0, 30 * M_PI / 180, 0);
  Vec2 f;
  ASSERT_TRUE(camera_pixel_to_floor(cam, {319.5, 239.5}, &f));
  EXPECT_NEAR(f.x, 1000, 1e-9);
  EXPECT_NEAR(f.y, 2000 + 4000 * std::tan(30 * M_PI / 180), 1e-6);
  EXPECT_NEAR(camera_tilt_rad(cam), 30 * M_PI / 180, 1e-12);
  cam.r_site_cam = camera_rotation_from_angles(0, 0, 20 * M_PI / 180);
  ASSERT_TRUE(camera_pixel_to_floor(cam, {319.5, 239.5}, &f));
  EXPECT_NEAR(f.x, 1000 + 4000 * std::tan(20 * M_PI / 180), 1e-6);
  EXPECT_NEAR(f.y, 2000, 1e-9);
  // Yaw 90: image right points along site +y; the image's right edge is on the +y side.
  cam.r_site_cam = camera_rotation_from_angles(M_PI / 2, 0, 0);
  ASSERT_TRUE(camera_pixel_to_floor(cam, {639, 239.5}, &f));
  EXPECT_NEAR(f.x, 1000, 1e-6);
  EXPECT_NEAR(f.y, 2000 + 4000 * 319.5 / 400, 1e-6);
  // Angles back from the matrix.
  for (const auto& [y, p, r] :
       {std::array<double, 3>{0.3, 0.2, -0.1}, {-2.5, -1.2, 0.7}, {3.0, 0.0, 1.5}}) {
    double y2 = 0, p2 = 0, r2 = 0;
    camera_angles_from_rotation(camera_rotation_from_angles(y, p, r), &y2, &p2, &r2);
    EXPECT_NEAR(y2, y, 1e-12);
    EXPECT_NEAR(p2, p, 1e-12);
    EXPECT_NEAR(r2, r, 1e-12);
  }
  // Looking at the horizon: yaw and roll not unique; the matrix still comes back.
  const auto lock = camera_rotation_from_angles(0.4, M_PI / 2, 0.3);
  double y2 = 0, p2 = 0, r2 = 0;
  camera_angles_from_rotation(lock, &y2, &p2, &r2);
  const auto back = camera_rotation_from_angles(y2, p2, r2);
  for (int i = 0; i < 9; ++i) EXPECT_NEAR(back[i], lock[i], 1e-9) << i;
}

TEST(SiteGeometry, FootprintOfADownCameraIsItsImageOnTheFloor) {
  CeilingCamera cam;
  cam.intrinsics = {641, 481, 400, 400, 320, 240};
  cam.t_site_cam_mm = {0, 0, 4000};
  const auto foot = camera_floor_footprint(cam, 2, 1e6);
  ASSERT_EQ(foot.size(), 8u);
  // First corner: image top-left = site (-x, +y); 320 px at 400 px per 4 m.
  EXPECT_NEAR(foot[0].x, -3200, 1e-6);
  EXPECT_NEAR(foot[0].y, 2400, 1e-6);
  EXPECT_NEAR(signed_area_mm2(Polygon{foot}), 6400.0 * 4800.0, 1e-3);
}

TEST(SiteGeometry, SightLinesStopAtObstaclesTallerThanTheLine) {
  Obstacle rack;
  rack.outline.vertices_mm = {{2000, -500}, {3000, -500}, {3000, 500}, {2000, 500}};
  rack.height_mm = 2000.0;
  const std::vector<Obstacle> racks{rack};
  const std::array<double, 3> cam{0.0, 0.0, 1000.0};
  EXPECT_TRUE(sight_line_blocked(cam, {5000.0, 0.0, 1000.0}, racks));      // through it
  EXPECT_FALSE(sight_line_blocked(cam, {5000.0, 2000.0, 1000.0}, racks));  // beside it
  EXPECT_FALSE(sight_line_blocked(cam, {5000.0, 0.0, 6000.0}, racks));     // over it
  // A landmark on the rack's near face is not hidden by that face, one on the far face is.
  EXPECT_FALSE(sight_line_blocked(cam, {2000.0, 100.0, 1000.0}, racks));
  EXPECT_TRUE(sight_line_blocked(cam, {3000.0, 100.0, 1000.0}, racks));
  EXPECT_FALSE(sight_line_blocked(cam, {5000.0, 0.0, 1000.0}, {}));
}

}  // namespace
}  // namespace agv::site
