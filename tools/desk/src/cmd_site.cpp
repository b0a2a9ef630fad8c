// agvloc-desk site: check a site file (docs/guide/site.md) and draw it.
//   site check SITE                      every error, one per line, or a one-line summary
//   site draw SITE --out F.svg [--png F.png --px-per-m N]
#include <CLI/CLI.hpp>
#include <cstdio>
#include <fstream>
#include <iterator>
#include <opencv2/core.hpp>
#include <optional>

#include "agv/recording/png_io.hpp"
#include "agv/site/site_file.hpp"
#include "cli_parse.hpp"
#include "commands.hpp"
#include "site_io.hpp"
#include "site_svg.hpp"
#include "subcommands.hpp"

namespace agv::desk {

namespace site_cmd {
namespace {

// Parses the command line and loads the site file `path` (bound to an option of `app`): the
// command's exit code when either fails (0 after --help), nothing when both succeed.
std::optional<int> parse_and_load(CLI::App& app, int argc, char** argv, const std::string& path,
                                  agv::site::Site* site) {
  if (const int parse_rc = cli::parse(app, argc, argv); parse_rc >= 0) return parse_rc;
  std::string errors;
  if (!load_site(path, site, &errors)) {
    std::fputs(errors.c_str(), stderr);
    return 2;
  }
  return std::nullopt;
}

int check(int argc, char** argv) {
  CLI::App app{
      "Check a site file: every key, range and geometric rule of docs/guide/site.md. "
      "Prints each error (key path and line) and exits 2, or prints a summary",
      "agvloc-desk site check"};
  std::string path;
  app.add_option("site", path, "The site file (site.yaml)")->required();
  agv::site::Site site;
  if (const std::optional<int> rc = parse_and_load(app, argc, argv, path, &site)) return *rc;
  for (const std::string& w : agv::site::site_warnings(site)) {
    std::printf("warning: %s: %s\n", path.c_str(), w.c_str());
  }
  std::printf(
      "site OK: %zu obstacles, %zu wall landmarks, %zu cameras, %zu AGVs, floor map %zu "
      "landmarks\n",
      site.obstacles.size(), site.wall_landmarks.size(), site.cameras.size(), site.fleet.size(),
      site.floor_map.entries.size());
  return 0;
}

int draw(int argc, char** argv) {
  CLI::App app{
      "Draw a site: outline, obstacles by kind, floor and wall landmarks, the floor "
      "each ceiling camera sees, the fleet",
      "agvloc-desk site draw"};
  std::string path, svg_path, png_path;
  double px_per_m = kSiteDrawDefaultPxPerM;
  app.add_option("site", path, "The site file (site.yaml)")->required();
  app.add_option("--out", svg_path, "Write the SVG here")->required();
  app.add_option("--png", png_path, "Also write a PNG of the same drawing here");
  app.add_option("--px-per-m", px_per_m, "Pixels per metre of the site")
      ->check(CLI::Range(1.0, 1000.0))
      ->capture_default_str();
  agv::site::Site site;
  if (const std::optional<int> rc = parse_and_load(app, argc, argv, path, &site)) return *rc;
  cv::Mat png;
  if (!png_path.empty()) {
    std::string err;
    if (!site_png(site, {}, {}, px_per_m, &png, &err)) {
      std::fprintf(stderr, "agvloc-desk site draw: %s\n", err.c_str());
      return 2;
    }
  }
  {
    std::ofstream f(svg_path, std::ios::binary | std::ios::trunc);
    f << site_svg(site, {}, {}, px_per_m);
    if (!f) {
      std::fprintf(stderr, "agvloc-desk site draw: cannot write %s\n", svg_path.c_str());
      return 1;
    }
  }
  if (!png_path.empty()) {
    std::string err;
    if (!png::write(png_path, png, &err)) {
      std::fprintf(stderr, "agvloc-desk site draw: %s\n", err.c_str());
      return 1;
    }
  }
  std::printf("agvloc-desk site draw: %s -> %s%s\n", path.c_str(), svg_path.c_str(),
              png_path.empty() ? "" : (", " + png_path).c_str());
  return 0;
}

const Subcommand kSiteSubcommands[] = {
    {"check", check, "check a site file (SITE); errors name the key and line, exit 2"},
    {"draw", draw, "draw a site (SITE --out F.svg [--png F.png --px-per-m N])"},
};
const CommandGroup kSite{"site", kSiteSubcommands, std::size(kSiteSubcommands)};

}  // namespace
}  // namespace site_cmd

int site_command(int argc, char** argv) { return dispatch_group(site_cmd::kSite, argc, argv); }

}  // namespace agv::desk
