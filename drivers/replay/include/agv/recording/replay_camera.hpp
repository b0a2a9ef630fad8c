// hal::Camera backend that plays a recording's frames.
//
// Pacing: with a clock, frame i is delivered once clock.now_ns() >= t_i, so the clock must run in
// recording time (agvloc replay --realtime uses a ScaledClock for that). Without a clock frames
// are delivered at once. Either way t_exposure_ns is the recorded time.
#pragma once

#include <atomic>
#include <opencv2/core.hpp>
#include <string>

#include "agv/hal/camera.hpp"
#include "agv/hal/clock.hpp"
#include "agv/recording/recording.hpp"

namespace agv::recording {

class ReplayCamera final : public hal::Camera {
 public:
  // `rec` must outlive the camera. clock may be null (fast replay).
  ReplayCamera(const Recording& rec, hal::Clock* clock);

  hal::CameraStatus start() override;
  void stop() override;
  hal::CameraStatus next_frame(std::int64_t timeout_ns, hal::FrameView* frame) override;
  void release(const hal::FrameView& frame) override;
  hal::CameraStats stats() const override { return stats_; }
  const char* last_error() const override { return error_.c_str(); }

  // Frames that fail to load (corrupt or missing PNG, wrong size) are skipped, counted in
  // stats().errors and reported through last_error().
  //
  // Simulates a stalled camera for tests of the loop's degradation: frames with recorded time in
  // [from_ns, to_ns) are withheld (skipped without delivery).
  void set_stall(std::int64_t from_ns, std::int64_t to_ns) {
    stall_from_ns_ = from_ns;
    stall_to_ns_ = to_ns;
  }

 private:
  const Recording& rec_;
  hal::Clock* clock_;
  bool started_ = false;
  // Like a live driver, a few buffers can be held by the loop at once (capture mailbox + vision
  // worker); a frame arriving while all are held is dropped and counted.
  static constexpr int kSlots = 3;
  cv::Mat slots_[kSlots];
  std::atomic<bool> held_[kSlots] = {false, false, false};  // released from another thread
  std::size_t next_ = 0;
  int prefetched_slot_ = -1;  // decoded, waiting for its time
  std::uint64_t sequence_ = 0;
  std::int64_t stall_from_ns_ = 0, stall_to_ns_ = 0;
  hal::CameraStats stats_;
  std::string error_;
};

}  // namespace agv::recording
