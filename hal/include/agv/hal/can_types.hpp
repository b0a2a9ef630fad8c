// Plain CAN bus health types shared by the CanBus interface (can_bus.hpp) and the pure localizer
// core (algo/), which latches bus faults from them without calling any hal interface.
#pragma once

#include <cstdint>

namespace agv::hal {

// ISO 11898 fault confinement states, plus "down" for a missing or administratively down link.
enum class CanBusState : int {
  kErrorActive = 0,
  kErrorWarning = 1,  // an error counter >= 96
  kErrorPassive = 2,  // an error counter >= 128
  kBusOff = 3,        // transmit error counter > 255; controller offline until restarted
  kDown = 4,
};

// Accept a frame when (frame.id & mask) == (id & mask) and its ID type equals `extended`.
struct CanFilter {
  std::uint32_t id = 0;
  std::uint32_t mask = 0;
  bool extended = false;
};

// Monotonic counts since the backend was created.
struct CanStats {
  std::uint64_t tx_ok = 0;
  std::uint64_t tx_dropped_queue_full = 0;  // kWouldBlock returns
  std::uint64_t tx_errors = 0;              // kBusOff / kDown / kError returns of send()
  std::uint64_t rx_frames = 0;              // data frames delivered by receive()
  std::uint64_t rx_error_frames = 0;        // error frames consumed (state/counters updated)
  std::uint64_t rx_dropped = 0;             // frames lost in the receive queue (overflow)
  std::uint64_t bus_off_count = 0;          // transitions into bus-off
  std::uint64_t error_passive_count = 0;    // transitions into error-passive
  std::uint64_t restarts = 0;               // successful reopen after the link went down
};

}  // namespace agv::hal
