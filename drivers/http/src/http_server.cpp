// The diagnostics HTTP server (http_server.hpp).
#include "agv/http/http_server.hpp"

#include <arpa/inet.h>
#include <netdb.h>
#include <netinet/in.h>
#include <netinet/tcp.h>
#include <png.h>
#include <sys/socket.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cerrno>
#include <chrono>
#include <condition_variable>
#include <cstdio>
#include <cstring>
#include <mutex>
#include <string_view>
#include <thread>
#include <utility>
#include <vector>
#ifdef AGV_HAVE_MHD
#include <microhttpd.h>
#endif

#include "agv/http/diag_conns.hpp"

namespace agv::app {

namespace {

#ifdef AGV_HAVE_MHD
// An idle connection is closed after this long without a byte (the library's idle timeout); its
// request must be complete this long after accept whatever it trickles (DiagConnections).
constexpr unsigned kIdleTimeoutS = 2;
constexpr auto kHeaderDeadline = std::chrono::milliseconds(2000);
// The whole connection (one request, its answer written): a frame to a slow browser fits.
constexpr auto kLifetime = std::chrono::milliseconds(10000);
// Per connection, everything the library keeps for it: the request line, every header, the answer's
// headers. A request whose line or headers do not fit is answered 414 / 431 and closed, so header
// count and size are bounded by this before any more memory is spent.
constexpr std::size_t kConnectionMemory = 16 * 1024;
// Connections open beyond diag.max_clients: idle ones are cheap (a socket and kConnectionMemory,
// touched only as far as used) and dropped oldest first near the library's hard limit.
constexpr std::size_t kIdleHeadroom = 64;
constexpr std::size_t kHardHeadroom = 64;
constexpr std::size_t kMaxConnections = 512;
#endif  // AGV_HAVE_MHD

#ifdef AGV_HAVE_MHD
// A connection reaches the library only once its first bytes are in (or after kIdleTimeoutS): a
// normal client's request is then waiting from the moment it is accepted, so it never looks like
// an idle socket to DiagConnections, however long the client or this process is descheduled
// between connect and send, and idle sockets take no library slot until they are old enough to
// be dropped. Best effort: without the option the eviction rules alone apply.
void defer_accept(MHD_Daemon* daemon) {
  const MHD_DaemonInfo* info = MHD_get_daemon_info(daemon, MHD_DAEMON_INFO_LISTEN_FD);
  if (!info) return;
  const int seconds = static_cast<int>(kIdleTimeoutS);
  (void)::setsockopt(info->listen_fd, IPPROTO_TCP, TCP_DEFER_ACCEPT, &seconds, sizeof(seconds));
}
#endif  // AGV_HAVE_MHD

void write_png_data(png_structp png, png_bytep data, png_size_t length) {
  auto* out = static_cast<std::string*>(png_get_io_ptr(png));
  out->append(reinterpret_cast<const char*>(data), length);
}
void flush_png(png_structp) {}

}  // namespace

bool is_loopback_address(const std::string& a) {
  if (a == "localhost") return true;
  in_addr v4{};
  if (inet_pton(AF_INET, a.c_str(), &v4) == 1) return (ntohl(v4.s_addr) >> 24) == 127;
  in6_addr v6{};
  return inet_pton(AF_INET6, a.c_str(), &v6) == 1 && IN6_IS_ADDR_LOOPBACK(&v6);
}

namespace {

std::string errno_text(int e) {
  std::string t = std::strerror(e);
  const char* name = nullptr;
  const char* hint = "";
  switch (e) {
    case EAFNOSUPPORT:
      name = "EAFNOSUPPORT";
      hint =
          ": IPv4/IPv6 sockets not permitted here, e.g. by the service's "
          "RestrictAddressFamilies= without AF_INET AF_INET6";
      break;
    case EADDRINUSE:
      name = "EADDRINUSE";
      hint = ": another process listens on this port";
      break;
    case EADDRNOTAVAIL:
      name = "EADDRNOTAVAIL";
      hint = ": not an address of this host";
      break;
    case EACCES:
      name = "EACCES";
      break;
    case EPERM:
      name = "EPERM";
      break;
    default:
      break;
  }
  if (name) t += std::string(" (") + name + hint + ")";
  return t;
}

}  // namespace

std::string listen_failure_reason(const std::string& address, int port) {
  addrinfo hints{};
  hints.ai_family = AF_UNSPEC;
  hints.ai_socktype = SOCK_STREAM;
  hints.ai_flags = AI_PASSIVE;
  addrinfo* res = nullptr;
  const std::string service = std::to_string(port);
  const int rc =
      getaddrinfo(address.empty() ? nullptr : address.c_str(), service.c_str(), &hints, &res);
  if (rc != 0) return std::string("address ") + address + ": " + gai_strerror(rc);
  std::string reason;
  for (const addrinfo* a = res; a; a = a->ai_next) {
    const int fd = ::socket(a->ai_family, a->ai_socktype, a->ai_protocol);
    if (fd < 0) {
      const int e = errno;
      reason = std::string("socket(") + (a->ai_family == AF_INET6 ? "AF_INET6" : "AF_INET") +
               "): " + errno_text(e);
      continue;
    }
    const int one = 1;  // as the HTTP library: a port in TIME_WAIT is not "in use"
    ::setsockopt(fd, SOL_SOCKET, SO_REUSEADDR, &one, sizeof one);
    const bool bound = ::bind(fd, a->ai_addr, a->ai_addrlen) == 0;
    const int e = errno;
    const bool listening = bound && ::listen(fd, 1) == 0;
    const int le = errno;
    ::close(fd);
    if (listening) {
      reason.clear();
      break;
    }
    reason = bound ? "listen: " + errno_text(le) : "bind: " + errno_text(e);
  }
  freeaddrinfo(res);
  return reason;
}

bool encode_png(const cv::Mat& image, std::string* out, int compression) {
  if (image.empty() || image.depth() != CV_8U || (image.channels() != 1 && image.channels() != 3)) {
    return false;
  }
  out->clear();
  png_structp png = png_create_write_struct(PNG_LIBPNG_VER_STRING, nullptr, nullptr, nullptr);
  if (!png) return false;
  png_infop info = png_create_info_struct(png);
  if (!info) {
    png_destroy_write_struct(&png, nullptr);
    return false;
  }
  // libpng reports errors by longjmp: nothing with a destructor is created below this point.
  if (setjmp(png_jmpbuf(png))) {
    png_destroy_write_struct(&png, &info);
    return false;
  }
  png_set_write_fn(png, out, &write_png_data, &flush_png);
  png_set_compression_level(png, compression);
  png_set_IHDR(png, info, static_cast<png_uint_32>(image.cols),
               static_cast<png_uint_32>(image.rows), 8,
               image.channels() == 3 ? PNG_COLOR_TYPE_RGB : PNG_COLOR_TYPE_GRAY, PNG_INTERLACE_NONE,
               PNG_COMPRESSION_TYPE_DEFAULT, PNG_FILTER_TYPE_DEFAULT);
  png_write_info(png, info);
  if (image.channels() == 3) png_set_bgr(png);
  for (int r = 0; r < image.rows; ++r) {
    png_write_row(png, const_cast<png_bytep>(image.ptr<png_byte>(r)));
  }
  png_write_end(png, nullptr);
  png_destroy_write_struct(&png, &info);
  return true;
}

#ifdef AGV_HAVE_MHD
struct HttpServer::Impl {
  Impl(HttpServerSettings s, Handler h, ThreadStart t)
      : cfg(std::move(s)),
        handler(std::move(h)),
        thread_start(std::move(t)),
        conns(DiagConnLimits{static_cast<std::size_t>(cfg.max_clients),
                             static_cast<std::size_t>(cfg.max_clients) + kIdleHeadroom,
                             kHeaderDeadline, kLifetime}) {}

  MHD_Result answer(MHD_Connection* connection, const char* url, const char* method);
  void reap_loop();
  void on_thread_start() const {
    if (thread_start) thread_start();
  }

  HttpServerSettings cfg;
  Handler handler;
  ThreadStart thread_start;
  MHD_Daemon* daemon = nullptr;
  int port = 0;
  DiagConnections conns;
  std::thread reaper;
  std::mutex reaper_mutex;
  std::condition_variable reaper_cv;
  bool stopping = false;
  std::atomic<std::uint64_t> requests{0}, refused_busy{0}, refused_bad{0};
};

namespace {

std::string_view header(MHD_Connection* c, const char* name) {
  const char* v = MHD_lookup_connection_value(c, MHD_HEADER_KIND, name);
  return v ? std::string_view(v) : std::string_view();
}

DiagConnections::Conn* conn_of(MHD_Connection* c) {
  const MHD_ConnectionInfo* info = MHD_get_connection_info(c, MHD_CONNECTION_INFO_SOCKET_CONTEXT);
  return info ? static_cast<DiagConnections::Conn*>(info->socket_context) : nullptr;
}

void notify_connection(void* cls, MHD_Connection* c, void** socket_context,
                       MHD_ConnectionNotificationCode toe) {
  auto& conns = *static_cast<DiagConnections*>(cls);
  if (toe == MHD_CONNECTION_NOTIFY_STARTED) {
    const MHD_ConnectionInfo* info = MHD_get_connection_info(c, MHD_CONNECTION_INFO_CONNECTION_FD);
    *socket_context =
        info ? conns.opened(info->connect_fd, DiagConnections::Clock::now()) : nullptr;
  } else {
    conns.closed(static_cast<DiagConnections::Conn*>(*socket_context));
    *socket_context = nullptr;
  }
}

void request_completed(void* cls, MHD_Connection* c, void**, MHD_RequestTerminationCode) {
  static_cast<DiagConnections*>(cls)->end_request(conn_of(c));
}

// The request line is in: the connection is talking, not idle.
void* uri_seen(void* cls, const char*, MHD_Connection* c) {
  static_cast<DiagConnections*>(cls)->line_seen(conn_of(c));
  return nullptr;
}

MHD_Result access_handler(void* cls, MHD_Connection* c, const char* url, const char* method,
                          const char*, const char*, size_t*, void**) {
  return static_cast<HttpServer::Impl*>(cls)->answer(c, url, method);
}

bool resolve_bind(const std::string& address, int port, sockaddr_storage* out, socklen_t* len) {
  addrinfo hints{};
  hints.ai_family = AF_UNSPEC;
  hints.ai_socktype = SOCK_STREAM;
  hints.ai_flags = AI_PASSIVE;
  addrinfo* res = nullptr;
  const std::string service = std::to_string(port);
  if (getaddrinfo(address.empty() ? nullptr : address.c_str(), service.c_str(), &hints, &res) !=
      0) {
    return false;
  }
  std::memcpy(out, res->ai_addr, res->ai_addrlen);
  *len = res->ai_addrlen;
  freeaddrinfo(res);
  return true;
}

}  // namespace

// Called once per request, its headers in and no body read: every answer is decided here (the
// page reads no body; one left unread closes the connection after the answer).
MHD_Result HttpServer::Impl::answer(MHD_Connection* c, const char* url, const char* method) {
  DiagRequestHead head;
  head.method = method;
  head.path = url;
  head.content_length = header(c, MHD_HTTP_HEADER_CONTENT_LENGTH);
  head.has_transfer_encoding =
      MHD_lookup_connection_value(c, MHD_HEADER_KIND, MHD_HTTP_HEADER_TRANSFER_ENCODING);
  head.busy = !conns.begin_request(conn_of(c));
  const DiagRoute route = route_diag_request(head);
  HttpAnswer a;
  a.status = diag_route_status(route);
  switch (route) {
    case DiagRoute::kPage:
    case DiagRoute::kStatus:
    case DiagRoute::kMap:
    case DiagRoute::kMetrics:
    case DiagRoute::kFrame:
      handler(route, &a);
      break;
    case DiagRoute::kSite:
    case DiagRoute::kCamera:
      a.body = "not found\n";  // unless the handler serves it
      a.camera = diag_camera_index(head.path);
      handler(route, &a);
      break;
    case DiagRoute::kNotFound:
      a.body = "not found\n";
      break;
    case DiagRoute::kMethodNotAllowed:
      a.body = "only GET and HEAD\n";
      a.headers.emplace_back("Allow", "GET, HEAD");
      break;
    case DiagRoute::kBodyTooLarge:
      a.body = "a request body is at most 1024 bytes\n";
      break;
    case DiagRoute::kBusy:
      a.body = "busy: too many diagnostics clients\n";
      a.headers.emplace_back("Retry-After", "1");
      break;
  }
  if (a.status >= 200 && a.status < 300) {
    ++requests;
  } else if (a.status == 503 && route == DiagRoute::kBusy) {
    ++refused_busy;
  } else if (a.status >= 400 && a.status != 503) {
    ++refused_bad;
  }
  MHD_Response* r =
      MHD_create_response_from_buffer(a.body.size(), a.body.data(), MHD_RESPMEM_MUST_COPY);
  if (!r) return MHD_NO;
  MHD_add_response_header(r, MHD_HTTP_HEADER_CONTENT_TYPE, a.type.c_str());
  MHD_add_response_header(r, MHD_HTTP_HEADER_CACHE_CONTROL, "no-store");
  MHD_add_response_header(r, "X-Content-Type-Options", "nosniff");
  // One request per connection: no client holds a connection between requests.
  MHD_add_response_header(r, MHD_HTTP_HEADER_CONNECTION, "close");
  for (const auto& [name, value] : a.headers) MHD_add_response_header(r, name, value.c_str());
  const MHD_Result ok = MHD_queue_response(c, static_cast<unsigned>(a.status), r);
  MHD_destroy_response(r);
  return ok;
}

void HttpServer::Impl::reap_loop() {
  std::unique_lock<std::mutex> lock(reaper_mutex);
  while (!reaper_cv.wait_for(lock, std::chrono::milliseconds(100), [this] { return stopping; })) {
    conns.reap(DiagConnections::Clock::now());
  }
}

HttpServer::HttpServer(HttpServerSettings settings, Handler handler, ThreadStart thread_start)
    : impl_(std::make_unique<Impl>(std::move(settings), std::move(handler),
                                   std::move(thread_start))) {}

HttpServer::~HttpServer() { stop(); }

int HttpServer::port() const { return impl_->port; }

HttpCounters HttpServer::counters() const {
  return {impl_->requests.load(), impl_->refused_busy.load(), impl_->refused_bad.load(),
          impl_->conns.open_count()};
}

bool HttpServer::start(std::string* error) {
  Impl& m = *impl_;
  const std::string& p = m.cfg.key_prefix;
  if (!is_loopback_address(m.cfg.bind_address) && !m.cfg.allow_remote) {
    *error = p + ".bind_address " + m.cfg.bind_address +
             " is not loopback: the page has no authentication; set " + p +
             ".allow_remote: true to serve it on that network";
    return false;
  }
  sockaddr_storage addr{};
  socklen_t addr_len = 0;
  const std::string why_not = listen_failure_reason(m.cfg.bind_address, m.cfg.port);
  if (!why_not.empty() || !resolve_bind(m.cfg.bind_address, m.cfg.port, &addr, &addr_len)) {
    *error = p + ": cannot listen on " + m.cfg.bind_address + ":" + std::to_string(m.cfg.port) +
             ": " + (why_not.empty() ? std::string("address not resolved") : why_not);
    return false;
  }
  unsigned flags = MHD_USE_INTERNAL_POLLING_THREAD | MHD_USE_EPOLL;
  if (addr.ss_family == AF_INET6) flags |= MHD_USE_IPv6;
  // The library splits its limit evenly between its threads, and one thread at its share stops
  // accepting: each share must be above the level at which idle connections are dropped, or a
  // normal client could wait behind idle ones. Capped well below the process's file limit.
  const auto threads = static_cast<std::size_t>(m.cfg.threads);
  const auto hard_limit = static_cast<unsigned>(std::min<std::size_t>(
      kMaxConnections,
      (static_cast<std::size_t>(m.cfg.max_clients) + kIdleHeadroom) * threads + kHardHeadroom));
  // The library's threads inherit the creating thread's name and CPU set.
  std::thread starter([&] {
    m.on_thread_start();
    m.daemon = MHD_start_daemon(
        flags, 0, nullptr, nullptr, &access_handler, &m, MHD_OPTION_SOCK_ADDR, &addr,
        MHD_OPTION_CONNECTION_LIMIT, hard_limit, MHD_OPTION_CONNECTION_TIMEOUT, kIdleTimeoutS,
        MHD_OPTION_CONNECTION_MEMORY_LIMIT, kConnectionMemory, MHD_OPTION_THREAD_POOL_SIZE,
        static_cast<unsigned>(m.cfg.threads), MHD_OPTION_NOTIFY_CONNECTION, &notify_connection,
        &m.conns, MHD_OPTION_NOTIFY_COMPLETED, &request_completed, &m.conns,
        MHD_OPTION_URI_LOG_CALLBACK, &uri_seen, &m.conns, MHD_OPTION_END);
  });
  starter.join();
  if (!m.daemon) {
    *error = p + ": cannot listen on " + m.cfg.bind_address + ":" + std::to_string(m.cfg.port) +
             ": the HTTP server did not start";
    return false;
  }
  const MHD_DaemonInfo* info = MHD_get_daemon_info(m.daemon, MHD_DAEMON_INFO_BIND_PORT);
  m.port = info ? info->port : 0;
  defer_accept(m.daemon);
  m.stopping = false;
  m.reaper = std::thread([&m] {
    m.on_thread_start();
    m.reap_loop();
  });
  return true;
}

void HttpServer::stop() {
  Impl& m = *impl_;
  if (!m.daemon) return;
  {
    std::lock_guard<std::mutex> lock(m.reaper_mutex);
    m.stopping = true;
  }
  m.reaper_cv.notify_all();
  if (m.reaper.joinable()) m.reaper.join();
  MHD_stop_daemon(m.daemon);
  m.daemon = nullptr;
}

#else  // !AGV_HAVE_MHD

struct HttpServer::Impl {};
HttpServer::HttpServer(HttpServerSettings, Handler, ThreadStart) {}
HttpServer::~HttpServer() = default;
int HttpServer::port() const { return 0; }
HttpCounters HttpServer::counters() const { return {}; }
bool HttpServer::start(std::string* error) {
  *error =
      "diag: this binary was built without GNU libmicrohttpd (libmicrohttpd-dev): no "
      "diagnostics page";
  return false;
}
void HttpServer::stop() {}

#endif  // AGV_HAVE_MHD

}  // namespace agv::app
