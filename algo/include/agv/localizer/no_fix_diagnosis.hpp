// Why a run of frames gave no landmark fix, named from what the frames gave ("a message that
// names the likely cause when nothing is found"). One diagnosis for `agvloc replay` and
// `agvloc-desk calibrate vehicle`: the family (nothing of it read, or QR borders without a code: a
// tag floor read as QR), the camera height or print size (tags found, their fitted square off
// landmark.size_mm: the metric frame's scale is the configured height's), or the map (landmarks
// read but not in it). Pure: the callers print it.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "agv/common/landmark.hpp"
#include "agv/localizer/run_statistics.hpp"
#include "agv/vision/landmark_localizer.hpp"

namespace agv::localizer {

// What one frame without a fix gave, as far as the diagnosis needs it (from its LandmarkFix).
struct FrameOutcome {
  vision::FixStatus status = vision::FixStatus::kNoLandmark;
  std::uint32_t landmark_id = 0;
  double outer_half_mm = 0.0;  // the fitted outer half side, 0 when not measured
};
FrameOutcome frame_outcome(const vision::LandmarkFix& fix);

struct NoFixContext {
  LandmarkFamily family = LandmarkFamily::kQr;
  // Where the family came from: "--config", "meta.yaml", or empty (the default).
  std::string family_source;
  bool have_map = false;
  double height_mm = 0.0;  // mounting.height_mm the frames were processed with
  double size_mm = 0.0;    // landmark.size_mm the frames were processed with
  // The frames are a calibration drive: a height too far off is set by hand before calibrating
  // (calibrate vehicle cannot measure it from frames that give no fix).
  bool calibrating = false;
};

enum class NoFixCause { kNone, kMap, kScale, kFamily, kUnclear };

struct NoFixDiagnosis {
  NoFixCause cause = NoFixCause::kNone;
  std::string statuses;  // "3 no landmark, 2 unknown landmark": every non-zero count
  std::string text;      // the likely cause and what to check; no trailing newline
};

// kNone (empty texts) when no frame was processed or a frame gave a fix: the counts are the run's
// per status (frames_processed their sum or more), `frames` what the frames without a fix gave
// (may be fewer than counted: a full record drops some).
NoFixDiagnosis diagnose_no_fix(std::uint64_t frames_processed,
                               const std::uint64_t (&by_status)[kFixStatusCount],
                               const std::vector<FrameOutcome>& frames, const NoFixContext& c);

}  // namespace agv::localizer
