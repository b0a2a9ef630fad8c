// End-to-end protection in the style of AUTOSAR E2E profile 1 (docs/guide/can.md, "E2E"):
//   byte 0       CRC-8 SAE J1850 (poly 0x1D, init 0xFF, xor-out 0xFF)
//   byte 1 0..3  alive counter 0..14 (15 is never sent and is rejected), +1 per frame, wraps 14->0
//   CRC input    data-ID low byte, data-ID high byte, then frame bytes 1..7, in this order
//                (profile 1 "both bytes" data-ID mode; the data ID itself is never transmitted).
// Pure: no I/O, no clocks.
#pragma once

#include <cstddef>
#include <cstdint>

#include "agv/protocol/can_frame.hpp"

namespace agv::protocol {

inline constexpr std::uint8_t kE2eCounterModulo = 15;  // counter values 0..14
inline constexpr std::uint8_t kE2eFrameLen = 8;

// CRC-8 SAE J1850 of `len` bytes (init 0xFF, xor-out 0xFF). crc8_sae_j1850(00 00 00 00) = 0x59.
std::uint8_t crc8_sae_j1850(const std::uint8_t* data, std::size_t len);

// The E2E CRC of an 8-byte frame: over data_id (low byte first) and data[1..7].
std::uint8_t e2e_crc(std::uint16_t data_id, const std::uint8_t data[8]);

// Writes counter (low nibble of byte 1, upper nibble kept) and the CRC (byte 0).
void e2e_protect(std::uint16_t data_id, std::uint8_t counter, std::uint8_t data[8]);

enum class E2eStatus : std::uint8_t {
  kOk = 0,         // next counter, CRC good: accept
  kOkSomeLost,     // CRC good, 2..max_delta_counter ahead: accept, (delta - 1) frames were lost
  kInitial,        // first frame seen (or first after reset): accept, no sequence reference yet
  kRepeated,       // same counter as the last accepted frame: reject (sender stuck or duplicate)
  kWrongSequence,  // counter jumped more than max_delta_counter: reject, resynchronise on it
  kBadCrc,         // CRC mismatch: reject (corruption or wrong data ID = masquerade)
  kBadLength,      // len != 8: reject
  kBadCounter,     // counter value 15: reject
};

const char* to_string(E2eStatus s);
inline bool e2e_accepted(E2eStatus s) {
  return s == E2eStatus::kOk || s == E2eStatus::kOkSomeLost || s == E2eStatus::kInitial;
}

struct E2eCheckerConfig {
  std::uint16_t data_id = 0;
  // Largest accepted counter step. 1 rejects any loss; larger tolerates (delta-1) lost frames.
  // Default 3: two lost frames in a row are still accepted (and counted), a longer gap is a jump.
  std::uint8_t max_delta_counter = 3;
};

struct E2eCounters {
  std::uint64_t ok = 0;            // kOk + kInitial
  std::uint64_t ok_some_lost = 0;  // accepted with a gap
  std::uint64_t lost_frames = 0;   // sum of gaps of accepted frames
  std::uint64_t repeated = 0;
  std::uint64_t wrong_sequence = 0;
  std::uint64_t bad_crc = 0;
  std::uint64_t bad_length = 0;
  std::uint64_t bad_counter = 0;
  std::uint64_t rejected() const {
    return repeated + wrong_sequence + bad_crc + bad_length + bad_counter;
  }
};

// Receiver-side check of one data ID. After kWrongSequence the jumped-to counter becomes the
// reference, so the following frame (counter + 1) is accepted again: a jump costs one frame.
class E2eChecker {
 public:
  explicit E2eChecker(const E2eCheckerConfig& cfg) : cfg_(cfg) {}
  E2eStatus check(const hal::CanFrame& frame);
  void reset() { have_ref_ = false; }
  const E2eCounters& counters() const { return counters_; }

 private:
  E2eCheckerConfig cfg_;
  E2eCounters counters_;
  bool have_ref_ = false;
  std::uint8_t last_counter_ = 0;
};

}  // namespace agv::protocol
