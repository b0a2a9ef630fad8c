// Hand-off between the real-time threads and the diagnostics server (docs/guide/diagnostics.md),
// shaped like the MQTT one (mqtt_handoff.hpp): the loop side never blocks and never allocates.
// The output loop records fixes and trajectory points into fixed rings it alone owns, and at the
// hand-off rate (loop time) copies them with the tick and the statistics into a LatestSlot it
// only try-locks; a busy slot skips that hand-off (counted), the next one retries. The vision
// worker offers frames to a FrameTap the same way; it copies one only when the server asked for it
// (or rarely, so a finished replay still has a recent frame).
#pragma once

#include <atomic>
#include <cstdint>
#include <opencv2/core.hpp>

#include "agv/diag/diag.hpp"
#include "agv/hal/can_bus.hpp"
#include "agv/http/latest_slot.hpp"
#include "output_sink.hpp"

namespace agv::app {

class DiagHandoff : public OutputSink {
 public:
  // 10 Hz: the page polls at 2 Hz; the trajectory gets a point per hand-off.
  static constexpr std::int64_t kDefaultPeriodNs = 100'000'000;

  // As the output loop's sink.
  void on_fix(const FixRecord& r) override { record_fix(r.fix, r.t_exposure_ns, r.t_done_ns); }
  void on_tick(const TickOutput& out) override {
    offer(out.tick, out.stats, out.bus, out.frames_dropped);
  }
  void finish(const localizer::TickRecord* last, const localizer::OutputStats& stats,
              const hal::CanBus* bus, std::uint64_t frames_dropped) override {
    // The loop has stopped: nothing real-time left, so this waits for the slot.
    if (last) track_.push(diag::track_point(*last));
    slot_.write([&](diag::Snapshot& s) {
      if (last) {
        fill(&s, *last, stats, bus, frames_dropped);
      } else {
        s.stats = stats;
      }
      s.finished = true;
    });
    finished_.store(true, std::memory_order_release);
  }

  // Loop side.
  void record_fix(const vision::LandmarkMeasurement& fix, std::int64_t t_exposure_ns,
                  std::int64_t t_arrival_ns) {
    fixes_.push(diag::fix_entry(fix, t_exposure_ns, t_arrival_ns));
  }
  void offer(const localizer::TickRecord& tick, const localizer::OutputStats& stats,
             const hal::CanBus* bus, std::uint64_t frames_dropped) {
    if (!due_.take(tick.t_ns)) return;
    track_.push(diag::track_point(tick));
    slot_.try_write([&](diag::Snapshot& s) { fill(&s, tick, stats, bus, frames_dropped); });
  }
  // Server side: copies the newest snapshot into *out when it is newer than *seq.
  bool take(diag::Snapshot* out, std::uint64_t* seq) {
    if (slot_.seq() == *seq) return false;
    slot_.read([&](const diag::Snapshot& s) {
      *out = s;
      *seq = slot_.seq();
    });
    return true;
  }
  bool finished() const { return finished_.load(std::memory_order_acquire); }
  std::uint64_t busy_skips() const { return slot_.busy_skips(); }

 private:
  void fill(diag::Snapshot* s, const localizer::TickRecord& tick,
            const localizer::OutputStats& stats, const hal::CanBus* bus,
            std::uint64_t frames_dropped) const {
    s->has_tick = true;
    s->tick = tick;
    s->stats = stats;
    s->can_present = bus != nullptr;
    if (bus) s->can = bus->stats();
    s->frames_dropped = frames_dropped;
    s->fixes = fixes_;
    s->track = track_;
  }

  PeriodicDue due_{kDefaultPeriodNs};                       // loop thread only
  diag::Ring<diag::FixEntry, diag::kLastFixes> fixes_;      // loop thread only
  diag::Ring<diag::TrackPoint, diag::kTrackPoints> track_;  // loop thread only
  LatestSlot<diag::Snapshot> slot_;
  std::atomic<bool> finished_{false};
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
    slot_.try_write([&](Frame& f) {
      gray.copyTo(f.gray);  // same size every time: allocates once
      f.t_exposure_ns = t_exposure_ns;
      last_copy_ns_ = t_exposure_ns;
      wanted_.store(false, std::memory_order_relaxed);
    });
  }

  // Server side.
  void request() { wanted_.store(true, std::memory_order_release); }
  std::uint64_t seq() const { return slot_.seq(); }
  bool take(cv::Mat* out, std::int64_t* t_exposure_ns) {
    return slot_.read([&](const Frame& f) {
      if (f.gray.empty()) return false;
      f.gray.copyTo(*out);
      *t_exposure_ns = f.t_exposure_ns;
      return true;
    });
  }

 private:
  struct Frame {
    cv::Mat gray;
    std::int64_t t_exposure_ns = 0;
  };
  std::atomic<bool> wanted_{false};
  std::int64_t last_copy_ns_ = INT64_MIN;  // vision thread only
  LatestSlot<Frame> slot_;
};

}  // namespace agv::app
