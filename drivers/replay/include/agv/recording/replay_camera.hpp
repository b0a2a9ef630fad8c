// hal::Camera backend that plays a recording's frames.
//
// Pacing: with a clock, frame i is delivered when clock.now_ns() >= t0_ns + (t_i - t_first) /
// speed, and its t_exposure_ns is moved onto that clock (t0_ns + (t_i - t_first)/speed), so the
// rest of the loop sees live-like timestamps. Without a clock (fast replay) frames are delivered
// at once with their recorded timestamps.
#pragma once

#include <opencv2/core.hpp>

#include <atomic>
#include <string>

#include "agv/hal/camera.hpp"
#include "agv/hal/clock.hpp"
#include "agv/recording/recording.hpp"

namespace agv::recording {

class ReplayCamera final : public hal::Camera {
 public:
  // `rec` must outlive the camera. clock may be null (fast replay).
  ReplayCamera(const Recording& rec, hal::Clock* clock, std::int64_t t0_ns, double speed);

  hal::CameraStatus start() override;
  void stop() override;
  hal::CameraStatus next_frame(std::int64_t timeout_ns, hal::FrameView* frame) override;
  void release(const hal::FrameView& frame) override;
  hal::CameraStats stats() const override { return stats_; }
  const char* last_error() const override { return error_.c_str(); }

  // Frames that failed to load (corrupt or missing PNG, wrong size); they are skipped, counted
  // in stats().errors and reported through last_error().
  std::size_t index() const { return next_; }
  // Simulates a stalled camera for tests of the loop's degradation: frames with recorded time in
  // [from_ns, to_ns) are withheld (skipped without delivery).
  void set_stall(std::int64_t from_ns, std::int64_t to_ns) {
    stall_from_ns_ = from_ns;
    stall_to_ns_ = to_ns;
  }

 private:
  std::int64_t mapped_ns(std::int64_t t_rec_ns) const;

  const Recording& rec_;
  hal::Clock* clock_;
  std::int64_t t0_ns_;
  double speed_;
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
