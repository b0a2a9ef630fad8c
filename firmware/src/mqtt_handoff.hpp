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

// The loop's answer to a command: applied (ok) or refused by the filter.
struct CommandAnswer {
  std::uint64_t seq = 0;  // 0: none
  bool ok = false;
};

class MqttHandoff {
 public:
  // Loop side. offer: the tick at t_ns, taken when the visualization period is due (rate limit in
  // loop time, so a fast replay publishes at recording rate, not at wall rate).
  void set_period_ns(std::int64_t period_ns) { period_ns_ = period_ns; }
  void offer(const localizer::TickRecord& tick) {
    // A reported command makes its tick due at once (the answer must carry the pose after it)
    // without moving the schedule.
    const bool due = next_due_ns_ == INT64_MIN || tick.t_ns >= next_due_ns_;
    if (!due && !report_pending_) return;
    std::unique_lock<std::mutex> lock(sample_mutex_, std::try_to_lock);
    if (!lock.owns_lock()) {
      busy_skips_.fetch_add(1, std::memory_order_relaxed);
      return;  // a pending report stays pending: the next tick offers again
    }
    if (has_sample_) superseded_.fetch_add(1, std::memory_order_relaxed);
    sample_ = tick;
    has_sample_ = true;
    if (report_pending_) {
      sample_answer_ = report_;
      report_pending_ = false;
    }
    if (!due) return;
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
  // The loop applied (ok) or refused command seq, before this tick's offer: the answer travels
  // with that tick's sample, so that it carries the pose after the command.
  void report(std::uint64_t seq, bool ok) {
    report_ = {seq, ok};
    report_pending_ = true;
  }

  // MQTT side (may block briefly).
  // The newest sample; *answer (if given) the command answered at or before its tick (seq 0: none
  // since the last take).
  bool take_sample(localizer::TickRecord* out, CommandAnswer* answer = nullptr) {
    std::lock_guard<std::mutex> lock(sample_mutex_);
    if (!has_sample_) return false;
    *out = sample_;
    has_sample_ = false;
    if (answer) *answer = sample_answer_;
    sample_answer_ = {};
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
  CommandAnswer report_;         // loop thread only
  bool report_pending_ = false;  // loop thread only
  CommandAnswer sample_answer_;  // sample_mutex_
  std::atomic<std::uint64_t> busy_skips_{0};
  std::atomic<std::uint64_t> superseded_{0};
};

}  // namespace agv::app
