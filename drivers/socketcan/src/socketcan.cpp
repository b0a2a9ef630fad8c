#include "agv/can/socketcan.hpp"

#include <linux/can.h>
#include <linux/can/error.h>
#include <linux/can/raw.h>
#include <net/if.h>
#include <poll.h>
#include <sys/ioctl.h>
#include <sys/socket.h>
#include <time.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstring>

namespace agv::can {

namespace {

std::int64_t clock_ns(clockid_t id) {
  timespec ts{};
  clock_gettime(id, &ts);
  return static_cast<std::int64_t>(ts.tv_sec) * 1'000'000'000 + ts.tv_nsec;
}

constexpr can_err_mask_t kErrMask = CAN_ERR_TX_TIMEOUT | CAN_ERR_CRTL | CAN_ERR_PROT | CAN_ERR_TRX |
                                    CAN_ERR_ACK | CAN_ERR_BUSOFF | CAN_ERR_RESTARTED | CAN_ERR_CNT;

}  // namespace

SocketCanBus::SocketCanBus(SocketCanConfig cfg) : cfg_(std::move(cfg)) {
  backoff_ns_ = cfg_.reopen_backoff_min_ns;
  if (!open_socket()) next_attempt_ns_ = clock_ns(CLOCK_MONOTONIC) + backoff_ns_;
}

SocketCanBus::~SocketCanBus() { close_socket(); }

void SocketCanBus::fail(const char* what, int err) {
  last_error_ = cfg_.iface + ": " + what + ": " + std::strerror(err);
}

void SocketCanBus::close_socket() {
  if (fd_ >= 0) {
    ::close(fd_);
    fd_ = -1;
    rx_dropped_base_ += rx_dropped_socket_;
    rx_dropped_socket_ = 0;
  }
}

bool SocketCanBus::open_socket() {
  tracker_.set_down();
  if (cfg_.iface.empty() || cfg_.iface.size() >= IFNAMSIZ) {
    last_error_ = "invalid interface name '" + cfg_.iface + "'";
    return false;
  }
  const int fd = ::socket(PF_CAN, SOCK_RAW | SOCK_NONBLOCK | SOCK_CLOEXEC, CAN_RAW);
  if (fd < 0) {
    fail("socket(PF_CAN)", errno);  // EAFNOSUPPORT: kernel without CAN
    return false;
  }
  ifreq ifr{};
  std::strncpy(ifr.ifr_name, cfg_.iface.c_str(), IFNAMSIZ - 1);
  if (::ioctl(fd, SIOCGIFINDEX, &ifr) < 0) {
    fail("SIOCGIFINDEX", errno);
    ::close(fd);
    return false;
  }
  const int ifindex = ifr.ifr_ifindex;
  if (::ioctl(fd, SIOCGIFFLAGS, &ifr) < 0) {
    fail("SIOCGIFFLAGS", errno);
    ::close(fd);
    return false;
  }
  if ((ifr.ifr_flags & IFF_UP) == 0) {
    last_error_ = cfg_.iface + ": link is down";
    ::close(fd);
    return false;
  }
  const int one = 1;
  const can_err_mask_t err_mask = kErrMask;
  const int own = cfg_.receive_own ? 1 : 0;
  if (::setsockopt(fd, SOL_CAN_RAW, CAN_RAW_ERR_FILTER, &err_mask, sizeof err_mask) < 0 ||
      ::setsockopt(fd, SOL_SOCKET, SO_TIMESTAMPNS, &one, sizeof one) < 0 ||
      ::setsockopt(fd, SOL_CAN_RAW, CAN_RAW_RECV_OWN_MSGS, &own, sizeof own) < 0) {
    fail("setsockopt", errno);
    ::close(fd);
    return false;
  }
  // Best effort: older kernels may lack SO_RXQ_OVFL; drops are then not counted.
  (void)::setsockopt(fd, SOL_SOCKET, SO_RXQ_OVFL, &one, sizeof one);
  if (cfg_.rcvbuf_bytes > 0 && ::setsockopt(fd, SOL_SOCKET, SO_RCVBUFFORCE, &cfg_.rcvbuf_bytes,
                                            sizeof cfg_.rcvbuf_bytes) < 0) {
    // Without CAP_NET_ADMIN: as much as net.core.rmem_max allows (best effort, as above).
    (void)::setsockopt(fd, SOL_SOCKET, SO_RCVBUF, &cfg_.rcvbuf_bytes, sizeof cfg_.rcvbuf_bytes);
  }
  int granted = 0;
  socklen_t granted_len = sizeof granted;
  rcvbuf_granted_bytes_ =
      ::getsockopt(fd, SOL_SOCKET, SO_RCVBUF, &granted, &granted_len) == 0 ? granted : 0;
  if (cfg_.sndbuf_bytes > 0 &&
      ::setsockopt(fd, SOL_SOCKET, SO_SNDBUF, &cfg_.sndbuf_bytes, sizeof cfg_.sndbuf_bytes) < 0) {
    fail("SO_SNDBUF", errno);
    ::close(fd);
    return false;
  }
  sockaddr_can addr{};
  addr.can_family = AF_CAN;
  addr.can_ifindex = ifindex;
  if (::bind(fd, reinterpret_cast<sockaddr*>(&addr), sizeof addr) < 0) {
    fail("bind", errno);
    ::close(fd);
    return false;
  }
  fd_ = fd;
  if (!apply_filters()) {
    close_socket();
    return false;
  }
  if (ever_opened_) ++stats_.restarts;
  ever_opened_ = true;
  tracker_.reset_active();
  backoff_ns_ = cfg_.reopen_backoff_min_ns;
  last_error_.clear();
  return true;
}

bool SocketCanBus::apply_filters() {
  if (fd_ < 0) return true;  // applied on open
  can_filter k[hal::kMaxCanFilters];
  std::size_t n = filters_.size();
  if (n == 0) {  // zero kernel filters would receive nothing: accept all data frames instead
    k[0].can_id = 0;
    k[0].can_mask = CAN_RTR_FLAG;
    n = 1;
  } else {
    for (std::size_t i = 0; i < n; ++i) {
      const hal::CanFilter& f = filters_[i];
      const std::uint32_t idmask = f.extended ? CAN_EFF_MASK : CAN_SFF_MASK;
      k[i].can_id = (f.id & idmask) | (f.extended ? CAN_EFF_FLAG : 0u);
      k[i].can_mask = (f.mask & idmask) | CAN_EFF_FLAG | CAN_RTR_FLAG;
    }
  }
  if (::setsockopt(fd_, SOL_CAN_RAW, CAN_RAW_FILTER, k,
                   static_cast<socklen_t>(n * sizeof(can_filter))) < 0) {
    fail("CAN_RAW_FILTER", errno);
    return false;
  }
  return true;
}

void SocketCanBus::mark_down(const char* what, int err) {
  fail(what, err);
  close_socket();
  tracker_.set_down();
  backoff_ns_ = cfg_.reopen_backoff_min_ns;
  next_attempt_ns_ = clock_ns(CLOCK_MONOTONIC) + backoff_ns_;
}

bool SocketCanBus::ensure_open() {
  if (fd_ >= 0) return true;
  const std::int64_t now = clock_ns(CLOCK_MONOTONIC);
  if (now < next_attempt_ns_) return false;
  if (open_socket()) return true;
  backoff_ns_ =
      next_backoff_ns(backoff_ns_, cfg_.reopen_backoff_min_ns, cfg_.reopen_backoff_max_ns);
  next_attempt_ns_ = now + backoff_ns_;
  return false;
}

std::size_t SocketCanBus::send_batch(const hal::CanFrame* frames, std::size_t count,
                                     hal::CanStatus* status) {
  // Eight frames: more than an output period has (6); longer batches go in several calls.
  constexpr std::size_t kMaxBatch = 8;
  std::size_t ok = 0, i = 0;
  while (i < count) {
    const std::size_t n = std::min(count - i, kMaxBatch);
    bool valid = ensure_open() && tracker_.state() != hal::CanBusState::kBusOff;
    can_frame cf[kMaxBatch] = {};
    iovec iov[kMaxBatch];
    mmsghdr msg[kMaxBatch] = {};
    for (std::size_t k = 0; valid && k < n; ++k) {
      const hal::CanFrame& f = frames[i + k];
      valid = f.len <= 8 && f.id <= (f.extended ? CAN_EFF_MASK : CAN_SFF_MASK);
      cf[k].can_id = f.id | (f.extended ? CAN_EFF_FLAG : 0u);
      cf[k].len = f.len;
      std::memcpy(cf[k].data, f.data, std::min<std::size_t>(f.len, 8));
      iov[k] = {&cf[k], sizeof cf[k]};
      msg[k].msg_hdr.msg_iov = &iov[k];
      msg[k].msg_hdr.msg_iovlen = 1;
    }
    int sent = 0;
    if (valid) {  // otherwise send() below reports each frame's reason
      do {
        sent = ::sendmmsg(fd_, msg, static_cast<unsigned>(n), MSG_DONTWAIT);
      } while (sent < 0 && errno == EINTR);
      sent = std::max(sent, 0);
    }
    for (int k = 0; k < sent; ++k) {
      const bool whole = msg[k].msg_len == sizeof cf[k];
      status[i + static_cast<std::size_t>(k)] =
          whole ? hal::CanStatus::kOk : hal::CanStatus::kError;
      ++(whole ? stats_.tx_ok : stats_.tx_errors);
      if (whole) ++ok;
    }
    for (std::size_t k = static_cast<std::size_t>(sent); k < n; ++k) {
      status[i + k] = send(frames[i + k]);
      if (status[i + k] == hal::CanStatus::kOk) ++ok;
    }
    i += n;
  }
  return ok;
}

hal::CanStatus SocketCanBus::send(const hal::CanFrame& frame) {
  if (frame.len > 8 || frame.id > (frame.extended ? CAN_EFF_MASK : CAN_SFF_MASK)) {
    last_error_ = "invalid frame (len > 8 or ID out of range)";
    return hal::CanStatus::kInvalidArgument;
  }
  if (!ensure_open()) {
    ++stats_.tx_errors;
    return hal::CanStatus::kDown;
  }
  if (tracker_.state() == hal::CanBusState::kBusOff) {
    // Do not queue: frames would leave stale after the restart.
    ++stats_.tx_errors;
    return hal::CanStatus::kBusOff;
  }
  can_frame cf{};
  cf.can_id = frame.id | (frame.extended ? CAN_EFF_FLAG : 0u);
  cf.len = frame.len;
  std::memcpy(cf.data, frame.data, frame.len);
  for (;;) {
    const ssize_t n = ::write(fd_, &cf, sizeof cf);
    if (n == static_cast<ssize_t>(sizeof cf)) {
      ++stats_.tx_ok;
      return hal::CanStatus::kOk;
    }
    const int err = n < 0 ? errno : EIO;
    if (err == EINTR) continue;
    const hal::CanStatus s = status_from_errno(err);
    if (s == hal::CanStatus::kWouldBlock) {
      ++stats_.tx_dropped_queue_full;
      return s;
    }
    ++stats_.tx_errors;
    if (s == hal::CanStatus::kDown) {
      mark_down("write", err);
    } else {
      fail("write", err);
    }
    return s;
  }
}

hal::CanStatus SocketCanBus::receive(hal::CanFrame* frame, std::int64_t timeout_ns) {
  const std::int64_t deadline = clock_ns(CLOCK_MONOTONIC) + (timeout_ns > 0 ? timeout_ns : 0);
  if (!ensure_open()) {
    // Link down: sleep until the next reopen attempt (within the timeout) instead of letting a
    // receive loop spin, then try once.
    const std::int64_t wake = std::min(deadline, next_attempt_ns_);
    if (wake > clock_ns(CLOCK_MONOTONIC)) {
      const timespec ts{static_cast<time_t>(wake / 1'000'000'000),
                        static_cast<long>(wake % 1'000'000'000)};
      ::clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &ts, nullptr);
    }
    if (!ensure_open()) return hal::CanStatus::kDown;
  }
  for (;;) {
    can_frame cf{};
    iovec iov{&cf, sizeof cf};
    alignas(cmsghdr) char ctrl[CMSG_SPACE(sizeof(timespec)) + CMSG_SPACE(sizeof(std::uint32_t))];
    msghdr msg{};
    msg.msg_iov = &iov;
    msg.msg_iovlen = 1;
    msg.msg_control = ctrl;
    msg.msg_controllen = sizeof ctrl;
    const ssize_t n = ::recvmsg(fd_, &msg, MSG_DONTWAIT);
    if (n < 0) {
      const int err = errno;
      if (err == EINTR) continue;
      if (err == EAGAIN || err == EWOULDBLOCK) {
        const std::int64_t left = deadline - clock_ns(CLOCK_MONOTONIC);
        if (left <= 0) return hal::CanStatus::kTimeout;
        pollfd pfd{fd_, POLLIN, 0};
        timespec ts{static_cast<time_t>(left / 1'000'000'000),
                    static_cast<long>(left % 1'000'000'000)};
        const int pr = ::ppoll(&pfd, 1, &ts, nullptr);
        if (pr < 0 && errno != EINTR) {
          fail("ppoll", errno);
          return hal::CanStatus::kError;
        }
        if (pr == 0) return hal::CanStatus::kTimeout;
        continue;  // readable or POLLERR: recvmsg tells which
      }
      if (is_link_gone_errno(err)) {
        mark_down("recvmsg", err);
        return hal::CanStatus::kDown;
      }
      fail("recvmsg", err);
      return hal::CanStatus::kError;
    }
    const std::int64_t mono_a = clock_ns(CLOCK_MONOTONIC);
    const std::int64_t rt_now = clock_ns(CLOCK_REALTIME);
    const std::int64_t mono_b = clock_ns(CLOCK_MONOTONIC);
    std::int64_t t_ns = mono_a + (mono_b - mono_a) / 2;
    for (cmsghdr* c = CMSG_FIRSTHDR(&msg); c != nullptr; c = CMSG_NXTHDR(&msg, c)) {
      if (c->cmsg_level != SOL_SOCKET) continue;
      if (c->cmsg_type == SCM_TIMESTAMPNS) {
        timespec ts{};
        std::memcpy(&ts, CMSG_DATA(c), sizeof ts);
        const std::int64_t stamp =
            static_cast<std::int64_t>(ts.tv_sec) * 1'000'000'000 + ts.tv_nsec;
        t_ns = rx_clock_.to_monotonic_ns(stamp, mono_a, rt_now, mono_b);
      } else if (c->cmsg_type == SO_RXQ_OVFL) {
        std::uint32_t dropped = 0;
        std::memcpy(&dropped, CMSG_DATA(c), sizeof dropped);
        rx_dropped_socket_ = dropped;
      }
    }
    if (n < static_cast<ssize_t>(sizeof cf)) continue;  // truncated: not a classic CAN frame
    if (cf.can_id & CAN_ERR_FLAG) {
      ++stats_.rx_error_frames;
      tracker_.apply(classify_error_frame(cf.can_id, cf.data));
      continue;
    }
    if (cf.can_id & CAN_RTR_FLAG) continue;  // remote frames carry no data for us
    frame->extended = (cf.can_id & CAN_EFF_FLAG) != 0;
    frame->id = cf.can_id & (frame->extended ? CAN_EFF_MASK : CAN_SFF_MASK);
    frame->len = cf.len > 8 ? 8 : cf.len;
    std::memset(frame->data, 0, sizeof frame->data);
    std::memcpy(frame->data, cf.data, frame->len);
    frame->t_ns = t_ns;
    ++stats_.rx_frames;
    return hal::CanStatus::kOk;
  }
}

hal::CanStatus SocketCanBus::set_filters(const hal::CanFilter* filters, std::size_t count) {
  if (count > hal::kMaxCanFilters || (count > 0 && !filters)) {
    last_error_ = "too many filters";
    return hal::CanStatus::kInvalidArgument;
  }
  filters_.assign(filters, filters + count);
  return apply_filters() ? hal::CanStatus::kOk : hal::CanStatus::kError;
}

hal::CanStats SocketCanBus::stats() const {
  hal::CanStats s = stats_;
  s.rx_dropped = rx_dropped_base_ + rx_dropped_socket_;
  s.bus_off_count = tracker_.bus_off_count();
  s.error_passive_count = tracker_.error_passive_count();
  return s;
}

}  // namespace agv::can
