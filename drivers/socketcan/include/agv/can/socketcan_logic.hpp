// The socket-free logic of the SocketCAN driver, unit-tested on machines without AF_CAN:
// error-frame classification, bus-state tracking, errno mapping, timestamp conversion, backoff.
#pragma once

#include <cstdint>

#include "agv/hal/can_bus.hpp"

namespace agv::can {

// What one SocketCAN error frame (can_id & CAN_ERR_FLAG) says (linux/can/error.h).
struct ErrorFrameInfo {
  bool tx_timeout = false;
  bool lost_arbitration = false;
  bool controller = false;   // CAN_ERR_CRTL: see the flags below
  bool rx_overflow = false;  // controller buffer overflows
  bool tx_overflow = false;
  bool warning = false;         // rx or tx counter reached 96
  bool passive = false;         // rx or tx counter reached 128
  bool back_to_active = false;  // CAN_ERR_CRTL_ACTIVE
  bool protocol = false;        // CAN_ERR_PROT (bit, form, stuff errors)
  bool transceiver = false;     // CAN_ERR_TRX (wiring)
  bool no_ack = false;          // CAN_ERR_ACK: nobody acknowledged (alone on the bus)
  bool bus_off = false;
  bool bus_error = false;
  bool restarted = false;
  bool has_counters = false;  // data[6] = tx, data[7] = rx error counter
  std::uint8_t tx_errors = 0;
  std::uint8_t rx_errors = 0;
};

// can_id is the raw SocketCAN can_id (flag bits included); data has 8 bytes.
ErrorFrameInfo classify_error_frame(std::uint32_t can_id, const std::uint8_t data[8]);

// Bus state from successive error frames. Counts transitions into bus-off and error-passive.
class BusStateTracker {
 public:
  void apply(const ErrorFrameInfo& e);
  void set_down() { state_ = hal::CanBusState::kDown; }
  void reset_active() {  // after a successful (re)open
    state_ = hal::CanBusState::kErrorActive;
    counters_ = {};
  }
  hal::CanBusState state() const { return state_; }
  hal::CanErrorCounters counters() const { return counters_; }
  std::uint64_t bus_off_count() const { return bus_off_count_; }
  std::uint64_t error_passive_count() const { return error_passive_count_; }

 private:
  hal::CanBusState state_ = hal::CanBusState::kDown;
  hal::CanErrorCounters counters_;
  std::uint64_t bus_off_count_ = 0;
  std::uint64_t error_passive_count_ = 0;
};

// errno of a failed write()/recvmsg() -> status. EAGAIN/EWOULDBLOCK/ENOBUFS: kWouldBlock (the
// queue is full; never wait); ENETDOWN/ENODEV/ENXIO: kDown (reopen); EINVAL/EMSGSIZE:
// kInvalidArgument; others kError.
hal::CanStatus status_from_errno(int err);
bool is_link_gone_errno(int err);

// SO_TIMESTAMPNS stamps are CLOCK_REALTIME. The driver reads both clocks right after recvmsg()
// and shifts the stamp by their difference: mono = stamp_rt + (mono_now - rt_now), mono_now the
// middle of the two monotonic reads around the realtime one. The result is clamped to the last
// monotonic read (a receive cannot be in the future; guards against a realtime step between the
// stamp and the clock reads). Error: the realtime slew/step between the kernel stamp and the
// read, normally well below a microsecond.
//
// RxStampClock: the receive stamps of one socket on the monotonic clock, converted as above. The
// kernel queues a socket's frames in the order it stamps them, so their times must not decrease;
// but the conversion reads the two clocks per frame, and a thread descheduled between those reads
// (milliseconds on a loaded machine or an emulated VM) shifts mono_now by half the delay. A frame
// of a burst could then be stamped before the one received just before it, and the odometry
// decoder rejected it as stale: a valid frame lost (seen once in hil_link_flap under load). So a
// stamp is always after the previous frame's, by at least 1 ns: two frames are two events, and
// a stamp equal to the previous one was still a lost sample (the filter takes odometry only
// strictly after its newest) and a recording that replay refused (hil_garbage under load: two
// odometry rows with the same t_ns).
class RxStampClock {
 public:
  // mono_a_ns, rt_now_ns, mono_b_ns: the clocks read in that order after recvmsg().
  std::int64_t to_monotonic_ns(std::int64_t stamp_rt_ns, std::int64_t mono_a_ns,
                               std::int64_t rt_now_ns, std::int64_t mono_b_ns);

 private:
  bool have_last_ = false;
  std::int64_t last_ns_ = 0;
};

// Reopen backoff: doubles from min_ns up to max_ns.
std::int64_t next_backoff_ns(std::int64_t current_ns, std::int64_t min_ns, std::int64_t max_ns);

}  // namespace agv::can
