// Replay outputs: CSV files with documented columns (docs/replay.md). Accuracy against truth.csv
// and the trajectory plot are desk work (`agvloc-desk report`, tools/desk) over these files.
#pragma once

#include <string>
#include <vector>

#include "pipeline.hpp"

namespace agv::app {

bool write_poses_csv(const std::string& path, const std::vector<TickRecord>& ticks,
                     std::string* error);
bool write_fixes_csv(const std::string& path, const std::vector<FixRecord>& fixes,
                     std::string* error);
// odom.csv's columns (docs/recording.md) with every digit of the doubles, so a replay of the
// file gives fusion the same samples to the bit.
bool write_odometry_csv(const std::string& path, const std::vector<recording::OdomRow>& rows,
                        std::string* error);

}  // namespace agv::app
