// A command group of agvloc-desk (`calibrate …`, `config …`): one table of subcommands gives the
// group's usage, its lines in the top-level usage and the dispatch, so no subcommand can be
// missing from the help.
#pragma once

#include <cstddef>
#include <cstdio>

namespace agv::desk {

struct Subcommand {
  const char* name;
  int (*run)(int argc, char** argv);  // argv[0] is the subcommand's name
  const char* help;
};

struct CommandGroup {
  const char* name;  // "calibrate"
  const Subcommand* subcommands;
  size_t count;
};

// "usage: agvloc-desk NAME <what> [options]" and one line per subcommand.
void print_group_usage(FILE* f, const CommandGroup& g);
// One "  NAME SUB  help" line per subcommand, for the top-level usage.
void print_group_lines(FILE* f, const CommandGroup& g);
// Runs the subcommand named by argv[1]. Returns its exit code; 0 after --help; 2 (usage on
// stderr) when argv[1] is missing or names no subcommand.
int dispatch_group(const CommandGroup& g, int argc, char** argv);

}  // namespace agv::desk
