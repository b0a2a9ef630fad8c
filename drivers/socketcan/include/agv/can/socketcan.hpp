// Linux SocketCAN backend of agv::hal::CanBus (docs/guide/can.md, "SocketCAN driver").
//  - raw socket (PF_CAN, SOCK_RAW, CAN_RAW), non-blocking: send() never waits; a full queue
//    (EAGAIN/ENOBUFS) drops the frame and counts it (stale localisation data is worthless).
//  - receive filters with CAN_RAW_FILTER (ID type and no-RTR are part of every filter).
//  - kernel receive timestamps (SO_TIMESTAMPNS, CLOCK_REALTIME) converted to CLOCK_MONOTONIC
//    (socketcan_logic.hpp); kernel receive-queue overflows via SO_RXQ_OVFL -> stats.rx_dropped.
//  - error frames (CAN_RAW_ERR_FILTER: controller problems, bus-off, restarted, protocol,
//    transceiver, no-ACK, TX timeout) update state(), error_counters() and stats().
//  - link down (ENETDOWN/ENODEV/ENXIO): the socket is closed, state() is kDown, and later
//    send()/receive() calls reopen it with exponential backoff once the link is up again
//    (stats.restarts counts successful reopens).
// Not thread-safe: one owner (the real-time loop).
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "agv/can/socketcan_logic.hpp"
#include "agv/hal/can_bus.hpp"

namespace agv::can {

struct SocketCanConfig {
  std::string iface = "can0";
  // SO_SNDBUF in bytes; 0 keeps the kernel default. Smaller: fewer frames wait in the socket
  // (lower worst-case latency of what does get out) but earlier kWouldBlock under bursts.
  int sndbuf_bytes = 0;
  // Receive buffer requested in bytes (SO_RCVBUFFORCE, which needs CAP_NET_ADMIN, else
  // SO_RCVBUF, which the kernel caps at net.core.rmem_max); 0 keeps the kernel default. The
  // kernel charges ~0.75 kB per queued CAN frame, so its default (208 kB) holds 278 frames
  // (measured in the VM): a loop starved for a second at a few hundred input frames per second
  // would lose odometry. 1 MiB (the kernel doubles it) holds seconds of every input agvloc takes;
  // the memory is used only while frames wait. Past it frames are still dropped, and counted
  // (stats.rx_dropped, learned from the next frame received).
  int rcvbuf_bytes = 1 << 20;
  // Reopen backoff after the link went down: doubles from min to max. The max is the driver's
  // restart time: the first pose after the link returns leaves at most this plus one output
  // period later. An attempt is a socket() and two ioctl()s (microseconds), so polling at 10 Hz
  // while the link is down costs nothing measurable; the old 2 s cap delayed the first pose by
  // up to 2 s after the link came back (HIL link_flap: 1.16-1.19 s).
  std::int64_t reopen_backoff_min_ns = 20'000'000;   // 20 ms
  std::int64_t reopen_backoff_max_ns = 100'000'000;  // 100 ms
  // Also receive the frames this socket sends (CAN_RAW_RECV_OWN_MSGS). Tests only.
  bool receive_own = false;
};

class SocketCanBus : public hal::CanBus {
 public:
  // Tries to open at once. If that fails (no AF_CAN, no such interface, link down) the object
  // is still usable: state() is kDown, last_error() says why, and later calls retry.
  explicit SocketCanBus(SocketCanConfig cfg);
  ~SocketCanBus() override;
  SocketCanBus(const SocketCanBus&) = delete;
  SocketCanBus& operator=(const SocketCanBus&) = delete;

  hal::CanStatus send(const hal::CanFrame& frame) override;
  // One sendmmsg for the frames; after a partial one, the rest frame by frame (send()), which
  // gives each its own status.
  std::size_t send_batch(const hal::CanFrame* frames, std::size_t count,
                         hal::CanStatus* status) override;
  hal::CanStatus receive(hal::CanFrame* frame, std::int64_t timeout_ns) override;
  hal::CanStatus set_filters(const hal::CanFilter* filters, std::size_t count) override;
  hal::CanBusState state() const override { return tracker_.state(); }
  hal::CanErrorCounters error_counters() const override { return tracker_.counters(); }
  hal::CanStats stats() const override;
  const char* last_error() const override { return last_error_.c_str(); }

  bool is_open() const { return fd_ >= 0; }
  // The receive buffer the kernel granted at the last open (SO_RCVBUF read back), 0 if never open.
  int receive_buffer_bytes() const { return rcvbuf_granted_bytes_; }
  const SocketCanConfig& config() const { return cfg_; }

 private:
  bool open_socket();  // true when open and bound
  void close_socket();
  void mark_down(const char* what, int err);
  bool ensure_open();  // reopens when the backoff has expired
  bool apply_filters();
  void fail(const char* what, int err);

  SocketCanConfig cfg_;
  int fd_ = -1;
  bool ever_opened_ = false;
  std::int64_t next_attempt_ns_ = 0;
  std::int64_t backoff_ns_ = 0;
  std::vector<hal::CanFilter> filters_;
  BusStateTracker tracker_;
  hal::CanStats stats_;
  std::uint64_t rx_dropped_base_ = 0;  // SO_RXQ_OVFL is per socket: carried over a reopen
  std::uint32_t rx_dropped_socket_ = 0;
  int rcvbuf_granted_bytes_ = 0;
  RxStampClock rx_clock_;  // kept across reopens: receive times never go back
  std::string last_error_;
};

}  // namespace agv::can
