// agvloc-overhead's diagnostics page and Prometheus /metrics (docs/guide/overhead.md
// "Diagnostics"), on the HTTP server the vehicle's page uses (drivers/http): per camera its
// frames, frame rate, drops, faults and clock mapping; per vehicle its track state, sigma, the age
// of its last fix and whether that fix came from the tag or the tray. The live loop hands a view
// over at every publish tick; the server's threads only read the newest view.
#pragma once

#include <cstdint>
#include <mutex>
#include <string>
#include <vector>

#include "agv/http/http_server.hpp"
#include "agv/overhead/tracker.hpp"
#include "agv/site/site.hpp"
#include "config.hpp"
#include "live_feed.hpp"

namespace agv::overhead_app {

using app::DiagRoute;
using app::HttpAnswer;
using app::HttpCounters;
using app::HttpServer;
using app::HttpServerSettings;

struct CameraDiag {
  std::string id;
  CameraHealth health;
  double fps = 0.0;  // frames taken over the last second or so
};

struct AgvDiag {
  std::string id;
  overhead::TrackOutput track;  // at the view's time
  const char* source = "";      // the last fix: "tag", "tray", or "" when there is no track
};

struct DiagView {
  std::int64_t t_ns = 0;  // the publish tick (CLOCK_MONOTONIC)
  std::uint64_t ticks = 0, ticks_skipped = 0, frames = 0, frames_dropped = 0;
  std::vector<CameraDiag> cameras;
  std::vector<AgvDiag> agvs;
};

// /metrics: Prometheus text exposition format 0.0.4.
std::string overhead_metrics_text(const DiagView& v, const HttpCounters& http);
// /api/status.json: the same figures for the page.
std::string overhead_status_json(const DiagView& v);

class OverheadDiag {
 public:
  explicit OverheadDiag(const DiagOutput& cfg);
  OverheadDiag(const OverheadDiag&) = delete;
  OverheadDiag& operator=(const OverheadDiag&) = delete;

  // False with *error for a non-loopback address without diag.allow_remote, an address that
  // cannot be bound, or a build without libmicrohttpd.
  bool start(std::string* error);
  void stop() { http_.stop(); }
  int port() const { return http_.port(); }
  void update(DiagView v);

 private:
  void answer(DiagRoute route, HttpAnswer* a);

  std::mutex mutex_;
  DiagView view_;
  HttpServer http_;  // last: stopped before the view it reads is destroyed
};

}  // namespace agv::overhead_app
