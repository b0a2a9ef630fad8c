// Subcommands of the vehicle binary agvloc (desk tools: tools/desk, agvloc-desk). Each returns
// the process exit code: 0 success, 1 runtime failure (message on stderr), 2 usage or
// configuration error.
#pragma once

namespace agv::cmd {

int replay(int argc, char** argv);  // run the pipeline on a recording
int run(int argc, char** argv);     // live: camera + CAN
int record(int argc, char** argv);  // live camera + CAN odometry -> recording

}  // namespace agv::cmd
