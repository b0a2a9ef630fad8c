// A CanBus that only logs: every sent frame goes to a `candump -l` file (replay without a CAN
// interface); nothing is ever received.
#pragma once

#include <string>
#include <utility>

#include "agv/can/candump_file.hpp"
#include "agv/hal/can_bus.hpp"
#include "agv/hal/clock.hpp"

namespace agv::can {

// Output-only bus that writes every sent frame to a `candump -l` file (replay without a CAN
// interface). The timestamp is the loop time of the send.
class LogOnlyBus final : public hal::CanBus {
 public:
  // clock gives the timestamps: the loop clock, or the stepped clock of a fast replay.
  LogOnlyBus(CandumpWriter& w, const hal::Clock& clock, std::string iface)
      : w_(w), clock_(clock), iface_(std::move(iface)) {}
  hal::CanStatus send(const hal::CanFrame& f) override {
    if (!w_.write(f, iface_, clock_.now_ns())) {
      ++stats_.tx_errors;
      return hal::CanStatus::kError;
    }
    ++stats_.tx_ok;
    return hal::CanStatus::kOk;
  }
  hal::CanStatus receive(hal::CanFrame*, std::int64_t) override { return hal::CanStatus::kTimeout; }
  hal::CanStatus set_filters(const hal::CanFilter*, std::size_t) override {
    return hal::CanStatus::kOk;
  }
  hal::CanBusState state() const override { return hal::CanBusState::kErrorActive; }
  hal::CanErrorCounters error_counters() const override { return {}; }
  hal::CanStats stats() const override { return stats_; }
  const char* last_error() const override { return ""; }

 private:
  CandumpWriter& w_;
  const hal::Clock& clock_;
  std::string iface_;
  hal::CanStats stats_;
};

}  // namespace agv::can
