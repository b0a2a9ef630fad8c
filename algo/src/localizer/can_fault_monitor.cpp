#include "agv/localizer/can_fault_monitor.hpp"

#include "agv/protocol/codec.hpp"

namespace agv::localizer {

std::uint8_t CanFaultMonitor::update(hal::CanBusState state, const hal::CanStats& s) {
  std::uint8_t f = 0;
  if (state == hal::CanBusState::kErrorWarning || state == hal::CanBusState::kErrorPassive ||
      s.error_passive_count > last_.error_passive_count) {
    f |= protocol::fault::kCanErrorPassive;
  }
  if (state == hal::CanBusState::kBusOff || state == hal::CanBusState::kDown ||
      s.bus_off_count > last_.bus_off_count || s.restarts > last_.restarts ||
      s.tx_dropped_queue_full > last_.tx_dropped_queue_full || s.rx_dropped > last_.rx_dropped) {
    f |= protocol::fault::kCanBusOff;
  }
  last_ = s;
  return f;
}

}  // namespace agv::localizer
