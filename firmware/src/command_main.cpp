#include "command_main.hpp"

#include <cstring>

namespace agv::cli {

int command_main(const char* program, int argc, char** argv, void (*usage)(FILE*),
                 void (*print_version)(), std::initializer_list<Command> commands) {
  if (argc < 2) {
    usage(stderr);
    return 2;
  }
  const char* c = argv[1];
  if (!std::strcmp(c, "--version") || !std::strcmp(c, "version")) {
    print_version();
    return 0;
  }
  if (!std::strcmp(c, "--help") || !std::strcmp(c, "-h")) {
    usage(stdout);
    return 0;
  }
  for (const Command& command : commands) {
    if (!std::strcmp(c, command.name)) return command.run(argc - 1, argv + 1);
  }
  std::fprintf(stderr, "%s: unknown command '%s'\n", program, c);
  usage(stderr);
  return 2;
}

}  // namespace agv::cli
