// The diagnostics page alone (no loop, no camera), for the hostile-client test (diag_hostile.py):
// prints the port, serves until its standard input closes, prints the page's counters.
#include <cstdio>
#include <string>

#include "diag_handoff.hpp"
#include "diag_server.hpp"

int main() {
  agv::config::Config cfg;
  cfg.diag.port = 0;
  agv::app::DiagHandoff handoff;
  agv::app::FrameTap frames;
  agv::app::DiagServer server(cfg, nullptr, handoff, frames, "test");
  std::string error;
  if (!server.start(&error)) {
    std::fprintf(stderr, "%s\n", error.c_str());
    return 77;  // built without the page
  }
  std::printf("port %d\n", server.port());
  std::fflush(stdout);
  while (std::getchar() != EOF) {
  }
  server.stop();
  std::fputs(agv::app::format_diag_counters(server.stats()).c_str(), stdout);
  return 0;
}
