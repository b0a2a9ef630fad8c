#include "agv/localizer/fault_transitions.hpp"

#include "agv/protocol/codec.hpp"

namespace agv::localizer {

const std::array<FaultBitName, kFaultBitCount>& fault_bit_names() {
  static constexpr std::array<FaultBitName, kFaultBitCount> kNames = {{
      {protocol::fault::kCameraStalled, "FaultCameraStalled", "camera_stalled"},
      {protocol::fault::kCameraError, "FaultCameraError", "camera_error"},
      {protocol::fault::kOdomTimeout, "FaultOdomTimeout", "odometry_timeout"},
      {protocol::fault::kOdomE2E, "FaultOdomE2E", "odometry_e2e"},
      {protocol::fault::kCanErrorPassive, "FaultCanErrorPassive", "can_error_passive"},
      {protocol::fault::kCanBusOff, "FaultCanBusOff", "can_bus_off"},
      {protocol::fault::kNoMap, "FaultNoMap", "no_map"},
      {protocol::fault::kLoopOverrun, "FaultLoopOverrun", "loop_overrun"},
      {protocol::fault::kImuTimeout, "FaultImuTimeout", "imu_timeout"},
      {protocol::fault::kImuE2E, "FaultImuE2E", "imu_e2e"},
  }};
  return kNames;
}

FaultTransitions FaultTransitionLog::update(std::uint16_t faults, std::int64_t now_ns) {
  FaultTransitions out;
  const auto& names = fault_bit_names();
  for (int i = 0; i < kFaultBitCount; ++i) {
    Bit& b = bits_[static_cast<std::size_t>(i)];
    const FaultBitName& nm = names[static_cast<std::size_t>(i)];
    const bool now = (faults & nm.bit) != 0;
    if (now != b.now) ++b.changes;
    b.now = now;
    if (b.changes == 0) continue;
    if (b.window_start_ns == INT64_MIN || now_ns - b.window_start_ns >= window_ns_) {
      b.window_start_ns = now_ns;
      b.lines_in_window = 0;
    }
    if (b.lines_in_window >= kBurst) continue;  // held to the end of the window
    ++b.lines_in_window;
    FaultTransition& t = out.items[static_cast<std::size_t>(out.n++)];
    t.bit = nm.bit;
    t.signal = nm.signal;
    t.name = nm.name;
    t.set = now;
    t.changes = b.changes;
    b.changes = 0;
  }
  return out;
}

}  // namespace agv::localizer
