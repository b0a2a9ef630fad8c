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
// likely cause, named from what the frames say (the run is otherwise a valid odometry-only replay,
// exit 0): the family (nothing found, or QR borders without a code: a tag floor read as QR), the
// camera height or print size (tags whose fitted square is off landmark.size_mm: the scale of the
// metric frame is the configured height's), or the map (landmarks read but not in it).
struct NoFixContext {
  LandmarkFamily family = LandmarkFamily::kQr;
  // Where the family came from: "--config", "meta.yaml", or empty (the default).
  std::string family_source;
  bool have_map = false;
  double height_mm = 0.0;  // mounting.height_mm as replayed
  double size_mm = 0.0;    // landmark.size_mm as replayed
};
// Empty when a frame gave a fix or no frame was processed.
std::string no_fix_hint(const localizer::RunResult& r, const std::vector<FixRecord>& fixes,
                        const NoFixContext& c);

}  // namespace agv::app
