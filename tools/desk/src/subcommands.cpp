#include "subcommands.hpp"

#include <cstring>

namespace agv::desk {

void print_group_usage(FILE* f, const CommandGroup& g) {
  std::fprintf(f, "usage: agvloc-desk %s <what> [options]\n", g.name);
  for (size_t i = 0; i < g.count; ++i) {
    std::fprintf(f, "  %-12s %s\n", g.subcommands[i].name, g.subcommands[i].help);
  }
  std::fprintf(f, "Each takes --help.\n");
}

void print_group_lines(FILE* f, const CommandGroup& g) {
  // The subcommand column lines up with the top-level commands' help (column 24).
  const int width = 20 - static_cast<int>(std::strlen(g.name));
  for (size_t i = 0; i < g.count; ++i) {
    std::fprintf(f, "  %s %-*s %s\n", g.name, width, g.subcommands[i].name, g.subcommands[i].help);
  }
}

int dispatch_group(const CommandGroup& g, int argc, char** argv) {
  if (argc < 2) {
    print_group_usage(stderr, g);
    return 2;
  }
  if (!std::strcmp(argv[1], "--help") || !std::strcmp(argv[1], "-h")) {
    print_group_usage(stdout, g);
    return 0;
  }
  for (size_t i = 0; i < g.count; ++i) {
    if (!std::strcmp(argv[1], g.subcommands[i].name)) {
      return g.subcommands[i].run(argc - 1, argv + 1);
    }
  }
  std::fprintf(stderr, "agvloc-desk %s: unknown subcommand '%s'\n", g.name, argv[1]);
  print_group_usage(stderr, g);
  return 2;
}

}  // namespace agv::desk
