// Replay outputs: CSV files with documented columns (docs/guide/replay.md). Accuracy against
// truth.csv and the trajectory plot are desk work (`agvloc-desk report`, tools/desk) over these
// files.
#pragma once

#include <string>
#include <vector>

#include "pipeline.hpp"

namespace agv::app {

bool write_poses_csv(const std::string& path, const std::vector<TickRecord>& ticks,
                     std::string* error);
bool write_fixes_csv(const std::string& path, const std::vector<FixRecord>& fixes,
                     std::string* error);
// odom.csv's columns (docs/guide/recording.md) with every digit of the doubles, so a replay of the
// file gives fusion the same samples to the bit.
bool write_odometry_csv(const std::string& path, const std::vector<recording::OdomRow>& rows,
                        std::string* error);

// The hint `agvloc replay` prints when no frame gave a landmark fix: what the frames gave and the
// usual cause, landmark.family against the printed family (a tag floor replayed with the QR family
// or the reverse finds nothing, and the run is otherwise a valid odometry-only replay, exit 0).
// family_configured: the family came from --config (else the default). Empty when a frame gave a
// fix or no frame was processed.
std::string no_fix_hint(const localizer::RunResult& r, LandmarkFamily family,
                        bool family_configured);

}  // namespace agv::app
