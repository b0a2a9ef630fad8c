// CAN identifier masks for the protocol. The frame itself is agv::hal::CanFrame, a plain struct
// with no dependencies (hal/include/agv/hal/can_frame.hpp): algo/ uses hal's data types, never
// its interfaces.
#pragma once

#include <cstdint>

#include "agv/hal/can_frame.hpp"

namespace agv::protocol {

inline constexpr std::uint32_t kCanStdIdMask = 0x7FFu;       // 11-bit identifier
inline constexpr std::uint32_t kCanExtIdMask = 0x1FFFFFFFu;  // 29-bit identifier

}  // namespace agv::protocol
