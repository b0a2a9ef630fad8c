// The live diagnostics page and /metrics (docs/guide/diagnostics.md), served by the shared
// diagnostics HTTP server (drivers/http: GNU libmicrohttpd, event-driven, on a fixed pool of
// ordinary, not real-time, threads). It reads the loop only through DiagHandoff and FrameTap
// (diag_handoff.hpp); pure encodings are algo/src/diag.
// Bounded however many clients connect (docs/design/security.md): diag.threads polling threads,
// diag.max_clients requests in progress (more answered 503 at once), a fixed memory budget per
// connection, a deadline for a request's headers and for the whole connection, one request per
// connection, the camera image encoded at most once per diag.frame_interval_ms and shared.
#pragma once

#include <atomic>
#include <cstdint>
#include <memory>
#include <mutex>
#include <opencv2/core.hpp>
#include <string>
#include <thread>

#include "agv/common/landmark.hpp"
#include "agv/config/config.hpp"
#include "agv/diag/diag.hpp"
#include "agv/http/http_server.hpp"
#include "diag_handoff.hpp"

namespace agv::app {

class DiagServer {
 public:
  // mode: "run" or "replay" (shown on the page). map: the landmarks to draw (null: none); must
  // outlive the server.
  DiagServer(const config::Config& cfg, const LandmarkMap* map, DiagHandoff& handoff,
             FrameTap& frames, const char* mode);
  ~DiagServer();
  DiagServer(const DiagServer&) = delete;
  DiagServer& operator=(const DiagServer&) = delete;

  // Binds and starts serving. False with *error for a non-loopback address without
  // diag.allow_remote, or an address / port that cannot be bound.
  bool start(std::string* error);
  void stop();
  int port() const { return port_; }
  diag::ServerStats stats() const;

  struct Impl;

 private:
  std::unique_ptr<Impl> impl_;
  int port_ = 0;
};

// One summary line: "diag: N requests, ...".
std::string format_diag_counters(const diag::ServerStats& s);

}  // namespace agv::app
