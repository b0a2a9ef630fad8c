// agvloc-overhead run: the live service (docs/guide/overhead.md "Running live").
#pragma once

#include <string>

namespace agv::overhead_app {

struct RunArgs {
  std::string config_path;  // required: the cameras' devices are configured there
  std::string site_path;
  std::string out_dir;      // empty: no CSV
  double duration_s = 0.0;  // 0: until SIGINT / SIGTERM
};

// Exit code: 0 stopped, 2 bad input (configuration, site, no camera), 1 an I/O failure.
int run_live_command(const RunArgs& args);

}  // namespace agv::overhead_app
