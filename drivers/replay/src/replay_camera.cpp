#include "agv/recording/replay_camera.hpp"

#include <algorithm>

namespace agv::recording {

ReplayCamera::ReplayCamera(const Recording& rec, hal::Clock* clock) : rec_(rec), clock_(clock) {}

hal::CameraStatus ReplayCamera::start() {
  started_ = true;
  return hal::CameraStatus::kOk;
}

void ReplayCamera::stop() {
  started_ = false;
  prefetched_slot_ = -1;
  for (auto& h : held_) h = false;
}

hal::CameraStatus ReplayCamera::next_frame(std::int64_t timeout_ns, hal::FrameView* frame) {
  if (!started_) return hal::CameraStatus::kNotStarted;
  while (true) {
    if (prefetched_slot_ < 0) {
      if (next_ >= rec_.frames.size()) return hal::CameraStatus::kEndOfStream;
      const FrameRow& row = rec_.frames[next_];
      if (row.t_ns >= stall_from_ns_ && row.t_ns < stall_to_ns_) {  // withheld: simulated stall
        ++next_;
        continue;
      }
      int slot = -1;
      for (int i = 0; i < kSlots; ++i) {
        if (!held_[i]) {
          slot = i;
          break;
        }
      }
      if (slot < 0) {
        // Every buffer is held by the loop: like a starved live queue, this frame is lost.
        if (clock_ && row.t_ns > clock_->now_ns()) {
          clock_->sleep_until_ns(std::min(row.t_ns, clock_->now_ns() + timeout_ns));
          return hal::CameraStatus::kTimeout;
        }
        ++stats_.frames_dropped;
        ++sequence_;
        ++next_;
        continue;
      }
      // Decode before the frame is due, so the loop sees it at its time as from a live camera
      // (PNG decoding takes milliseconds; a live driver hands over a finished buffer).
      if (!load_frame(rec_, next_, &slots_[slot], &error_)) {
        ++stats_.errors;
        ++sequence_;
        ++next_;
        continue;
      }
      held_[slot] = true;
      prefetched_slot_ = slot;
    }
    const std::int64_t due_ns = rec_.frames[next_].t_ns;
    if (clock_) {
      const std::int64_t now = clock_->now_ns();
      if (due_ns > now) {
        if (due_ns - now > timeout_ns) {
          clock_->sleep_until_ns(now + timeout_ns);
          return hal::CameraStatus::kTimeout;
        }
        clock_->sleep_until_ns(due_ns);
      }
    }
    const cv::Mat& image = slots_[prefetched_slot_];
    frame->data = image.data;
    frame->width_px = image.cols;
    frame->height_px = image.rows;
    frame->stride_bytes = static_cast<int>(image.step[0]);
    frame->t_exposure_ns = due_ns;
    frame->sequence = sequence_++;
    frame->slot = prefetched_slot_;
    prefetched_slot_ = -1;
    ++next_;
    ++stats_.frames_delivered;
    return hal::CameraStatus::kOk;
  }
}

void ReplayCamera::release(const hal::FrameView& frame) {
  if (frame.slot >= 0 && frame.slot < kSlots) held_[frame.slot] = false;
}

}  // namespace agv::recording
