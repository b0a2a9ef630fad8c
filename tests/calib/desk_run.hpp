// Runs agvloc-desk (AGVLOC_DESK, set by tests/calib/CMakeLists.txt) and collects its exit code
// and output, for the command-line tests.
#pragma once

#include <sys/wait.h>

#include <cstdio>
#include <string>

namespace agv::test {

struct DeskOut {
  int code = -1;     // -1: did not exit normally
  std::string text;  // stdout + stderr
};

// timeout_s > 0: killed after that long (exit code 124), so a hang fails the test instead of
// blocking the suite.
inline DeskOut run_desk(const std::string& args, int timeout_s = 0) {
  const std::string cmd = (timeout_s > 0 ? "timeout " + std::to_string(timeout_s) + " " : "") +
                          std::string(AGVLOC_DESK) + " " + args + " 2>&1";
  DeskOut o;
  FILE* p = popen(cmd.c_str(), "r");
  if (!p) return o;
  char buf[4096];
  size_t n;
  while ((n = fread(buf, 1, sizeof buf, p)) > 0) o.text.append(buf, n);
  const int status = pclose(p);
  o.code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  return o;
}

}  // namespace agv::test
