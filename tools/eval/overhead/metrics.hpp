// Scoring of eval_overhead: the tracker's outputs against the simulator's truth at every output
// tick, every detection against the rendered tags, the per-frame processing time.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "agv/overhead/camera_frame.hpp"
#include "agv/overhead/tracker.hpp"
#include "agv/sim/site_render.hpp"

namespace agv::eval {

double percentile(std::vector<double> v, double q);  // q in [0, 1]; NaN when empty

struct VehicleScore {
  std::vector<double> pos_err_mm, head_err_deg;
  std::uint64_t ticks = 0, valid = 0, in_view = 0, valid_in_view = 0;
  std::uint64_t confident_wrong = 0;  // valid with a position error beyond 3 sigma and 50 mm
  bool on_other = false;              // its track follows another vehicle now
};

struct Score {
  std::vector<VehicleScore> vehicles;
  // Every vehicle's ticks while a parcel hid its whole tag (the tray box alone can fix it).
  VehicleScore covered;
  // Every vehicle's ticks while its track coasts (no fix for coast_after_ms; valid by definition).
  VehicleScore coasting;
  std::uint64_t id_switches = 0, duplicates = 0;
  std::vector<std::vector<std::uint8_t>> pair_close;  // duplicate episodes in progress
  // NEES of (x, y, theta) over valid outputs; position within 3 sigma_xy.
  double nees_sum = 0.0;
  std::uint64_t nees_n = 0, nees_in95 = 0, within3 = 0;
  // Detections.
  std::uint64_t reads = 0, right_reads = 0, wrong_reads = 0, wrong_fixes = 0, phantom_reads = 0;
  std::uint64_t phantom_fixes = 0, gated = 0;
  // Tags with injected bit errors (wholly in the image) and what became of them: of vehicles
  // with a track (read on the predicted path against the area's ids) and without (only the
  // strict global decode can start a track).
  std::uint64_t flipped = 0, flipped_right = 0, flipped_wrong = 0;
  std::uint64_t flipped_untracked = 0, flipped_untracked_right = 0;
  // Per-frame processing time (ms), all frames and those that swept the whole image.
  std::vector<double> frame_ms, frame_full_ms, frame_windows_ms, apriltag_ms;
};

// One output tick: every vehicle's output against its truth (in_view: its tag lies inside some
// camera's image; covered, when not null: a parcel hides its whole tag, scored in s->covered too).
void score_tick(const std::vector<overhead::TrackOutput>& outs,
                const std::vector<sim::AgvState>& truth, const std::vector<std::uint8_t>& in_view,
                Score* s, const std::vector<std::uint8_t>* covered = nullptr);

// One frame's detections against its rendered tags (corners page order; projected: in front of
// the camera, matched against; in_image: wholly inside the image, counted for bit errors); flipped
// marks the vehicles whose tag had cells overwritten in this frame, tracked those that had a track
// (tentative, confirmed or coasting) when the frame was processed.
void score_detections(const std::vector<overhead::Detection>& dets,
                      const std::vector<std::array<Vec2, 4>>& truth_corners,
                      const std::vector<std::uint8_t>& projected,
                      const std::vector<std::uint8_t>& in_image,
                      const std::vector<std::uint8_t>& flipped,
                      const std::vector<std::uint8_t>& tracked, Score* s);

std::string report(const Score& s, const std::vector<std::string>& ids);

}  // namespace agv::eval
