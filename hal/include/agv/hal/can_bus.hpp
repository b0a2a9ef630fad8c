// CAN bus interface. Backends: drivers/socketcan (Linux SocketCAN), drivers/fakecan (in-process
// fake for tests), drivers/candump (replay of a `candump -l` log). No Linux headers here.
// Methods are called from the real-time loop: none of them may block longer than the timeout
// it is given (send never blocks).
#pragma once

#include <cstddef>
#include <cstdint>

namespace agv::hal {

// Same members as agv::protocol::CanFrameData (algo/); convert with agv::can::to_hal/from_hal.
struct CanFrame {
  std::uint32_t id = 0;   // 11- or 29-bit identifier, no flag bits
  bool extended = false;  // 29-bit identifier
  std::uint8_t len = 0;   // data length 0..8
  std::uint8_t data[8] = {};
  std::int64_t t_ns = 0;  // receive: kernel receive timestamp on CLOCK_MONOTONIC; send: ignored
};

enum class CanStatus : int {
  kOk = 0,
  kWouldBlock = 1,       // transmit queue full (EAGAIN/ENOBUFS); frame dropped and counted
  kTimeout = 2,          // receive: nothing within the timeout
  kBusOff = 3,           // controller is bus-off; frame not sent
  kDown = 4,             // interface down or missing; the backend retries by itself
  kInvalidArgument = 5,  // bad frame (len > 8, ID out of range) or too many filters
  kError = 6,            // other failure; see last_error()
  kEndOfStream = 7,      // replay backends: no more frames
};

const char* to_string(CanStatus s);

// ISO 11898 fault confinement states, plus "down" for a missing or administratively down link.
enum class CanBusState : int {
  kErrorActive = 0,
  kErrorWarning = 1,  // an error counter >= 96
  kErrorPassive = 2,  // an error counter >= 128
  kBusOff = 3,        // transmit error counter > 255; controller offline until restarted
  kDown = 4,
};

const char* to_string(CanBusState s);

// Accept a frame when (frame.id & mask) == (id & mask) and its ID type equals `extended`.
struct CanFilter {
  std::uint32_t id = 0;
  std::uint32_t mask = 0;
  bool extended = false;
};

// Controller error counters as last reported (0 when the backend cannot know them).
struct CanErrorCounters {
  std::uint16_t tx = 0;
  std::uint16_t rx = 0;
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

class CanBus {
 public:
  virtual ~CanBus() = default;

  // Queues one frame for transmission without blocking.
  // kOk (queued), kWouldBlock (queue full: dropped, counted in tx_dropped_queue_full),
  // kBusOff, kDown (dropped; recovery is attempted in the background of later calls),
  // kInvalidArgument (len > 8 or ID too large for its type), kError.
  virtual CanStatus send(const CanFrame& frame) = 0;

  // Waits up to timeout_ns (0 = poll) for the next data frame passing the filters and fills
  // *frame (t_ns = receive time on CLOCK_MONOTONIC). Error frames are consumed internally and
  // update state(), error_counters() and stats(); they are never returned.
  // kOk, kTimeout, kDown (link down: waits at most timeout_ns for the backend's next reopen
  // attempt, so a receive loop does not spin), kEndOfStream (replay), kError.
  virtual CanStatus receive(CanFrame* frame, std::int64_t timeout_ns) = 0;

  // Replaces the receive filters. count == 0 receives every frame. kOk, kInvalidArgument
  // (too many filters for the backend, max 64), kError. Filters survive a reopen.
  virtual CanStatus set_filters(const CanFilter* filters, std::size_t count) = 0;

  virtual CanBusState state() const = 0;
  virtual CanErrorCounters error_counters() const = 0;
  virtual CanStats stats() const = 0;
  // Human-readable description of the last failure; empty when none.
  virtual const char* last_error() const = 0;
};

inline constexpr std::size_t kMaxCanFilters = 64;

inline const char* to_string(CanStatus s) {
  switch (s) {
    case CanStatus::kOk:
      return "ok";
    case CanStatus::kWouldBlock:
      return "would-block";
    case CanStatus::kTimeout:
      return "timeout";
    case CanStatus::kBusOff:
      return "bus-off";
    case CanStatus::kDown:
      return "down";
    case CanStatus::kInvalidArgument:
      return "invalid-argument";
    case CanStatus::kError:
      return "error";
    case CanStatus::kEndOfStream:
      return "end-of-stream";
  }
  return "?";
}

inline const char* to_string(CanBusState s) {
  switch (s) {
    case CanBusState::kErrorActive:
      return "error-active";
    case CanBusState::kErrorWarning:
      return "error-warning";
    case CanBusState::kErrorPassive:
      return "error-passive";
    case CanBusState::kBusOff:
      return "bus-off";
    case CanBusState::kDown:
      return "down";
  }
  return "?";
}

}  // namespace agv::hal
