// agvloc-desk: the tools for the desk (simulator, landmark printing, replay reports). Kept out
// of the vehicle binary `agvloc` so that the real-time program links none of their code.
#include <cstdio>
#include <cstring>

#include "commands.hpp"

namespace {

void usage(FILE* f) {
  std::fprintf(f,
               "usage: agvloc-desk <command> [options]\n"
               "  sim --out DIR      write a simulated recording\n"
               "  landmark           print landmarks (SVG at physical scale, PNG)\n"
               "  report OUT --recording REC   accuracy against truth + trajectory.svg of a "
               "replay\n"
               "  sim-board --out DIR   simulated calibration-board views (tests)\n"
               "  site check|draw SITE  validate a site file; draw it as SVG/PNG\n"
               "  plan --site S --from X,Y --to X,Y   route around the site's obstacles\n"
               "  fleet --site S --out DIR   simulate a fleet driving tasks on a site\n"
               "  render-site --site S --out DIR   render any camera of a site (ceiling, rack)\n");
  agv::desk::print_calibrate_subcommands(f);
  agv::desk::print_config_subcommands(f);
  std::fprintf(f,
               "  --version          version\n"
               "Each command takes --help. The vehicle commands (run, replay, record) are in "
               "agvloc.\n");
}

}  // namespace

int main(int argc, char** argv) {
  if (argc < 2) {
    usage(stderr);
    return 2;
  }
  const char* c = argv[1];
  if (!std::strcmp(c, "--version") || !std::strcmp(c, "version")) {
    std::printf("agvloc-desk %s\n", AGV_VERSION);
    return 0;
  }
  if (!std::strcmp(c, "--help") || !std::strcmp(c, "-h")) {
    usage(stdout);
    return 0;
  }
  if (!std::strcmp(c, "sim")) return agv::desk::sim(argc - 1, argv + 1);
  if (!std::strcmp(c, "landmark")) return agv::desk::landmark(argc - 1, argv + 1);
  if (!std::strcmp(c, "report")) return agv::desk::report(argc - 1, argv + 1);
  if (!std::strcmp(c, "calibrate")) return agv::desk::calibrate(argc - 1, argv + 1);
  if (!std::strcmp(c, "sim-board")) return agv::desk::sim_board(argc - 1, argv + 1);
  if (!std::strcmp(c, "config")) return agv::desk::config_command(argc - 1, argv + 1);
  if (!std::strcmp(c, "site")) return agv::desk::site_command(argc - 1, argv + 1);
  if (!std::strcmp(c, "plan")) return agv::desk::plan_command(argc - 1, argv + 1);
  if (!std::strcmp(c, "fleet")) return agv::desk::fleet_command(argc - 1, argv + 1);
  if (!std::strcmp(c, "render-site")) return agv::desk::render_site_command(argc - 1, argv + 1);
  std::fprintf(stderr, "agvloc-desk: unknown command '%s'\n", c);
  usage(stderr);
  return 2;
}
