// agvloc-overhead's diagnostics page and Prometheus /metrics (docs/guide/overhead.md
// "Diagnostics"), on the HTTP server the vehicle's page uses (drivers/http): per camera its
// frames, frame rate, drops, faults and clock mapping; per vehicle its track state, sigma, the age
// of its last fix and whether that fix came from the tag or the tray; each camera's newest frame
// with its detections and track windows drawn, and the site map with the fleet (diag_views.hpp).
// The live loop hands a view over at every publish tick and a camera's frame when the page asked
// for it; the server's threads only read the newest ones.
#pragma once

#include <atomic>
#include <cstdint>
#include <map>
#include <memory>
#include <mutex>
#include <string>
#include <vector>

#include "agv/http/http_server.hpp"
#include "agv/overhead/tracker.hpp"
#include "agv/site/site.hpp"
#include "config.hpp"
#include "diag_views.hpp"
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

// `run --detections-from-broker`: the detections messages taken from the broker and what became
// of them and of their tags.
struct BusDiag {
  std::uint64_t messages = 0;        // refused ones included
  std::uint64_t lost = 0;            // skipped sequence numbers: lost on the way
  std::uint64_t dropped_behind = 0;  // never decoded: the tracker's queue was full
  // Refused messages (never applied) by overhead::reason_name; every reason, 0 included.
  std::map<std::string, std::uint64_t> refused;
  std::uint64_t tags = 0, unknown_ids = 0, no_fix = 0, restricted_refused = 0;
};

// orders.subscribe: the vehicles' orders taken from the broker (TrackerCore::apply_order).
struct OrdersDiag {
  std::uint64_t messages = 0, routes_set = 0, routes_cleared = 0, duplicates = 0;
  std::map<std::string, std::uint64_t> refused;  // by reason, every reason, 0 included
};

// The tray boxes fitted for vehicles whose tag a parcel covers (this process's frames).
struct TrayDiag {
  std::uint64_t applied = 0, gated = 0, tag_disagree = 0;
  std::map<std::string, std::uint64_t> refused;  // by overhead::TrayRefusal name, 0 included
};

struct DiagView {
  std::int64_t t_ns = 0;  // the publish tick (CLOCK_MONOTONIC)
  std::uint64_t ticks = 0, ticks_skipped = 0, frames = 0, frames_dropped = 0;
  std::vector<CameraDiag> cameras;
  std::vector<AgvDiag> agvs;
  bool has_bus = false;  // the tracker is fed by detector processes: `bus` is filled
  BusDiag bus;
  bool has_orders = false;  // orders.subscribe: `orders` is filled
  OrdersDiag orders;
  bool has_tray = false;  // tray.enabled in a process that sees frames: `tray` is filled
  TrayDiag tray;
};

// /metrics: Prometheus text exposition format 0.0.4.
std::string overhead_metrics_text(const DiagView& v, const HttpCounters& http);
// /api/status.json: the same figures for the page; with a site, its cameras' views
// ("views": index and id, the index of /camera/<index>.png).
std::string overhead_status_json(const DiagView& v, const site::Site* site = nullptr);
// /site.svg: the site's outline, obstacles and cameras' floor footprints, and every vehicle of
// the view with a track at its pose: heading, 3-sigma ellipse, track state (data-state); the
// vehicles never seen listed apart. v.agvs[i] is site.fleet[i].
std::string overhead_site_svg(const site::Site& site, const DiagView& v);

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

  // The site (it must outlive this) and the search's parameters, for /site.svg and the cameras'
  // views; until then both are 404. Once only: a second call is ignored. Any thread.
  void attach(const site::Site& site, const overhead::SearchParams& search);
  // Tracker side, after site camera `camera`'s frame exposed at t_ns was processed: copies the
  // frame and what was found in it when the page asked for that camera (CameraViewTap's bound),
  // otherwise does nothing. Never waits.
  void offer_frame(std::size_t camera, std::int64_t t_ns, const cv::Mat& gray,
                   const overhead::FleetTracker& tracker,
                   const std::vector<overhead::Detection>& detections);
  // A camera's view as it is (waits for the slot): tests, a finished run.
  void put_view(std::size_t camera, CameraView v);

 private:
  struct ViewCache {
    std::mutex mutex;
    std::uint64_t seq = 0;  // the tap's seq the PNG was drawn from
    std::string png;
    std::int64_t t_ns = 0;
  };
  void answer(DiagRoute route, HttpAnswer* a);
  void answer_camera(int camera, HttpAnswer* a);

  std::mutex mutex_;
  DiagView view_;
  const int view_width_px_;
  // Set once by attach, read after attached_ (acquire).
  std::atomic<bool> attached_{false};
  std::mutex attach_mutex_;
  const site::Site* site_ = nullptr;
  overhead::SearchParams search_;
  std::vector<std::string> agv_ids_;
  std::vector<std::unique_ptr<CameraViewTap>> taps_;  // per site camera
  std::vector<std::unique_ptr<ViewCache>> caches_;
  HttpServer http_;  // last: stopped before the view it reads is destroyed
};

}  // namespace agv::overhead_app
