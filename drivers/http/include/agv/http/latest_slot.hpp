// The two mechanics every hand-off out of the real-time threads shares (the MQTT, diagnostics,
// frame and snapshot hand-offs): a latest-value slot the real-time side only try-locks, and a
// schedule in loop time that says when a periodic output is due.
#pragma once

#include <atomic>
#include <cstdint>
#include <mutex>

namespace agv::app {

// A value the real-time side overwrites and another thread copies out. The writer never waits:
// try_write skips (and counts) when the reader holds the slot, the next offer retries. Readers
// may wait (they hold the lock for one copy). seq() counts the writes, so a reader can tell a new
// value from the one it has.
template <typename T>
class LatestSlot {
 public:
  // Real-time side: fill(T&) under the lock unless the slot is busy. False when skipped.
  template <typename Fill>
  bool try_write(Fill&& fill) {
    std::unique_lock<std::mutex> lock(mutex_, std::try_to_lock);
    if (!lock.owns_lock()) {
      busy_skips_.fetch_add(1, std::memory_order_relaxed);
      return false;
    }
    fill(value_);
    seq_.fetch_add(1, std::memory_order_release);
    return true;
  }
  // Any side, waiting for the lock (the reader's side, or the writer once real time is over).
  template <typename Fill>
  void write(Fill&& fill) {
    std::lock_guard<std::mutex> lock(mutex_);
    fill(value_);
    seq_.fetch_add(1, std::memory_order_release);
  }
  // Reader side: use(T&) under the lock; returns what use returns.
  template <typename Use>
  decltype(auto) read(Use&& use) {
    std::lock_guard<std::mutex> lock(mutex_);
    return use(value_);
  }
  // A reader that must not wait either (the real-time side taking a command): use(T&) unless the
  // slot is busy. False when skipped (not counted: the next look retries).
  template <typename Use>
  bool try_read(Use&& use) {
    std::unique_lock<std::mutex> lock(mutex_, std::try_to_lock);
    if (!lock.owns_lock()) return false;
    use(value_);
    return true;
  }
  std::uint64_t seq() const { return seq_.load(std::memory_order_acquire); }
  std::uint64_t busy_skips() const { return busy_skips_.load(std::memory_order_relaxed); }

 private:
  std::mutex mutex_;
  T value_{};
  std::atomic<std::uint64_t> seq_{0};
  std::atomic<std::uint64_t> busy_skips_{0};
};

// When a periodic output is due, in loop time (so a fast replay publishes at recording rate, not
// at wall rate). The first call is due at once, or one period later (first_at_start false);
// after a gap longer than a period the schedule restarts from the late time instead of bursting.
// One thread only.
class PeriodicDue {
 public:
  explicit PeriodicDue(std::int64_t period_ns, bool first_at_start = true)
      : period_ns_(period_ns), first_at_start_(first_at_start) {}

  void set_period_ns(std::int64_t period_ns) { period_ns_ = period_ns; }
  std::int64_t period_ns() const { return period_ns_; }

  // Is t_ns due? (Starts the schedule when first_at_start is false.)
  bool is_due(std::int64_t t_ns) {
    if (next_due_ns_ == INT64_MIN) {
      if (first_at_start_) return true;
      next_due_ns_ = t_ns + period_ns_;
    }
    return t_ns >= next_due_ns_;
  }
  // The output due at t_ns went out: the next one is a period later.
  void advance(std::int64_t t_ns) {
    next_due_ns_ = (next_due_ns_ == INT64_MIN ? t_ns : next_due_ns_) + period_ns_;
    if (next_due_ns_ <= t_ns) next_due_ns_ = t_ns + period_ns_;
  }
  // is_due and advance in one: true (and the schedule moved on) when t_ns is due.
  bool take(std::int64_t t_ns) {
    if (!is_due(t_ns)) return false;
    advance(t_ns);
    return true;
  }

 private:
  std::int64_t period_ns_;
  bool first_at_start_;
  std::int64_t next_due_ns_ = INT64_MIN;
};

}  // namespace agv::app
