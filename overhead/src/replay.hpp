// agvloc-overhead replay: recorded frames of the site's ceiling cameras through the tracker, as
// live but from recordings (docs/guide/overhead.md "Replay").
#pragma once

#include <string>
#include <vector>

namespace agv::overhead_app {

struct ReplayArgs {
  std::string config_path;  // empty: the defaults
  std::string site_path;
  std::vector<std::string> recordings;
  std::string out_dir;  // empty: no CSV
  bool fast = false;    // as fast as possible instead of at the recording's pace
};

// Exit code: 0 done, 2 bad input (configuration, site, recordings; the error printed), 1 an I/O
// failure while running (the broker, --out).
int run_replay(const ReplayArgs& args);

}  // namespace agv::overhead_app
