// Test doubles for the loop tests: a fixed-capacity CAN bus that never allocates.
#pragma once

#include <array>
#include <cstddef>

#include "agv/hal/can_bus.hpp"

namespace agv::test {

class StaticBus final : public hal::CanBus {
 public:
  static constexpr std::size_t kCap = 4096;
  hal::CanStatus send(const hal::CanFrame& f) override {
    if (fail_sends) {
      ++stats_.tx_errors;
      return hal::CanStatus::kError;
    }
    if (sent_n < kCap) sent[sent_n++] = f;
    ++stats_.tx_ok;
    return hal::CanStatus::kOk;
  }
  hal::CanStatus receive(hal::CanFrame* f, std::int64_t) override {
    if (rx_head == rx_n) return hal::CanStatus::kTimeout;
    *f = rx[rx_head++];
    ++stats_.rx_frames;
    return hal::CanStatus::kOk;
  }
  hal::CanStatus set_filters(const hal::CanFilter*, std::size_t) override {
    return hal::CanStatus::kOk;
  }
  hal::CanBusState state() const override { return bus_state; }
  hal::CanErrorCounters error_counters() const override { return {}; }
  hal::CanStats stats() const override { return stats_; }
  const char* last_error() const override { return ""; }

  void inject(const hal::CanFrame& f) {
    if (rx_n < kCap) rx[rx_n++] = f;
  }
  void clear_sent() { sent_n = 0; }

  std::array<hal::CanFrame, kCap> sent{};
  std::size_t sent_n = 0;
  std::array<hal::CanFrame, kCap> rx{};
  std::size_t rx_n = 0, rx_head = 0;
  bool fail_sends = false;
  hal::CanBusState bus_state = hal::CanBusState::kErrorActive;

 private:
  hal::CanStats stats_;
};

}  // namespace agv::test
