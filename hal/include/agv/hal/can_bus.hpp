// CAN bus interface. Backends: drivers/socketcan (Linux SocketCAN), drivers/fakecan (in-process
// fake for tests), drivers/candump (replay of a `candump -l` log). No Linux headers here.
// Methods are called from the real-time loop: none of them may block longer than the timeout
// it is given (send never blocks).
#pragma once

#include <cstddef>
#include <cstdint>

#include "agv/hal/can_frame.hpp"
#include "agv/hal/can_types.hpp"

namespace agv::hal {

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

const char* to_string(CanBusState s);

// Controller error counters as last reported (0 when the backend cannot know them).
struct CanErrorCounters {
  std::uint16_t tx = 0;
  std::uint16_t rx = 0;
};

class CanBus {
 public:
  virtual ~CanBus() = default;

  // Queues one frame for transmission without blocking.
  // kOk (queued), kWouldBlock (queue full: dropped, counted in tx_dropped_queue_full),
  // kBusOff, kDown (dropped; recovery is attempted in the background of later calls),
  // kInvalidArgument (len > 8 or ID too large for its type), kError.
  virtual CanStatus send(const CanFrame& frame) = 0;

  // Queues frames[0, count) in order, each as send() would, with its result in status[i]; returns
  // how many were kOk. A backend that can hands them to the driver in one system call, so that a
  // preemption cannot separate frames a receiver pairs (one output period's). Default: send()
  // for each (fakes, replay and log backends).
  virtual std::size_t send_batch(const CanFrame* frames, std::size_t count, CanStatus* status) {
    std::size_t ok = 0;
    for (std::size_t i = 0; i < count; ++i) {
      status[i] = send(frames[i]);
      if (status[i] == CanStatus::kOk) ++ok;
    }
    return ok;
  }

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
