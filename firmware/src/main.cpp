#include <cstdio>

#include "command_main.hpp"
#include "commands.hpp"

namespace {

void usage(FILE* f) {
  std::fprintf(f,
               "usage: agvloc <command> [options]\n"
               "  replay RECORDING   run the localizer on a recording (frames + odometry)\n"
               "  run --config FILE  live: camera, vision, fusion, CAN output\n"
               "  record --config FILE --out DIR   record the live camera and CAN odometry\n"
               "  --version          version and build features\n"
               "Each command takes --help. Desk tools (sim, landmark, report, calibrate) are in "
               "agvloc-desk.\n");
}

// The desk commands are not in the vehicle binary: say where they are.
int desk_command(int, char** argv) {
  std::fprintf(stderr,
               "agvloc: '%s' is a desk command and not part of the vehicle binary: run "
               "`agvloc-desk %s` (built beside agvloc, not in the .deb)\n",
               argv[0], argv[0]);
  return 2;
}

void print_version() {
#ifdef AGV_HAVE_LIBCAMERA
  std::printf("agvloc %s (live camera: libcamera)\n", AGV_VERSION);
#else
  std::printf("agvloc %s (replay-only build: libcamera not found at build time)\n", AGV_VERSION);
#endif
}

}  // namespace

int main(int argc, char** argv) {
  return agv::cli::command_main("agvloc", argc, argv, usage, print_version,
                                {{"sim", desk_command},
                                 {"landmark", desk_command},
                                 {"report", desk_command},
                                 {"calibrate", desk_command},
                                 {"sim-board", desk_command},
                                 {"replay", agv::cmd::replay},
                                 {"run", agv::cmd::run},
                                 {"record", agv::cmd::record}});
}
