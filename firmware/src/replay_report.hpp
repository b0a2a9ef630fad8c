// Replay outputs: CSV files with documented columns (docs/guide/replay.md). Accuracy against
// truth.csv and the trajectory plot are desk work (`agvloc-desk report`, tools/desk) over these
// files.
#pragma once

#include <string>
#include <vector>

#include "agv/localizer/no_fix_diagnosis.hpp"
#include "pipeline.hpp"

namespace agv::app {

bool write_poses_csv(const std::string& path, const std::vector<TickRecord>& ticks,
                     std::string* error);
bool write_fixes_csv(const std::string& path, const std::vector<FrameRecord>& fixes,
                     std::string* error);
// odom.csv's columns (docs/guide/recording.md) with every digit of the doubles, so a replay of the
// file gives fusion the same samples to the bit.
bool write_odometry_csv(const std::string& path, const std::vector<recording::OdomRow>& rows,
                        std::string* error);

// The hint `agvloc replay` prints when no frame gave a landmark fix: what the frames gave and the
// likely cause (localizer/no_fix_diagnosis.hpp; the run is otherwise a valid odometry-only replay,
// exit 0).
using NoFixContext = localizer::NoFixContext;
// Empty when a frame gave a fix or no frame was processed.
std::string no_fix_hint(const localizer::RunResult& r, const std::vector<FrameRecord>& fixes,
                        const NoFixContext& c);

}  // namespace agv::app
