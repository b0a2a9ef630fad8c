// The diagnostics HTTP server both products serve their pages and /metrics with (the vehicle's
// agvloc, docs/guide/diagnostics.md, and the site tracker agvloc-overhead, docs/guide/overhead.md):
// GNU libmicrohttpd, event-driven, on a fixed pool of ordinary (not real-time) threads. Bounded
// however many clients connect (docs/design/security.md): a fixed number of polling threads,
// max_clients requests in progress (more answered 503 at once), a fixed memory budget per
// connection, a deadline for a request's headers and for the whole connection, one request per
// connection. What a route answers is the caller's: a handler called on the library's threads.
#pragma once

#include <cstdint>
#include <functional>
#include <memory>
#include <opencv2/core.hpp>
#include <string>
#include <utility>
#include <vector>

#include "agv/http/diag_route.hpp"

namespace agv::app {

// True for an address the page may listen on without allow_remote (loopback).
bool is_loopback_address(const std::string& address);
// Why a TCP listening socket on address:port cannot be opened now, naming the failing call and
// its errno, e.g. "socket(AF_INET): Address family not supported by protocol (EAFNOSUPPORT: ...)"
// or "bind: Address already in use (EADDRINUSE)"; "" when it can. The HTTP library reports only
// that binding failed; HttpServer::start asks this for the reason.
std::string listen_failure_reason(const std::string& address, int port);

// Encodes CV_8UC3 (BGR) or CV_8UC1 as PNG into *out (libpng, in memory). False on error.
bool encode_png(const cv::Mat& image, std::string* out, int compression = 1);

struct HttpServerSettings {
  std::string bind_address = "127.0.0.1";
  int port = 0;  // 0: any free port (port() says which)
  bool allow_remote = false;
  int threads = 1;
  int max_clients = 4;
  // The configuration's prefix, for the errors ("diag.bind_address ...").
  std::string key_prefix = "diag";
};

// The server settings of a diagnostics configuration section: the vehicle's config::DiagSection
// and the overhead application's DiagOutput carry the same five keys (key_prefix stays "diag").
template <class Section>
HttpServerSettings http_settings_of(const Section& d) {
  return {d.bind_address, d.port, d.allow_remote, d.threads, d.max_clients};
}

// What a route answers. The server adds Content-Type, Cache-Control: no-store, nosniff and
// Connection: close.
struct HttpAnswer {
  int camera = -1;  // given to the handler: kCamera's index (diag_camera_index), else -1
  int status = 200;
  std::string body;
  std::string type = "text/plain";
  std::vector<std::pair<const char*, std::string>> headers;
};

struct HttpCounters {
  std::uint64_t requests = 0;      // answered 2xx
  std::uint64_t refused_busy = 0;  // 503: more than max_clients in progress
  std::uint64_t refused_bad = 0;   // 4xx
  std::uint64_t open = 0;          // connections accepted and not yet closed or cut
};

class HttpServer {
 public:
  // Called for kPage, kStatus, kMap, kMetrics, kFrame, kSite and kCamera with *answer holding that
  // route's status (kSite and kCamera: 404 "not found" until the handler answers them); the other
  // routes the server answers itself. On the library's threads, several at once.
  using Handler = std::function<void(DiagRoute route, HttpAnswer* answer)>;
  // Run first on every thread the server starts (to name it, pin it).
  using ThreadStart = std::function<void()>;

  HttpServer(HttpServerSettings settings, Handler handler, ThreadStart thread_start = {});
  ~HttpServer();
  HttpServer(const HttpServer&) = delete;
  HttpServer& operator=(const HttpServer&) = delete;

  // Binds and starts serving. False with *error for a non-loopback address without
  // allow_remote, an address / port that cannot be bound, or a build without libmicrohttpd.
  bool start(std::string* error);
  void stop();
  int port() const;
  HttpCounters counters() const;

  struct Impl;

 private:
  std::unique_ptr<Impl> impl_;
};

}  // namespace agv::app
