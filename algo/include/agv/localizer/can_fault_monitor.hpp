// Maps CAN bus health to the AGV_Status fault flags (agv::protocol::fault), once per status
// frame. Events are latched between two calls so a short error-passive or a single dropped frame
// still shows in the next status frame. Pure: the caller reads the bus state and counters.
#pragma once

#include <cstdint>

#include "agv/hal/can_types.hpp"

namespace agv::localizer {

class CanFaultMonitor {
 public:
  // Returns fault::kCanErrorPassive when the bus is in warning/passive now or went passive since
  // the last call; fault::kCanBusOff when it is bus-off or down now, or since the last call
  // went bus-off, was reopened, or dropped frames (full transmit queue, receive overflow).
  std::uint8_t update(hal::CanBusState state, const hal::CanStats& stats);

 private:
  hal::CanStats last_;
};

}  // namespace agv::localizer
