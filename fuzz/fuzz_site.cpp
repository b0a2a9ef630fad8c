// Site file (docs/guide/site.md), as `agvloc-desk site check` reads it. The input is the site
// text, then optionally a NUL byte and the floor map's text. Properties: nothing throws, aborts
// or hangs; accepted exactly when no error is reported, every error names a key, at most
// max_errors + 1 of them; an accepted site has counter-clockwise polygons of 3+ finite vertices,
// and what write_site makes of it reads back, accepted, with the same contents.
#include <algorithm>
#include <cmath>
#include <string>
#include <vector>

#include "agv/site/site_file.hpp"
#include "agv/site/site_geometry.hpp"
#include "fuzz_check.hpp"

namespace {

void check_polygon(const agv::site::Polygon& p, const char* what) {
  FUZZ_CHECK(p.vertices_mm.size() >= 3, "%s has %zu vertices", what, p.vertices_mm.size());
  for (const auto& v : p.vertices_mm) {
    FUZZ_CHECK(std::isfinite(v.x) && std::isfinite(v.y), "%s has a non-finite vertex", what);
  }
  FUZZ_CHECK(agv::site::signed_area_mm2(p) > 0.0, "%s is not counter-clockwise", what);
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const unsigned char* data, std::size_t size) {
  const std::string_view all = agv::fuzz::as_text(data, size);
  const std::size_t nul = all.find('\0');
  const std::string_view site_text = all.substr(0, nul);
  const std::string_view map_text = nul == std::string_view::npos ? "" : all.substr(nul + 1);
  // Tighter than the defaults so that every input stays well within the 1 s per input.
  agv::site::SiteLimits limits;
  limits.max_obstacles = 200;
  limits.max_total_vertices = 5000;
  limits.max_wall_landmarks = 200;
  limits.max_fleet = 100;
  agv::site::Site site;
  std::vector<agv::site::SiteError> errors;
  const bool ok = agv::site::parse_site(site_text, map_text, &site, &errors, limits);
  FUZZ_CHECK(ok == errors.empty(), "accepted=%d with %zu errors", ok, errors.size());
  FUZZ_CHECK(errors.size() <= limits.max_errors + 1, "%zu errors", errors.size());
  for (const auto& e : errors) {
    FUZZ_CHECK(!e.key.empty() && !e.message.empty() && e.line >= 0, "'%s'", e.to_string().c_str());
  }
  std::string file, error;
  agv::site::site_floor_map_file(site_text, &file, &error);
  if (!ok) return 0;
  check_polygon(site.outline, "the outline");
  for (const auto& o : site.obstacles) check_polygon(o.outline, "an obstacle");
  for (const auto& a : site.fleet) check_polygon(a.footprint, "a footprint");
  FUZZ_CHECK(file == site.floor_map_file, "floor map file '%s' vs '%s'", file.c_str(),
             site.floor_map_file.c_str());
  (void)agv::site::site_warnings(site);
  const std::string written = agv::site::write_site(site);
  agv::site::Site back;
  FUZZ_CHECK(agv::site::parse_site(written, map_text, &back, &errors, limits),
             "write_site's output is refused: %s",
             errors.empty() ? "" : errors.front().to_string().c_str());
  FUZZ_CHECK(back.name == site.name && back.obstacles.size() == site.obstacles.size() &&
                 back.wall_landmarks.size() == site.wall_landmarks.size() &&
                 back.cameras.size() == site.cameras.size() &&
                 back.fleet.size() == site.fleet.size() &&
                 back.outline.vertices_mm.size() == site.outline.vertices_mm.size(),
             "the written site reads back different");
  return 0;
}
