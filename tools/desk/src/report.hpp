// `agvloc-desk report`: accuracy of a replay against the recording's truth.csv and the
// trajectory plot, computed from the replay's output files (poses.csv, fixes.csv,
// docs/guide/replay.md) so that the vehicle binary carries neither.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "agv/common/geometry.hpp"
#include "agv/common/landmark.hpp"
#include "agv/recording/recording.hpp"

namespace agv::desk {

// One poses.csv row, the columns the report uses.
struct PoseRow {
  std::int64_t t_ns = 0;
  bool valid = false;
  Pose2 pose;
  std::int64_t time_since_fix_ns = -1;  // -1: no fix yet
  int health = 0;                       // 0 uninitialised, 1 localized, 2 dead reckoning, 3 lost
  double sigma_x_mm = 0.0, sigma_y_mm = 0.0, sigma_theta_rad = 0.0;
};

// One fixes.csv row with status ok (other rows carry no pose).
struct FixRow {
  std::int64_t t_exposure_ns = 0;
  Pose2 vehicle_in_world;
};

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

// poses.csv / fixes.csv as written by `agvloc replay`; false with *error on a malformed file.
bool read_poses_csv(const std::string& path, std::vector<PoseRow>* out, std::string* error);
bool read_fixes_csv(const std::string& path, std::vector<FixRow>* out, std::string* error);

// Truth interpolated at t (linear; heading along the shortest arc). False outside the range.
bool truth_at(const std::vector<recording::TruthRow>& truth, std::int64_t t_ns, Pose2* out);

AccuracySummary evaluate(const recording::Recording& rec, const std::vector<PoseRow>& ticks,
                         const std::vector<FixRow>& fixes, std::vector<Vec2>* odometry_only_track);

std::string format_accuracy(const AccuracySummary& a);

bool write_plot(const std::string& path, const recording::Recording& rec,
                const std::vector<PoseRow>& ticks, const std::vector<Vec2>& odometry_only,
                const LandmarkMap* map, std::string* error);

}  // namespace agv::desk
