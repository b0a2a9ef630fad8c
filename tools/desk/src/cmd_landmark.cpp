// agvloc-desk landmark: one landmark as SVG (exact physical scale) and/or PNG, or a printable sheet
// of every landmark in a map (docs/design/landmark.md).
#include <CLI/CLI.hpp>
#include <cstdio>
#include <fstream>

#include "agv/recording/png_io.hpp"
#include "agv/sim/render.hpp"
#include "cli_parse.hpp"
#include "commands.hpp"
#include "config.hpp"

namespace agv::desk {

namespace {

bool write_file(const std::string& path, const std::string& text) {
  std::ofstream f(path, std::ios::binary | std::ios::trunc);
  f << text;
  return static_cast<bool>(f);
}

// --family tag36h11: one tag (SVG) or a sheet of the map's ids (tag id = map id).
int print_tags(double size_mm, int id, const std::string& map_path, const std::string& sheet,
               const std::string& svg, int columns) {
  AprilTagGeometry g;
  g.size_mm = size_mm;
  g.margin_mm = 2.0 * g.module_mm();
  std::string text, what, err;
  if (!map_path.empty()) {
    LandmarkMap map;
    if (!config::load_map_file(map_path, &map, &err)) err = err.empty() ? "bad map" : err;
    if (err.empty() && sheet.empty()) err = "--map needs --sheet FILE.svg";
    if (err.empty()) text = sim::tag_sheet_svg(g, map, columns);
    if (err.empty() && text.empty()) err = "a map id is not a tag36h11 id (0..586)";
    what = sheet;
  } else {
    if (id < 0 || id > static_cast<int>(kTag36h11MaxId)) err = "--id must be in 0..586";
    if (err.empty() && svg.empty()) err = "need --svg FILE (PNG: QR landmarks only)";
    if (err.empty()) text = sim::tag_svg(g, static_cast<std::uint32_t>(id));
    what = svg;
  }
  if (!err.empty()) {
    std::fprintf(stderr, "agvloc-desk landmark: %s\n", err.c_str());
    return 2;
  }
  if (!write_file(what, text)) {
    std::fprintf(stderr, "agvloc-desk landmark: cannot write %s\n", what.c_str());
    return 1;
  }
  std::printf("agvloc-desk landmark: tag36h11, black square %.1f mm -> %s\n", size_mm,
              what.c_str());
  return 0;
}

}  // namespace

int landmark(int argc, char** argv) {
  CLI::App app{
      "Print landmarks: one landmark as SVG at exact physical scale and/or PNG, or a "
      "sheet of every landmark of a map (geometry: docs/design/landmark.md)",
      "agvloc-desk landmark"};
  int id = 0;
  double x_mm = 0.0, y_mm = 0.0, heading_deg = 0.0, size_mm = 60.0, mm_per_px = 0.1;
  std::string svg, png, map_path, sheet;
  bool id_only = false;
  int columns = 3;
  auto* id_opt = app.add_option("--id", id, "Landmark id 1..65535");
  app.add_option("--x-mm", x_mm, "World x of the landmark centre (mm)")->capture_default_str();
  app.add_option("--y-mm", y_mm, "World y of the landmark centre (mm)")->capture_default_str();
  app.add_option("--heading-deg", heading_deg, "Heading of the landmark's forward axis (deg)")
      ->capture_default_str();
  app.add_flag("--id-only", id_only, "Encode only the id (pose comes from the map file)");
  app.add_option("--size-mm", size_mm, "Outer border side S (mm)")
      ->check(CLI::Range(10.0, 1000.0))
      ->capture_default_str();
  app.add_option("--svg", svg, "Write SVG here (mm units; print at 100 %)");
  app.add_option("--png", png, "Write PNG here (landmark centred, black 0 / white 255)");
  app.add_option("--mm-per-px", mm_per_px, "PNG resolution")
      ->check(CLI::Range(0.005, 10.0))
      ->capture_default_str();
  auto* map_opt = app.add_option("--map", map_path, "Landmark map file: print a sheet of all");
  app.add_option("--sheet", sheet, "Sheet SVG output (with --map)");
  app.add_option("--columns", columns, "Landmarks per sheet row")
      ->check(CLI::Range(1, 100))
      ->capture_default_str();
  std::string family = "qr";
  app.add_option("--family", family,
                 "qr (QR landmark) | tag36h11 (AprilTag, id 0..586; --size-mm = black square "
                 "side, white margin of two cells)")
      ->capture_default_str();
  id_opt->excludes(map_opt);
  if (const int parse_rc = cli::parse(app, argc, argv); parse_rc >= 0) return parse_rc;
  auto usage_error = [](const std::string& msg) {
    std::fprintf(stderr, "agvloc-desk landmark: %s\n", msg.c_str());
    return 2;
  };
  const LandmarkGeometry geometry{size_mm};
  LandmarkFamily landmark_family = LandmarkFamily::kQr;
  if (!parse_landmark_family(family, &landmark_family)) {
    return usage_error("unknown --family '" + family + "' (qr or tag36h11)");
  }
  if (landmark_family == LandmarkFamily::kTag36h11) {
    return print_tags(size_mm, id_opt->count() ? id : -1, map_path, sheet, svg, columns);
  }

  if (!map_path.empty()) {
    if (sheet.empty()) return usage_error("--map needs --sheet FILE.svg");
    LandmarkMap map;
    std::string err;
    if (!config::load_map_file(map_path, &map, &err)) return usage_error(err);
    if (map.entries.empty()) return usage_error(map_path + ": no landmarks");
    const std::string text = sim::landmark_sheet_svg(geometry, map, columns);
    if (text.empty()) return usage_error("a landmark pose cannot be encoded in a payload");
    if (!write_file(sheet, text)) {
      std::fprintf(stderr, "agvloc-desk landmark: cannot write %s\n", sheet.c_str());
      return 1;
    }
    std::printf("agvloc-desk landmark: wrote %s (%zu landmarks, S = %.1f mm)\n", sheet.c_str(),
                map.entries.size(), size_mm);
    return 0;
  }

  if (id_opt->count() == 0) return usage_error("need --id N (or --map FILE --sheet OUT.svg)");
  if (svg.empty() && png.empty()) return usage_error("need --svg FILE and/or --png FILE");
  if (id < 1 || id > 65535) return usage_error("--id must be in 1..65535");
  LandmarkPayload p;
  p.id = static_cast<std::uint32_t>(id);
  p.has_pose = !id_only;
  p.x_mm = x_mm;
  p.y_mm = y_mm;
  p.heading_deg = wrap_angle_deg(heading_deg);
  const std::string payload = format_payload(p);
  if (payload.empty())
    return usage_error("pose out of the payload's range (|x|,|y| <= 999999.9 mm)");
  if (!svg.empty()) {
    const std::string text = sim::landmark_svg(geometry, payload);
    if (text.empty() || !write_file(svg, text)) {
      std::fprintf(stderr, "agvloc-desk landmark: cannot write %s\n", svg.c_str());
      return 1;
    }
  }
  if (!png.empty()) {
    const cv::Mat img = sim::render_landmark_page(geometry, payload, mm_per_px);
    if (img.empty()) return usage_error("image too large for this --mm-per-px");
    std::string err;
    if (!png::write(png, img, &err)) {
      std::fprintf(stderr, "agvloc-desk landmark: %s\n", err.c_str());
      return 1;
    }
  }
  std::printf("agvloc-desk landmark: payload %s%s%s\n", payload.c_str(),
              svg.empty() ? "" : (" -> " + svg).c_str(), png.empty() ? "" : (" -> " + png).c_str());
  return 0;
}

}  // namespace agv::desk
