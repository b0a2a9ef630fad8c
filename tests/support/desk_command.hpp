// Runs one of agvloc-desk's command entry points in the test process, with `args` as its command
// line after the command's name (argv[0]), as main() would hand them over.
#pragma once

#include <string>
#include <vector>

namespace agv::testsupport {

inline int run_command(int (*command)(int, char**), const std::string& name,
                       std::vector<std::string> args) {
  args.insert(args.begin(), name);
  std::vector<char*> argv;
  for (std::string& a : args) argv.push_back(a.data());
  return command(static_cast<int>(argv.size()), argv.data());
}

}  // namespace agv::testsupport
