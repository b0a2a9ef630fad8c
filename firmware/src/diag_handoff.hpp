// Hand-off between the real-time threads and the diagnostics server (docs/guide/diagnostics.md),
// shaped like the MQTT one (mqtt_handoff.hpp): the loop side never blocks and never allocates.
// The output loop records fixes and trajectory points into fixed rings it alone owns, and at the
// hand-off rate (loop time) copies them with the tick and the statistics into a slot it only
// try-locks; a busy slot skips that hand-off (counted), the next one retries. The vision worker
// offers frames to a FrameTap the same way; it copies one only when the server asked for it (or
// rarely, so a finished replay still has a recent frame).
#pragma once

#include <atomic>
#include <cstdint>
#include <mutex>
#include <opencv2/core.hpp>

#include "agv/diag/diag.hpp"
#include "agv/hal/can_bus.hpp"

namespace agv::app {

class DiagHandoff {
 public:
  // 10 Hz: the page polls at 2 Hz; the trajectory gets a point per hand-off.
  static constexpr std::int64_t kDefaultPeriodNs = 100'000'000;

  // Loop side.
  void record_fix(const vision::LandmarkMeasurement& fix, std::int64_t t_exposure_ns,
                  std::int64_t t_arrival_ns) {
    fixes_.push(diag::fix_entry(fix, t_exposure_ns, t_arrival_ns));
  }
  void offer(const localizer::TickRecord& tick, const localizer::OutputStats& stats,
             const hal::CanBus* bus, std::uint64_t frames_dropped) {
    if (next_due_ns_ != INT64_MIN && tick.t_ns < next_due_ns_) return;
    next_due_ns_ = (next_due_ns_ == INT64_MIN ? tick.t_ns : next_due_ns_) + period_ns_;
    if (next_due_ns_ <= tick.t_ns) next_due_ns_ = tick.t_ns + period_ns_;  // after a gap
    track_.push(diag::track_point(tick));
    std::unique_lock<std::mutex> lock(slot_mutex_, std::try_to_lock);
    if (!lock.owns_lock()) {
      busy_skips_.fetch_add(1, std::memory_order_relaxed);
      return;
    }
    fill(tick, stats, bus, frames_dropped);
  }
  // The run is over: its final state, waited for (the loop has stopped; nothing real-time left).
  void finish(const localizer::TickRecord* tick, const localizer::OutputStats& stats,
              const hal::CanBus* bus, std::uint64_t frames_dropped) {
    std::lock_guard<std::mutex> lock(slot_mutex_);
    if (tick) {
      track_.push(diag::track_point(*tick));
      fill(*tick, stats, bus, frames_dropped);
    } else {
      slot_.stats = stats;
      seq_.fetch_add(1, std::memory_order_release);
    }
    slot_.finished = true;
    finished_.store(true, std::memory_order_release);
  }

  // Server side: copies the newest snapshot into *out when it is newer than *seq.
  bool take(diag::Snapshot* out, std::uint64_t* seq) {
    if (seq_.load(std::memory_order_acquire) == *seq) return false;
    std::lock_guard<std::mutex> lock(slot_mutex_);
    *out = slot_;
    *seq = seq_.load(std::memory_order_relaxed);
    return true;
  }
  bool finished() const { return finished_.load(std::memory_order_acquire); }
  std::uint64_t busy_skips() const { return busy_skips_.load(std::memory_order_relaxed); }

 private:
  void fill(const localizer::TickRecord& tick, const localizer::OutputStats& stats,
            const hal::CanBus* bus, std::uint64_t frames_dropped) {
    slot_.has_tick = true;
    slot_.tick = tick;
    slot_.stats = stats;
    slot_.can_present = bus != nullptr;
    if (bus) slot_.can = bus->stats();
    slot_.frames_dropped = frames_dropped;
    slot_.fixes = fixes_;
    slot_.track = track_;
    seq_.fetch_add(1, std::memory_order_release);
  }

  std::int64_t period_ns_ = kDefaultPeriodNs;
  std::int64_t next_due_ns_ = INT64_MIN;                    // loop thread only
  diag::Ring<diag::FixEntry, diag::kLastFixes> fixes_;      // loop thread only
  diag::Ring<diag::TrackPoint, diag::kTrackPoints> track_;  // loop thread only
  std::mutex slot_mutex_;
  diag::Snapshot slot_;
  std::atomic<std::uint64_t> seq_{0};
  std::atomic<bool> finished_{false};
  std::atomic<std::uint64_t> busy_skips_{0};
};

// Newest camera frame for the page, copied by the vision thread only when asked (one 640x480
// copy, ~0.1 ms, at most once per diag.frame_interval_ms) or when the kept one is older than
// kRefreshNs in loop time.
class FrameTap {
 public:
  static constexpr std::int64_t kRefreshNs = 1'000'000'000;

  // Vision side: never waits.
  void offer(const cv::Mat& gray, std::int64_t t_exposure_ns) {
    const bool wanted = wanted_.load(std::memory_order_acquire);
    if (!wanted && last_copy_ns_ != INT64_MIN && t_exposure_ns - last_copy_ns_ < kRefreshNs &&
        t_exposure_ns >= last_copy_ns_) {
      return;
    }
    std::unique_lock<std::mutex> lock(mutex_, std::try_to_lock);
    if (!lock.owns_lock()) return;
    gray.copyTo(frame_);  // same size every time: allocates once
    t_exposure_ns_ = t_exposure_ns;
    last_copy_ns_ = t_exposure_ns;
    wanted_.store(false, std::memory_order_relaxed);
    seq_.fetch_add(1, std::memory_order_release);
  }

  // Server side.
  void request() { wanted_.store(true, std::memory_order_release); }
  std::uint64_t seq() const { return seq_.load(std::memory_order_acquire); }
  bool take(cv::Mat* out, std::int64_t* t_exposure_ns) {
    std::lock_guard<std::mutex> lock(mutex_);
    if (frame_.empty()) return false;
    frame_.copyTo(*out);
    *t_exposure_ns = t_exposure_ns_;
    return true;
  }

 private:
  std::atomic<bool> wanted_{false};
  std::atomic<std::uint64_t> seq_{0};
  std::int64_t last_copy_ns_ = INT64_MIN;  // vision thread only
  std::mutex mutex_;
  cv::Mat frame_;
  std::int64_t t_exposure_ns_ = 0;
};

}  // namespace agv::app
