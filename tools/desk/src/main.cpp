// agvloc-desk: the tools for the desk (simulator, landmark printing, replay reports). Kept out
// of the vehicle binary `agvloc` so that the real-time program links none of their code.
#include <cstdio>

#include "command_main.hpp"
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

void print_version() { std::printf("agvloc-desk %s\n", AGV_VERSION); }

}  // namespace

int main(int argc, char** argv) {
  return agv::cli::command_main("agvloc-desk", argc, argv, usage, print_version,
                                {{"sim", agv::desk::sim},
                                 {"landmark", agv::desk::landmark},
                                 {"report", agv::desk::report},
                                 {"calibrate", agv::desk::calibrate},
                                 {"sim-board", agv::desk::sim_board},
                                 {"config", agv::desk::config_command},
                                 {"site", agv::desk::site_command},
                                 {"plan", agv::desk::plan_command},
                                 {"fleet", agv::desk::fleet_command},
                                 {"render-site", agv::desk::render_site_command}});
}
