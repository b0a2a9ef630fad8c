#include "agv/http/diag_conns.hpp"

#include <sys/ioctl.h>
#include <sys/socket.h>

#include <algorithm>

namespace agv::app {

void DiagConnections::cut(Conn& c) {
  if (c.cut) return;
  c.cut = true;
  --live_;
  ++cuts_;
  ::shutdown(c.fd, SHUT_RDWR);
}

DiagConnections::Conn* DiagConnections::opened(int fd, Clock::time_point now) {
  std::lock_guard<std::mutex> lock(mutex_);
  if (live_ + 1 >= limits_.evict_idle_at) {
    // Bytes waiting unread: a client whose request the library has not read yet, not an idle one
    // (a normal GET accepted just before a burst). Silent ones go first, then ones stalled after
    // their request line: one being parsed right now by another thread has its line seen at most.
    const auto idle = [](const Conn& c, bool allow_line) {
      int pending = 0;
      return !c.cut && !c.requested && (allow_line || !c.line_seen) &&
             (::ioctl(c.fd, FIONREAD, &pending) != 0 || pending == 0);
    };
    for (const bool allow_line : {false, true}) {
      auto it = std::find_if(conns_.begin(), conns_.end(),
                             [&](const Conn& c) { return idle(c, allow_line); });
      if (it != conns_.end()) {
        cut(*it);
        break;
      }
    }
  }
  conns_.push_back(Conn{fd, now});
  ++live_;
  return &conns_.back();
}

void DiagConnections::closed(Conn* c) {
  if (!c) return;
  std::lock_guard<std::mutex> lock(mutex_);
  for (auto it = conns_.begin(); it != conns_.end(); ++it) {
    if (&*it != c) continue;
    if (it->in_progress) --in_progress_;
    if (!it->cut) --live_;
    conns_.erase(it);
    return;
  }
}

bool DiagConnections::begin_request(Conn* c) {
  std::lock_guard<std::mutex> lock(mutex_);
  if (c) c->requested = true;
  if (in_progress_ >= limits_.max_requests) return false;
  if (c && !c->in_progress) {
    c->in_progress = true;
    ++in_progress_;
  }
  return true;
}

void DiagConnections::line_seen(Conn* c) {
  if (!c) return;
  std::lock_guard<std::mutex> lock(mutex_);
  c->line_seen = true;
}

void DiagConnections::end_request(Conn* c) {
  if (!c) return;
  std::lock_guard<std::mutex> lock(mutex_);
  if (c->in_progress) {
    c->in_progress = false;
    --in_progress_;
  }
}

std::size_t DiagConnections::reap(Clock::time_point now) {
  std::lock_guard<std::mutex> lock(mutex_);
  std::size_t n = 0;
  for (Conn& c : conns_) {
    if (c.cut) continue;
    const auto age = now - c.opened;
    if ((!c.requested && age > limits_.header_deadline) || age > limits_.lifetime) {
      cut(c);
      ++n;
    }
  }
  return n;
}

std::size_t DiagConnections::open_count() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return live_;
}

std::uint64_t DiagConnections::cut_count() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return cuts_;
}

}  // namespace agv::app
