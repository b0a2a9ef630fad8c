// Replay outputs: CSV files with documented columns (docs/replay.md), accuracy against
// truth.csv, and the trajectory plot.
#pragma once

#include <string>
#include <vector>

#include "agv/common/landmark.hpp"
#include "agv/recording/recording.hpp"
#include "pipeline.hpp"

namespace agv::app {

struct ErrorStats {
  std::size_t n = 0;
  double pos_p50_mm = 0, pos_p95_mm = 0, pos_max_mm = 0;
  double head_p50_deg = 0, head_p95_deg = 0, head_max_deg = 0;
};

struct AccuracySummary {
  ErrorStats fixes;          // vision fixes (status ok) against truth at their exposure time
  ErrorStats at_landmark;    // fused pose at output ticks within 50 ms after a fused fix
  ErrorStats between;        // fused pose at ticks >= 200 ms after the last fused fix
  ErrorStats all;            // every valid tick
  ErrorStats odometry_only;  // dead reckoning from the first truth pose, every tick
  std::size_t ticks_invalid = 0;
};

// Truth interpolated at t (linear; heading along the shortest arc). False outside the range.
bool truth_at(const std::vector<recording::TruthRow>& truth, std::int64_t t_ns, Pose2* out);

AccuracySummary evaluate(const recording::Recording& rec, const std::vector<TickRecord>& ticks,
                         const std::vector<FixRecord>& fixes,
                         std::vector<Vec2>* odometry_only_track);

std::string format_accuracy(const AccuracySummary& a);

bool write_poses_csv(const std::string& path, const std::vector<TickRecord>& ticks,
                     std::string* error);
bool write_fixes_csv(const std::string& path, const std::vector<FixRecord>& fixes,
                     std::string* error);
bool write_plot(const std::string& path, const recording::Recording& rec,
                const std::vector<TickRecord>& ticks, const std::vector<Vec2>& odometry_only,
                const LandmarkMap* map, std::string* error);

}  // namespace agv::app
