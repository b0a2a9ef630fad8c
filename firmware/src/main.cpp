#include <cstdio>
#include <cstring>
#include <initializer_list>

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

}  // namespace

int main(int argc, char** argv) {
  if (argc < 2) {
    usage(stderr);
    return 2;
  }
  const char* c = argv[1];
  if (!std::strcmp(c, "--version") || !std::strcmp(c, "version")) {
#ifdef AGV_HAVE_LIBCAMERA
    std::printf("agvloc %s (live camera: libcamera)\n", AGV_VERSION);
#else
    std::printf("agvloc %s (replay-only build: libcamera not found at build time)\n", AGV_VERSION);
#endif
    return 0;
  }
  if (!std::strcmp(c, "--help") || !std::strcmp(c, "-h")) {
    usage(stdout);
    return 0;
  }
  for (const char* desk : {"sim", "landmark", "report", "calibrate", "sim-board"}) {
    if (!std::strcmp(c, desk)) {
      std::fprintf(stderr,
                   "agvloc: '%s' is a desk command and not part of the vehicle binary: run "
                   "`agvloc-desk %s` (built beside agvloc, not in the .deb)\n",
                   c, c);
      return 2;
    }
  }
  if (!std::strcmp(c, "replay")) return agv::cmd::replay(argc - 1, argv + 1);
  if (!std::strcmp(c, "run")) return agv::cmd::run(argc - 1, argv + 1);
  if (!std::strcmp(c, "record")) return agv::cmd::record(argc - 1, argv + 1);
  std::fprintf(stderr, "agvloc: unknown command '%s'\n", c);
  usage(stderr);
  return 2;
}
