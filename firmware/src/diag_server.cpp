#include "diag_server.hpp"

#include <arpa/inet.h>
#include <netdb.h>
#include <netinet/in.h>
#include <png.h>
#include <sys/socket.h>
#include <unistd.h>

#include <cerrno>
#include <chrono>
#include <condition_variable>
#include <cstdio>
#include <cstring>
#include <deque>
#include <functional>
#include <vector>
#ifdef AGV_HAVE_HTTPLIB
#include <httplib.h>
#endif

#include "affinity.hpp"
#include "agv/posix/realtime.hpp"
#include "agv/vision/landmark_localizer.hpp"

namespace agv::app {

#ifdef AGV_HAVE_HTTPLIB
const char* diag_page_html();  // diag_server_page.cpp
#endif

namespace {

#ifdef AGV_HAVE_HTTPLIB
// A slow or silent client holds a worker at most this long per read or write (a slowloris that
// trickles its headers holds one up to the header limit; diag.max_clients bounds how many).
constexpr time_t kReadTimeoutS = 2;
constexpr time_t kWriteTimeoutS = 2;
// GET only: any request body beyond this is refused (413).
constexpr std::size_t kMaxPayloadBytes = 1024;
// How long a frame request waits for the vision thread to copy a fresh frame before it encodes the
// newest one it has (a stalled camera, a finished replay).
constexpr auto kFrameWait = std::chrono::milliseconds(300);

// A body beyond kMaxPayloadBytes, or one whose length is not given in advance (chunked), or a
// Content-Length that is not a number: the page needs no body at all.
bool request_body_too_large(const std::string& content_length, bool has_transfer_encoding) {
  if (has_transfer_encoding) return true;
  if (content_length.empty()) return false;
  if (content_length.size() > 19) return true;
  std::uint64_t n = 0;
  for (const char c : content_length) {
    if (c < '0' || c > '9') return true;
    n = n * 10 + static_cast<std::uint64_t>(c - '0');
  }
  return n > kMaxPayloadBytes;
}

// Set while the accept thread answers a connection over the limit itself: the pre-routing
// handler refuses it (503) without routing.
thread_local bool tl_refuse = false;

// httplib's task queue with a fixed worker count and a bounded backlog. A connection over the
// bound is answered 503 by the accept thread itself (it cannot be dropped: the task owns the
// socket); while it does, further connections wait in the kernel's listen backlog, so memory
// stays bounded whatever the number of clients.
class BoundedQueue : public httplib::TaskQueue {
 public:
  BoundedQueue(std::size_t threads, std::size_t max_pending) : max_pending_(max_pending) {
    for (std::size_t i = 0; i < threads; ++i) {
      workers_.emplace_back([this] { work(); });
    }
  }
  ~BoundedQueue() override { shutdown(); }

  void enqueue(std::function<void()> fn) override {
    {
      std::lock_guard<std::mutex> lock(mutex_);
      if (!stopping_ && pending_.size() < max_pending_) {
        pending_.push_back(std::move(fn));
        cv_.notify_one();
        return;
      }
    }
    tl_refuse = true;
    fn();
    tl_refuse = false;
  }

  void shutdown() override {
    {
      std::lock_guard<std::mutex> lock(mutex_);
      if (stopping_ && workers_.empty()) return;
      stopping_ = true;
    }
    cv_.notify_all();
    for (auto& t : workers_) t.join();
    workers_.clear();
  }

 private:
  void work() {
    while (true) {
      std::function<void()> fn;
      {
        std::unique_lock<std::mutex> lock(mutex_);
        cv_.wait(lock, [this] { return stopping_ || !pending_.empty(); });
        if (pending_.empty()) return;  // stopping and drained: every socket was closed
        fn = std::move(pending_.front());
        pending_.pop_front();
      }
      fn();
    }
  }

  const std::size_t max_pending_;
  std::mutex mutex_;
  std::condition_variable cv_;
  std::deque<std::function<void()>> pending_;
  std::vector<std::thread> workers_;
  bool stopping_ = false;
};

#endif  // AGV_HAVE_HTTPLIB

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

#ifdef AGV_HAVE_HTTPLIB
struct DiagServer::Impl {
  Impl(const config::Config& c, const LandmarkMap* m, DiagHandoff& h, FrameTap& f, const char* md)
      : cfg(c.diag), cpus(c.loop.service_cpus), map(m), handoff(h), frames(f), mode(md) {
    LandmarkGeometry g;
    g.size_mm = c.landmark_size_mm;
    vision::VisionConfig v = c.vision;
    v.now_ns = nullptr;  // the page shows the overlay, not stage timings
    localizer = std::make_unique<vision::LandmarkLocalizer>(v, c.camera_model, g, map);
  }

  // The newest snapshot (copied from the loop's slot only when it changed).
  template <typename Fn>
  std::string with_snapshot(Fn fn) {
    std::lock_guard<std::mutex> lock(snap_mutex);
    if (handoff.take(&snap, &snap_seq)) ++snapshots_taken;
    return fn(snap, stats());
  }

  diag::ServerStats stats() const {
    diag::ServerStats s;
    s.requests = requests.load();
    s.refused_busy = refused_busy.load();
    s.refused_bad = refused_bad.load();
    s.frames_encoded = frames_encoded.load();
    s.snapshots_taken = snapshots_taken.load();
    s.loop_busy_skips = handoff.busy_skips();
    return s;
  }

  // The overlay image: encoded at most once per diag.frame_interval_ms, shared by every client.
  bool frame_png(std::string* png, std::int64_t* t_exposure_ns) {
    std::lock_guard<std::mutex> lock(frame_mutex);
    const auto now = std::chrono::steady_clock::now();
    const auto interval = std::chrono::duration<double, std::milli>(cfg.frame_interval_ms);
    if (png_cache.empty() || now - png_at >= interval) {
      const std::uint64_t before = frames.seq();
      frames.request();
      const auto deadline = now + kFrameWait;
      while (frames.seq() == before && !handoff.finished() &&
             std::chrono::steady_clock::now() < deadline) {
        std::this_thread::sleep_for(std::chrono::milliseconds(5));
      }
      cv::Mat gray, bgr;
      std::int64_t t = 0;
      if (frames.take(&gray, &t) && (t != png_t_ns || png_cache.empty())) {
        vision::LandmarkFix fix;
        localizer->process(gray, &fix);
        localizer->draw_overlay(gray, fix, &bgr);
        std::string encoded;
        if (encode_png(bgr, &encoded)) {
          png_cache = std::move(encoded);
          png_t_ns = t;
          ++frames_encoded;
        }
      }
      png_at = now;
    }
    if (png_cache.empty()) return false;
    *png = png_cache;
    *t_exposure_ns = png_t_ns;
    return true;
  }

  config::DiagSection cfg;
  std::string cpus;  // loop.service_cpus
  const LandmarkMap* map;
  DiagHandoff& handoff;
  FrameTap& frames;
  const char* mode;
  std::unique_ptr<vision::LandmarkLocalizer> localizer;  // frame_mutex
  httplib::Server server;
  std::thread listener;

  std::mutex snap_mutex;
  diag::Snapshot snap;
  std::uint64_t snap_seq = 0;

  std::mutex frame_mutex;
  std::string png_cache;
  std::int64_t png_t_ns = INT64_MIN;
  std::chrono::steady_clock::time_point png_at{};

  std::atomic<std::uint64_t> requests{0}, refused_busy{0}, refused_bad{0}, frames_encoded{0},
      snapshots_taken{0};
};

DiagServer::DiagServer(const config::Config& cfg, const LandmarkMap* map, DiagHandoff& handoff,
                       FrameTap& frames, const char* mode)
    : impl_(std::make_unique<Impl>(cfg, map, handoff, frames, mode)) {}

DiagServer::~DiagServer() { stop(); }

diag::ServerStats DiagServer::stats() const { return impl_->stats(); }

bool DiagServer::start(std::string* error) {
  Impl& m = *impl_;
  if (!is_loopback_address(m.cfg.bind_address) && !m.cfg.allow_remote) {
    *error = "diag.bind_address " + m.cfg.bind_address +
             " is not loopback: the page has no authentication; set diag.allow_remote: true to "
             "serve it on that network";
    return false;
  }
  httplib::Server& s = m.server;
  const auto threads = static_cast<std::size_t>(m.cfg.threads);
  const auto max_clients = static_cast<std::size_t>(m.cfg.max_clients);
  const std::size_t max_pending = max_clients > threads ? max_clients - threads : 1;
  s.new_task_queue = [threads, max_pending] { return new BoundedQueue(threads, max_pending); };
  s.set_keep_alive_max_count(1);  // one request per connection: no idle client holds a worker
  s.set_read_timeout(kReadTimeoutS, 0);
  s.set_write_timeout(kWriteTimeoutS, 0);
  s.set_payload_max_length(kMaxPayloadBytes);
  s.set_pre_routing_handler([](const httplib::Request& req, httplib::Response& res) {
    if (tl_refuse) {
      res.status = 503;
      res.set_header("Retry-After", "1");
      res.set_content("busy: too many diagnostics clients\n", "text/plain");
      return httplib::Server::HandlerResponse::Handled;
    }
    // Decided on the headers, before any body is read: the library reads a body only for the
    // methods that usually carry one, and a GET's not at all (its limit would not apply).
    if (req.method != "GET" && req.method != "HEAD") {
      res.status = 405;
      res.set_header("Allow", "GET, HEAD");
      res.set_content("only GET and HEAD\n", "text/plain");
      return httplib::Server::HandlerResponse::Handled;
    }
    if (request_body_too_large(req.get_header_value("Content-Length"),
                               req.has_header("Transfer-Encoding"))) {
      res.status = 413;
      res.set_content("a request body is at most 1024 bytes\n", "text/plain");
      return httplib::Server::HandlerResponse::Handled;
    }
    return httplib::Server::HandlerResponse::Unhandled;
  });
  s.set_logger([&m](const httplib::Request&, const httplib::Response& res) {
    if (res.status >= 200 && res.status < 300) {
      ++m.requests;
    } else if (res.status == 503) {
      ++m.refused_busy;
    } else if (res.status >= 400) {
      ++m.refused_bad;
    }
  });
  s.set_default_headers({{"Cache-Control", "no-store"}, {"X-Content-Type-Options", "nosniff"}});

  s.Get("/", [](const httplib::Request&, httplib::Response& res) {
    res.set_header("Content-Security-Policy",
                   "default-src 'none'; script-src 'unsafe-inline'; style-src 'unsafe-inline'; "
                   "img-src 'self'; connect-src 'self'");
    res.set_content(diag_page_html(), "text/html; charset=utf-8");
  });
  s.Get("/api/status.json", [&m](const httplib::Request&, httplib::Response& res) {
    res.set_content(m.with_snapshot([&m](const diag::Snapshot& snap, const diag::ServerStats& st) {
      return diag::status_json(snap, st, m.mode);
    }),
                    "application/json");
  });
  s.Get("/api/map.json", [&m](const httplib::Request&, httplib::Response& res) {
    res.set_content(m.with_snapshot([&m](const diag::Snapshot& snap, const diag::ServerStats&) {
      return diag::map_json(m.map, snap);
    }),
                    "application/json");
  });
  s.Get("/metrics", [&m](const httplib::Request&, httplib::Response& res) {
    res.set_content(m.with_snapshot([](const diag::Snapshot& snap, const diag::ServerStats& st) {
      return diag::metrics_text(snap, st);
    }),
                    "text/plain; version=0.0.4; charset=utf-8");
  });
  s.Get("/frame.png", [&m](const httplib::Request&, httplib::Response& res) {
    std::string png;
    std::int64_t t = 0;
    if (!m.frame_png(&png, &t)) {
      res.status = 503;
      res.set_header("Retry-After", "1");
      res.set_content("no camera frame yet\n", "text/plain");
      return;
    }
    res.set_header("X-Frame-Exposure-Ns", std::to_string(t));
    res.set_content(png, "image/png");
  });

  if (m.cfg.port == 0) {
    port_ = s.bind_to_any_port(m.cfg.bind_address);
  } else {
    port_ = s.bind_to_port(m.cfg.bind_address, m.cfg.port) ? m.cfg.port : -1;
  }
  if (port_ <= 0) {
    std::string why = listen_failure_reason(m.cfg.bind_address, m.cfg.port);
    if (why.empty()) why = "the HTTP server could not bind (no error on a second attempt)";
    *error = "diag: cannot listen on " + m.cfg.bind_address + ":" + std::to_string(m.cfg.port) +
             ": " + why;
    port_ = 0;
    return false;
  }
  // The workers are created by the listener (cpp-httplib's task queue), so they inherit its name
  // and CPU set.
  m.listener = std::thread([&s, cpus = m.cpus] {
    posix::set_thread_name("agv-diag");
    pin_this_thread(cpus, "diagnostics page, loop.service_cpus");
    s.listen_after_bind();
  });
  const bool v6 = m.cfg.bind_address.find(':') != std::string::npos;
  std::printf("diag: serving http://%s%s%s:%d/ (%s)\n", v6 ? "[" : "", m.cfg.bind_address.c_str(),
              v6 ? "]" : "", port_, m.mode);
  std::fflush(stdout);
  return true;
}

void DiagServer::stop() {
  if (!impl_->listener.joinable()) return;
  impl_->server.stop();
  impl_->listener.join();
}

#else  // !AGV_HAVE_HTTPLIB

struct DiagServer::Impl {};
DiagServer::DiagServer(const config::Config&, const LandmarkMap*, DiagHandoff&, FrameTap&,
                       const char*) {}
DiagServer::~DiagServer() = default;
diag::ServerStats DiagServer::stats() const { return {}; }
bool DiagServer::start(std::string* error) {
  *error =
      "diag: this agvloc was built without cpp-httplib (libcpp-httplib-dev): no "
      "diagnostics page";
  return false;
}
void DiagServer::stop() {}

#endif  // AGV_HAVE_HTTPLIB

std::string format_diag_counters(const diag::ServerStats& s) {
  char buf[256];
  std::snprintf(buf, sizeof buf,
                "diag: %llu requests, refused %llu busy %llu bad, %llu frames encoded, %llu "
                "snapshots, %llu loop skips\n",
                static_cast<unsigned long long>(s.requests),
                static_cast<unsigned long long>(s.refused_busy),
                static_cast<unsigned long long>(s.refused_bad),
                static_cast<unsigned long long>(s.frames_encoded),
                static_cast<unsigned long long>(s.snapshots_taken),
                static_cast<unsigned long long>(s.loop_busy_skips));
  return buf;
}

}  // namespace agv::app
