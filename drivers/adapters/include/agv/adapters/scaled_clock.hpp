// Replay-time adapters for `agvloc replay --realtime`.
#pragma once

#include <cstdint>

#include "agv/hal/can_bus.hpp"
#include "agv/hal/clock.hpp"

namespace agv::adapters {

// Replay time for --realtime at a chosen pace: now = t_first + (mono - mono0) * speed, so every
// timestamp the loop sees (frames, odometry, ticks) stays in recording time while the wall-clock
// pace is `speed` (0.5 = half speed).
class ScaledClock final : public hal::Clock {
 public:
  ScaledClock(hal::Clock& base, std::int64_t t_first_ns, double speed)
      : ScaledClock(base, t_first_ns, speed, base.now_ns()) {}
  // t_first_ns is at base time mono0_ns (e.g. the receive time of the first odometry frame).
  ScaledClock(hal::Clock& base, std::int64_t t_first_ns, double speed, std::int64_t mono0_ns)
      : base_(base), t_first_ns_(t_first_ns), mono0_ns_(mono0_ns), speed_(speed) {}
  std::int64_t now_ns() const override { return to_scaled(base_.now_ns()); }
  int sleep_until_ns(std::int64_t t_ns) override { return base_.sleep_until_ns(to_base(t_ns)); }
  std::int64_t to_monotonic_ns(std::int64_t t_ns) const override {
    return base_.to_monotonic_ns(to_base(t_ns));
  }
  std::int64_t to_scaled(std::int64_t mono_ns) const {
    return t_first_ns_ +
           static_cast<std::int64_t>(static_cast<double>(mono_ns - mono0_ns_) * speed_);
  }
  std::int64_t to_base(std::int64_t t_ns) const {
    return mono0_ns_ + static_cast<std::int64_t>(static_cast<double>(t_ns - t_first_ns_) / speed_);
  }

 private:
  hal::Clock& base_;
  std::int64_t t_first_ns_;
  std::int64_t mono0_ns_;
  double speed_;
};

// Wraps a bus: received frames get their kernel timestamps moved onto the scaled clock (a real
// interface is logged with candump itself; --can-log applies only to the log-only bus).
class TimeMappedBus final : public hal::CanBus {
 public:
  TimeMappedBus(hal::CanBus& inner, const ScaledClock* clock) : inner_(inner), clock_(clock) {}
  // A frame already taken from the inner bus (its receive time on the inner clock), delivered
  // by the next receive() before the inner bus's: replay --odom-from-can reads the first
  // odometry frame to anchor the clock, and fusion must still get it.
  void unread(const hal::CanFrame& f) {
    held_ = f;
    has_held_ = true;
  }
  hal::CanStatus send(const hal::CanFrame& f) override { return inner_.send(f); }
  std::size_t send_batch(const hal::CanFrame* f, std::size_t n, hal::CanStatus* s) override {
    return inner_.send_batch(f, n, s);
  }
  hal::CanStatus receive(hal::CanFrame* f, std::int64_t timeout_ns) override {
    hal::CanStatus s = hal::CanStatus::kOk;
    if (has_held_) {
      *f = held_;
      has_held_ = false;
    } else {
      s = inner_.receive(f, timeout_ns);
    }
    if (s == hal::CanStatus::kOk && clock_) {
      // The inner bus's receive times increase (by 1 ns at the least, can::RxStampClock); at a
      // speed below 1 the scaling can map two of them onto one nanosecond, and fusion takes
      // odometry only strictly after its newest (hil_garbage at speed 0.5 under load: two rows
      // of the received odometry with the same t_ns). Kept strictly increasing here too.
      f->t_ns = clock_->to_scaled(f->t_ns);
      if (has_last_ && f->t_ns <= last_t_ns_) f->t_ns = last_t_ns_ + 1;
      has_last_ = true;
      last_t_ns_ = f->t_ns;
    }
    return s;
  }
  hal::CanStatus set_filters(const hal::CanFilter* f, std::size_t n) override {
    return inner_.set_filters(f, n);
  }
  hal::CanBusState state() const override { return inner_.state(); }
  hal::CanErrorCounters error_counters() const override { return inner_.error_counters(); }
  hal::CanStats stats() const override { return inner_.stats(); }
  const char* last_error() const override { return inner_.last_error(); }

 private:
  hal::CanBus& inner_;
  const ScaledClock* clock_;
  hal::CanFrame held_{};
  bool has_held_ = false;
  bool has_last_ = false;
  std::int64_t last_t_ns_ = 0;  // the last delivered frame's time on the scaled clock
};

}  // namespace agv::adapters
