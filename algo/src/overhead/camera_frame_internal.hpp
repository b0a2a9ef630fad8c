// CameraFrameProcessor's per-call state, shared by its source files (camera_frame*.cpp).
#pragma once

#include <cstdint>
#include <opencv2/core/types.hpp>
#include <unordered_set>
#include <utility>
#include <vector>

#include "agv/overhead/camera_frame.hpp"

namespace agv::overhead {

// State of one call, so that the steps below stay short.
struct CameraFrameProcessor::FrameWork {
  std::size_t camera = 0;
  std::int64_t t_ns = 0;
  FleetTracker* tracker = nullptr;
  std::vector<Detection>* out = nullptr;
  std::unordered_set<std::uint32_t> ids_seen;  // tags handled this frame (any window)
  std::vector<std::uint8_t> found;             // per vehicle: its tag was read this frame
  std::vector<std::uint8_t> looked_for;        // per vehicle: a window expected it
  std::vector<std::uint8_t> tray_applied;      // per vehicle: a tray box of it was applied
  std::vector<Pose2> tag_pose;                 // per vehicle found: its tag's fix (if any)
  std::vector<std::uint8_t> has_tag_pose;
  // Regions searched this frame, with their decimation: a later window inside one at the same
  // or a finer decimation would find nothing new.
  std::vector<std::pair<cv::Rect, int>> searched;
};

}  // namespace agv::overhead
