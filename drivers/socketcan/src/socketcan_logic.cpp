#include "agv/can/socketcan_logic.hpp"

#include <linux/can.h>
#include <linux/can/error.h>

#include <algorithm>
#include <cerrno>

namespace agv::can {

ErrorFrameInfo classify_error_frame(std::uint32_t can_id, const std::uint8_t data[8]) {
  ErrorFrameInfo e;
  const std::uint32_t c = can_id & CAN_ERR_MASK;
  e.tx_timeout = (c & CAN_ERR_TX_TIMEOUT) != 0;
  e.lost_arbitration = (c & CAN_ERR_LOSTARB) != 0;
  e.controller = (c & CAN_ERR_CRTL) != 0;
  if (e.controller) {
    const std::uint8_t d1 = data[1];
    e.rx_overflow = (d1 & CAN_ERR_CRTL_RX_OVERFLOW) != 0;
    e.tx_overflow = (d1 & CAN_ERR_CRTL_TX_OVERFLOW) != 0;
    e.warning = (d1 & (CAN_ERR_CRTL_RX_WARNING | CAN_ERR_CRTL_TX_WARNING)) != 0;
    e.passive = (d1 & (CAN_ERR_CRTL_RX_PASSIVE | CAN_ERR_CRTL_TX_PASSIVE)) != 0;
    e.back_to_active = (d1 & CAN_ERR_CRTL_ACTIVE) != 0;
  }
  e.protocol = (c & CAN_ERR_PROT) != 0;
  e.transceiver = (c & CAN_ERR_TRX) != 0;
  e.no_ack = (c & CAN_ERR_ACK) != 0;
  e.bus_off = (c & CAN_ERR_BUSOFF) != 0;
  e.bus_error = (c & CAN_ERR_BUSERROR) != 0;
  e.restarted = (c & CAN_ERR_RESTARTED) != 0;
  // CAN_ERR_CNT (kernel >= 5.19) marks data[6..7] valid; older drivers filled them in
  // controller-state frames without the flag, so accept non-zero counters there too.
  if ((c & CAN_ERR_CNT) != 0 || (e.controller && (data[6] | data[7]) != 0)) {
    e.has_counters = true;
    e.tx_errors = data[6];
    e.rx_errors = data[7];
  }
  return e;
}

void BusStateTracker::apply(const ErrorFrameInfo& e) {
  if (e.has_counters) counters_ = {e.tx_errors, e.rx_errors};
  if (state_ == hal::CanBusState::kDown) return;  // only a reopen leaves "down"
  hal::CanBusState next = state_;
  if (e.bus_off) {
    next = hal::CanBusState::kBusOff;
  } else if (e.restarted) {
    next = hal::CanBusState::kErrorActive;
    counters_ = {};
  } else if (e.controller) {
    if (e.passive) {
      next = hal::CanBusState::kErrorPassive;
    } else if (e.warning) {
      next = hal::CanBusState::kErrorWarning;
    } else if (e.back_to_active) {
      next = hal::CanBusState::kErrorActive;
    }
  }
  if (next == hal::CanBusState::kBusOff && state_ != hal::CanBusState::kBusOff) ++bus_off_count_;
  if (next == hal::CanBusState::kErrorPassive && state_ != hal::CanBusState::kErrorPassive) {
    ++error_passive_count_;
  }
  state_ = next;
}

hal::CanStatus status_from_errno(int err) {
  switch (err) {
    case EAGAIN:
#if EWOULDBLOCK != EAGAIN
    case EWOULDBLOCK:
#endif
    case ENOBUFS:
      return hal::CanStatus::kWouldBlock;
    case ENETDOWN:
    case ENODEV:
    case ENXIO:
      return hal::CanStatus::kDown;
    case EINVAL:
    case EMSGSIZE:
      return hal::CanStatus::kInvalidArgument;
    default:
      return hal::CanStatus::kError;
  }
}

bool is_link_gone_errno(int err) { return status_from_errno(err) == hal::CanStatus::kDown; }

std::int64_t RxStampClock::to_monotonic_ns(std::int64_t stamp_rt_ns, std::int64_t mono_a_ns,
                                           std::int64_t rt_now_ns, std::int64_t mono_b_ns) {
  const std::int64_t offset_ns = (mono_a_ns + (mono_b_ns - mono_a_ns) / 2) - rt_now_ns;
  std::int64_t t = std::min(stamp_rt_ns + offset_ns, mono_b_ns);
  if (have_last_) t = std::max(t, last_ns_ + 1);
  have_last_ = true;
  last_ns_ = t;
  return t;
}

std::int64_t next_backoff_ns(std::int64_t current_ns, std::int64_t min_ns, std::int64_t max_ns) {
  if (current_ns < min_ns) return min_ns;
  if (current_ns > max_ns / 2) return max_ns;
  return current_ns * 2;
}

}  // namespace agv::can
