// Subcommands of the agvloc binary. Each returns the process exit code:
// 0 success, 1 runtime failure (message on stderr), 2 usage or configuration error.
#pragma once

#include <string>

namespace agv {
struct LandmarkMap;
}

namespace agv::cmd {

int landmark(int argc, char** argv);  // print landmarks as SVG/PNG
int sim(int argc, char** argv);       // write a simulated recording
int replay(int argc, char** argv);    // run the pipeline on a recording
int run(int argc, char** argv);       // live: camera + CAN
int record(int argc, char** argv);    // live camera + CAN odometry -> recording

// Reads a landmark map file (docs/landmark.md); false with *error naming file and line.
bool load_map_file(const std::string& path, LandmarkMap* map, std::string* error);

}  // namespace agv::cmd
