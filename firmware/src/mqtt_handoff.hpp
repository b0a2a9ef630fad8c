// Hand-off between the output loop and the MQTT thread (docs/guide/vda5050.md "Threads"). The loop
// side never blocks and never allocates: each slot is a LatestSlot the loop only try-locks (the
// MQTT thread holds it for one copy of a few hundred bytes); a busy slot skips this tick's sample
// (counted) or this tick's look at the mailbox, the next tick retries.
#pragma once

#include <atomic>
#include <cstdint>

#include "agv/localizer/localizer.hpp"
#include "agv/http/latest_slot.hpp"
#include "output_sink.hpp"

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

class MqttHandoff : public OutputSink {
 public:
  // As the output loop's sink: a pending initPosition is applied before the tick (the pose an
  // operator sets gets half the lost limits as sigma, localizer::init_position_sigma) and each
  // tick is offered.
  void before_tick(std::int64_t now_ns, localizer::Localizer& core) override {
    InitPoseCommand cmd;
    if (take_command(&cmd)) {
      report(cmd.seq, core.init_position(now_ns, {cmd.x_mm, cmd.y_mm, cmd.theta_rad}));
    }
  }
  void on_tick(const TickOutput& out) override { offer(out.tick); }

  // Loop side. offer: the tick at t_ns, taken when the visualization period is due (rate limit in
  // loop time, so a fast replay publishes at recording rate, not at wall rate).
  void set_period_ns(std::int64_t period_ns) { due_.set_period_ns(period_ns); }
  void offer(const localizer::TickRecord& tick) {
    // A reported command makes its tick due at once (the answer must carry the pose after it)
    // without moving the schedule.
    const bool due = due_.is_due(tick.t_ns);
    if (!due && !report_pending_) return;
    const bool written = sample_.try_write([&](Sample& s) {
      if (s.has_tick) superseded_.fetch_add(1, std::memory_order_relaxed);
      s.tick = tick;
      s.has_tick = true;
      if (report_pending_) {
        s.answer = report_;
        report_pending_ = false;
      }
    });
    // Busy: a pending report stays pending and the schedule stays, the next tick offers again.
    if (written && due) due_.advance(tick.t_ns);
  }
  // A pending pose command, once; false when none (or the slot was busy this tick).
  bool take_command(InitPoseCommand* out) {
    if (!command_pending_.load(std::memory_order_acquire)) return false;
    return command_.try_read([&](InitPoseCommand& c) {
      *out = c;
      command_pending_.store(false, std::memory_order_release);
    });
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
    return sample_.read([&](Sample& s) {
      if (!s.has_tick) return false;
      *out = s.tick;
      s.has_tick = false;
      if (answer) *answer = s.answer;
      s.answer = {};
      return true;
    });
  }
  // Replaces a command the loop has not taken yet: returns its seq (0 if none) so it can be
  // answered FAILED (superseded).
  std::uint64_t post_command(const InitPoseCommand& c) {
    std::uint64_t replaced = 0;
    command_.write([&](InitPoseCommand& slot) {
      replaced = command_pending_.load() ? slot.seq : 0;
      slot = c;
      command_pending_.store(true, std::memory_order_release);
    });
    return replaced;
  }
  std::uint64_t busy_skips() const { return sample_.busy_skips(); }
  std::uint64_t superseded() const { return superseded_.load(std::memory_order_relaxed); }

 private:
  struct Sample {
    localizer::TickRecord tick;
    bool has_tick = false;
    CommandAnswer answer;  // the command answered at or before this tick
  };
  PeriodicDue due_{100'000'000};  // loop thread only
  LatestSlot<Sample> sample_;
  LatestSlot<InitPoseCommand> command_;
  std::atomic<bool> command_pending_{false};
  CommandAnswer report_;         // loop thread only
  bool report_pending_ = false;  // loop thread only
  std::atomic<std::uint64_t> superseded_{0};
};

}  // namespace agv::app
