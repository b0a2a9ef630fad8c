// The plain CAN frame the protocol codec reads and writes. algo/ must not depend on hal/, so this
// is its own struct; agv::hal::CanFrame has the same members and converts with
// agv::can::to_hal()/from_hal() (drivers/candump/include/agv/can/frame_convert.hpp).
#pragma once

#include <cstdint>

namespace agv::protocol {

inline constexpr std::uint32_t kCanStdIdMask = 0x7FFu;       // 11-bit identifier
inline constexpr std::uint32_t kCanExtIdMask = 0x1FFFFFFFu;  // 29-bit identifier

struct CanFrameData {
  std::uint32_t id = 0;   // 11- or 29-bit identifier, no flag bits
  bool extended = false;  // true: 29-bit identifier
  std::uint8_t len = 0;   // data length 0..8 (classic CAN)
  std::uint8_t data[8] = {};
  std::int64_t t_ns = 0;  // receive timestamp, monotonic clock; 0 on frames to be sent
};

}  // namespace agv::protocol
