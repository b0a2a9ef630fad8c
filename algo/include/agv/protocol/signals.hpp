// The signal table: the single source of the CAN frame layout in code. can/agvloc.dbc is checked
// against it by tests/can (field by field) and docs/guide/can.md's frame table is rendered from it.
// All signals are Intel (little-endian) byte order; start bit = least significant bit, counted
// from bit 0 of byte 0 (DBC "@1" convention). raw = round((phys - offset) / scale), clamped to
// [raw_min, raw_max] = the raw values of [min, max]: signals saturate, they never wrap.
#pragma once

#include <cstddef>
#include <cstdint>
#include <span>

#include "agv/protocol/can_frame.hpp"

namespace agv::protocol {

inline constexpr int kProtocolVersion = 1;  // sent in the heartbeat; bump on any layout change

struct SignalDef {
  const char* name;
  std::uint8_t start_bit;
  std::uint8_t length;
  bool little_endian;  // always true here; kept so the DBC test checks it explicitly
  bool is_signed;
  double scale;
  double offset;
  double min;  // physical range; encoding saturates here
  double max;
  const char* unit;
  const char* comment;
};

enum class Direction : std::uint8_t { kTx, kRx };  // seen from the localizer

// Message indices (stable; also the order of message_table()).
enum class Msg : std::uint8_t {
  kPoseXY = 0,
  kPoseHeading,
  kVelocity,
  kQuality,
  kStatus,
  kHeartbeat,
  kOdomWheels,
  kOdomTwist,
  kGyro,  // appended: the indices above stay stable
  kCount
};

struct MessageDef {
  Msg msg;
  const char* name;
  std::uint32_t id_offset;  // CAN ID = base_id + id_offset (default; input IDs configurable)
  std::uint16_t data_id;    // E2E data ID (independent of the CAN ID)
  std::uint8_t dlc;
  Direction dir;
  std::uint32_t cycle_ms;  // nominal period; 0 = event/configurable
  const char* comment;
  std::span<const SignalDef> signals;
};

std::span<const MessageDef> message_table();
const MessageDef& message_def(Msg m);
// nullptr when absent.
const SignalDef* find_signal(const MessageDef& m, const char* name);

// Raw limits implied by a signal's physical [min, max].
std::int64_t raw_min(const SignalDef& s);
std::int64_t raw_max(const SignalDef& s);

// Physical -> raw with saturation. NaN encodes as the raw value of 0 (clamped) and sets
// *was_nan; +-inf saturate. *saturated (optional) tells whether clamping happened.
std::int64_t to_raw(const SignalDef& s, double phys, bool* saturated = nullptr,
                    bool* was_nan = nullptr);
double to_phys(const SignalDef& s, std::int64_t raw);

// Bit packing into / out of an 8-byte payload (Intel order). put_raw masks to `length` bits.
void put_raw(const SignalDef& s, std::int64_t raw, std::uint8_t data[8]);
std::int64_t get_raw(const SignalDef& s, const std::uint8_t data[8]);  // sign-extended if signed

// Convenience: saturating physical write / read.
void put_phys(const SignalDef& s, double phys, std::uint8_t data[8]);
double get_phys(const SignalDef& s, const std::uint8_t data[8]);

}  // namespace agv::protocol
