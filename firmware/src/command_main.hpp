// The top level of a program made of subcommands (agvloc, agvloc-desk): `PROGRAM COMMAND
// [options]`, with --help / -h and --version / version.
#pragma once

#include <cstdio>
#include <initializer_list>

namespace agv::cli {

struct Command {
  const char* name;
  int (*run)(int argc, char** argv);  // argv[0] is the command's name
};

// Runs the command argv[1] names with the arguments after it. No command, or one not in the
// list: the usage on stderr, exit code 2 (an unknown one named first as "PROGRAM: unknown command
// 'X'"). --help / -h: the usage on stdout, 0; --version / version: print_version(), 0.
int command_main(const char* program, int argc, char** argv, void (*usage)(FILE*),
                 void (*print_version)(), std::initializer_list<Command> commands);

}  // namespace agv::cli
