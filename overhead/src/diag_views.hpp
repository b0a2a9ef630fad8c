// The diagnostics page's pictures (docs/guide/overhead.md "Diagnostics page and metrics"): each
// ceiling camera's newest view with its detections and the tracks' search windows drawn
// (/camera/<index>.png), and the site map with the fleet (/site.svg). The tracker hands a frame
// over through a LatestSlot (drivers/http, the vehicle's frame hand-off) only when the page asked
// for that camera and at most every kMinCopyIntervalNs of exposure time; it never waits for the
// slot. Downscaling, drawing and PNG encoding happen on the HTTP threads.
#pragma once

#include <array>
#include <atomic>
#include <cstddef>
#include <cstdint>
#include <opencv2/core.hpp>
#include <string>
#include <vector>

#include "agv/http/latest_slot.hpp"
#include "agv/overhead/camera_frame.hpp"
#include "agv/overhead/search.hpp"
#include "agv/overhead/tracker.hpp"
#include "agv/site/site.hpp"

namespace agv::overhead_app {

// A track as its camera expects it: the window its tag is searched in and the predicted corners.
struct TrackMark {
  std::size_t agv = 0;
  overhead::TrackState state = overhead::TrackState::kNone;
  cv::Rect window;                             // full-resolution pixels
  std::array<Vec2, 4> predicted_corners_px{};  // page order, distorted pixels
};

// One camera's frame with what the tracker made of it.
struct CameraView {
  std::int64_t t_ns = 0;                        // exposure
  cv::Mat gray;                                 // the full frame, 8-bit
  std::vector<overhead::Detection> detections;  // this frame's, this camera's
  std::vector<TrackMark> tracks;
};

// The view of site camera `camera` after its frame exposed at t_ns was processed: the frame, the
// detections of that camera among `detections`, and a track window per vehicle with a track in
// view, planned from the tracker's state at t_ns as the search plans the next frame's (a window
// that missed is not shown as the area it falls back to).
void fill_camera_view(const site::Site& site, std::size_t camera,
                      const overhead::FleetTracker& tracker,
                      const std::vector<overhead::Detection>& detections,
                      const overhead::SearchParams& search, std::int64_t t_ns, const cv::Mat& gray,
                      CameraView* out);

// The view drawn in colour, downscaled (area averaging, aspect kept) to width_px when the frame
// is wider: each detection's corners and tag id (green: a fix applied or a track started; orange:
// gated, too old or invalid; red: a tag not in the fleet), each track's window (blue) and
// predicted tag with the vehicle's id and state. agv_ids[i] names fleet vehicle i. Empty for an
// empty frame.
cv::Mat draw_camera_view(const CameraView& v, const std::vector<std::string>& agv_ids,
                         int width_px);

// One camera's hand-off from the tracker to the page.
class CameraViewTap {
 public:
  // Copies closer together than this (exposure time) are not made, however often the page asks.
  static constexpr std::int64_t kMinCopyIntervalNs = 200'000'000;

  // Tracker side, never waits: whether the frame exposed at t_ns is to be handed over.
  bool due(std::int64_t t_ns) const {
    return wanted_.load(std::memory_order_acquire) &&
           (last_copy_ns_ == INT64_MIN || t_ns < last_copy_ns_ ||
            t_ns - last_copy_ns_ >= kMinCopyIntervalNs);
  }
  // Tracker side: fill(CameraView&) into the slot unless an HTTP thread holds it (skipped; the
  // next due frame retries). Waits for nothing.
  template <typename Fill>
  void offer(std::int64_t t_ns, Fill&& fill) {
    slot_.try_write([&](CameraView& v) {
      fill(v);
      last_copy_ns_ = t_ns;
      wanted_.store(false, std::memory_order_relaxed);
    });
  }
  // Any side, waiting for the slot (tests, a finished run).
  void put(CameraView v) {
    slot_.write([&](CameraView& s) { s = std::move(v); });
  }

  // Server side.
  void request() { wanted_.store(true, std::memory_order_release); }
  std::uint64_t seq() const { return slot_.seq(); }
  template <typename Use>
  decltype(auto) read(Use&& use) {
    return slot_.read(use);
  }

 private:
  std::atomic<bool> wanted_{false};
  std::int64_t last_copy_ns_ = INT64_MIN;  // tracker side only
  app::LatestSlot<CameraView> slot_;
};

}  // namespace agv::overhead_app
