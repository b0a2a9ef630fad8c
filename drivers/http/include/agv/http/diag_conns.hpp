// The diagnostics page's accounting of its connections, apart from the HTTP library so that the
// limits it cannot express are enforced here (docs/design/security.md "Diagnostics page"):
//  - a total deadline for a request's headers from the moment of accept (the library's own
//    timeout is an idle one, which a client sending a byte a second never reaches);
//  - a total lifetime of a connection;
//  - near the connection limit, the oldest connection that has not sent a complete request and
//    has nothing waiting to be read is dropped for a new one, so idle sockets cannot lock a normal
//    client out;
//  - at most max_requests requests in progress; more are answered 503 (decided, not waited for).
// A connection is cut by shutdown(2) on its socket: the library notices on its next poll and
// closes it itself. Every call is made from the library's threads and the reaper, under one mutex;
// the library reports a connection closed before it closes the socket, so a socket cut here is
// always still the connection's.
#pragma once

#include <chrono>
#include <cstddef>
#include <cstdint>
#include <list>
#include <mutex>

namespace agv::app {

struct DiagConnLimits {
  std::size_t max_requests = 16;   // diag.max_clients
  std::size_t evict_idle_at = 80;  // connections open at which the oldest idle one is dropped
  std::chrono::milliseconds header_deadline{2000};
  std::chrono::milliseconds lifetime{10000};
};

class DiagConnections {
 public:
  using Clock = std::chrono::steady_clock;
  struct Conn {
    int fd = -1;
    Clock::time_point opened;
    bool line_seen = false;    // its request line is in
    bool requested = false;    // its headers are in
    bool in_progress = false;  // counted in requests_in_progress
    bool cut = false;          // shut down here, not yet closed by the library
  };

  explicit DiagConnections(const DiagConnLimits& limits) : limits_(limits) {}

  // A connection accepted: its context for the calls below.
  Conn* opened(int fd, Clock::time_point now);
  void closed(Conn* c);
  void line_seen(Conn* c);
  // Its headers are in: false when max_requests requests are in progress (answer 503).
  bool begin_request(Conn* c);
  void end_request(Conn* c);
  // Cuts the connections past their deadlines; returns how many.
  std::size_t reap(Clock::time_point now);

  std::size_t open_count() const;
  std::uint64_t cut_count() const;

 private:
  void cut(Conn& c);

  const DiagConnLimits limits_;
  mutable std::mutex mutex_;
  std::list<Conn> conns_;  // oldest first
  std::size_t in_progress_ = 0;
  std::size_t live_ = 0;  // open and not cut
  std::uint64_t cuts_ = 0;
};

}  // namespace agv::app
