// The `candump -l` log line format of can-utils, for classic CAN frames:
//   (1436509052.249713) can0 123#DEADBEEF        standard ID: 3 hex digits
//   (1436509052.249713) can0 12345678#0102       extended ID: 8 hex digits
//   (1436509052.249713) can0 123#R               remote frame (no data; optional DLC digit)
//   (1436509052.249713) can0 20000004#0004...    error frame (CAN_ERR_FLAG, bit 29, set)
//   (1436509052.249713) can0 123#1122 R          direction suffix of candump -x / asc2log
//                                                (" R" / " T", accepted and ignored)
// The timestamp is whatever clock candump used (wall clock for live captures); records keep it
// as integer nanoseconds with microsecond resolution. CAN FD lines ("##") are rejected.
// Pure parse/format: the file I/O is in drivers/candump.
#pragma once

#include <cstdint>
#include <string>
#include <string_view>

#include "agv/protocol/can_frame.hpp"

namespace agv::protocol {

struct CandumpRecord {
  std::int64_t t_ns = 0;  // log timestamp; also copied into frame.t_ns by the parser
  std::string iface;      // e.g. "can0"
  hal::CanFrame frame;
  bool rtr = false;
  bool error_frame = false;  // frame.id then holds the error class bits (linux/can/error.h)
};

// Parses one line (trailing "\n"/"\r\n" allowed). false + *error on malformed input.
bool parse_candump_line(std::string_view line, CandumpRecord* out, std::string* error);

// Formats one record without a trailing newline, exactly as `candump -l` writes it
// (hex upper case, timestamp truncated to microseconds).
std::string format_candump_line(const CandumpRecord& rec);

}  // namespace agv::protocol
