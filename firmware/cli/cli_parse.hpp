// The command line convention of agvloc, agvloc-desk and agvloc-overhead: --help and --version exit
// 0, any parse error exits 2 after CLI11 has printed it.
#pragma once

#include <CLI/CLI.hpp>

namespace agv::cli {

// Parses argv into app's options; -1 to go on, else the exit code.
inline int parse(CLI::App& app, int argc, char** argv) {
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return app.exit(e) == 0 ? 0 : 2;
  }
  return -1;
}

}  // namespace agv::cli
