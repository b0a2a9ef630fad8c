// Hand-off between the output loop and the MQTT thread (docs/guide/vda5050.md "Threads"). The loop
// side never blocks and never allocates: each slot is guarded by a mutex the loop only try-locks
// (the MQTT thread holds it for one copy of a few hundred bytes); a busy slot skips this tick's
// sample or this tick's look at the mailbox (counted), the next tick retries.
#pragma once

#include <atomic>
#include <cstdint>
#include <mutex>

#include "agv/localizer/localizer.hpp"

namespace agv::app {

// A pose to set, from a validated initPosition; seq names it in the answer.
struct InitPoseCommand {
  std::uint64_t seq = 0;
  double x_mm = 0.0, y_mm = 0.0, theta_rad = 0.0;
};

class MqttHandoff {
 public:
  // Loop side. offer: the tick at t_ns, taken when the visualization period is due (rate limit in
  // loop time, so a fast replay publishes at recording rate, not at wall rate).
  void set_period_ns(std::int64_t period_ns) { period_ns_ = period_ns; }
  void offer(const localizer::TickRecord& tick) {
    if (next_due_ns_ != INT64_MIN && tick.t_ns < next_due_ns_) return;
    std::unique_lock<std::mutex> lock(sample_mutex_, std::try_to_lock);
    if (!lock.owns_lock()) {
      busy_skips_.fetch_add(1, std::memory_order_relaxed);
      return;
    }
    if (has_sample_) superseded_.fetch_add(1, std::memory_order_relaxed);
    sample_ = tick;
    has_sample_ = true;
    next_due_ns_ = (next_due_ns_ == INT64_MIN ? tick.t_ns : next_due_ns_) + period_ns_;
    if (next_due_ns_ <= tick.t_ns) next_due_ns_ = tick.t_ns + period_ns_;  // after a gap
  }
  // A pending pose command, once; false when none (or the slot was busy this tick).
  bool take_command(InitPoseCommand* out) {
    if (!command_pending_.load(std::memory_order_acquire)) return false;
    std::unique_lock<std::mutex> lock(command_mutex_, std::try_to_lock);
    if (!lock.owns_lock()) return false;
    *out = command_;
    command_pending_.store(false, std::memory_order_release);
    return true;
  }
  // The loop applied (ok) or refused command seq.
  void report(std::uint64_t seq, bool ok) {
    applied_ok_.store(ok, std::memory_order_relaxed);
    applied_seq_.store(seq, std::memory_order_release);
  }

  // MQTT side (may block briefly).
  bool take_sample(localizer::TickRecord* out) {
    std::lock_guard<std::mutex> lock(sample_mutex_);
    if (!has_sample_) return false;
    *out = sample_;
    has_sample_ = false;
    return true;
  }
  // Replaces a command the loop has not taken yet: returns its seq (0 if none) so it can be
  // answered FAILED (superseded).
  std::uint64_t post_command(const InitPoseCommand& c) {
    std::lock_guard<std::mutex> lock(command_mutex_);
    const std::uint64_t replaced = command_pending_.load() ? command_.seq : 0;
    command_ = c;
    command_pending_.store(true, std::memory_order_release);
    return replaced;
  }
  // The newest command the loop answered (seq 0: none yet).
  std::uint64_t applied_seq(bool* ok) const {
    const std::uint64_t s = applied_seq_.load(std::memory_order_acquire);
    *ok = applied_ok_.load(std::memory_order_relaxed);
    return s;
  }
  std::uint64_t busy_skips() const { return busy_skips_.load(std::memory_order_relaxed); }
  std::uint64_t superseded() const { return superseded_.load(std::memory_order_relaxed); }

 private:
  std::int64_t period_ns_ = 100'000'000;
  std::int64_t next_due_ns_ = INT64_MIN;  // loop thread only
  std::mutex sample_mutex_;
  localizer::TickRecord sample_;
  bool has_sample_ = false;
  std::mutex command_mutex_;
  InitPoseCommand command_;
  std::atomic<bool> command_pending_{false};
  std::atomic<std::uint64_t> applied_seq_{0};
  std::atomic<bool> applied_ok_{false};
  std::atomic<std::uint64_t> busy_skips_{0};
  std::atomic<std::uint64_t> superseded_{0};
};

}  // namespace agv::app
