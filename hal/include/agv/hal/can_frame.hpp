// The one CAN frame type of the project: the protocol codec (algo/) encodes into it and decodes
// from it, and every CanBus backend sends and receives it. Plain data with no dependencies, so
// algo/ may include it without depending on any hal interface.
#pragma once

#include <cstdint>

namespace agv::hal {

struct CanFrame {
  std::uint32_t id = 0;   // 11- or 29-bit identifier, no flag bits
  bool extended = false;  // true: 29-bit identifier
  std::uint8_t len = 0;   // data length 0..8 (classic CAN)
  std::uint8_t data[8] = {};
  std::int64_t t_ns = 0;  // receive: kernel receive timestamp on CLOCK_MONOTONIC; send: ignored
};

}  // namespace agv::hal
