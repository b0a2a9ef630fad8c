#include "diag_server.hpp"

#include <chrono>
#include <condition_variable>
#include <cstdio>
#include <thread>
#include <utility>

#include "affinity.hpp"
#include "agv/posix/realtime.hpp"
#include "agv/vision/landmark_localizer.hpp"

namespace agv::app {

const char* diag_page_html();  // diag_server_page.cpp

namespace {

// How long a frame request waits for the vision thread to copy a fresh frame before it encodes the
// newest one it has (a stalled camera, a finished replay).
constexpr auto kFrameWait = std::chrono::milliseconds(300);

}  // namespace

struct DiagServer::Impl {
  Impl(const config::Config& c, const LandmarkMap* m, DiagHandoff& h, FrameTap& f, const char* md)
      : cfg(c.diag),
        cpus(c.loop.service_cpus),
        map(m),
        handoff(h),
        frames(f),
        mode(md),
        http(
            http_settings_of(c.diag), [this](DiagRoute r, HttpAnswer* a) { answer(r, a); },
            [this] {
              posix::set_thread_name("agv-diag");
              pin_this_thread(cpus, "diagnostics page, loop.service_cpus");
            }) {
    vision::VisionConfig v = c.vision;
    v.now_ns = nullptr;  // the page shows the overlay, not stage timings
    localizer = std::make_unique<vision::LandmarkLocalizer>(v, c.camera_model,
                                                            config::landmark_geometry(c), map);
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
    const HttpCounters h = http.counters();
    s.requests = h.requests;
    s.refused_busy = h.refused_busy;
    s.refused_bad = h.refused_bad;
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

  void answer(DiagRoute route, HttpAnswer* a);

  config::DiagSection cfg;
  std::string cpus;  // loop.service_cpus
  const LandmarkMap* map;
  DiagHandoff& handoff;
  FrameTap& frames;
  const char* mode;
  std::unique_ptr<vision::LandmarkLocalizer> localizer;  // frame_mutex

  std::mutex snap_mutex;
  diag::Snapshot snap;
  std::uint64_t snap_seq = 0;

  std::mutex frame_mutex;
  std::string png_cache;
  std::int64_t png_t_ns = INT64_MIN;
  std::chrono::steady_clock::time_point png_at{};

  std::atomic<std::uint64_t> frames_encoded{0}, snapshots_taken{0};
  // Last: stopped (its threads joined) before the members its handler uses are destroyed.
  HttpServer http;
};

void DiagServer::Impl::answer(DiagRoute route, HttpAnswer* a) {
  const auto snapshot = [this](auto fn) { return with_snapshot(fn); };
  switch (route) {
    case DiagRoute::kPage:
      a->body = diag_page_html();
      a->type = "text/html; charset=utf-8";
      a->headers.emplace_back("Content-Security-Policy",
                              "default-src 'none'; script-src 'unsafe-inline'; style-src "
                              "'unsafe-inline'; img-src 'self'; connect-src 'self'");
      break;
    case DiagRoute::kStatus:
      a->body = snapshot([this](const diag::Snapshot& s, const diag::ServerStats& st) {
        return diag::status_json(s, st, mode);
      });
      a->type = "application/json";
      break;
    case DiagRoute::kMap:
      a->body = snapshot([this](const diag::Snapshot& s, const diag::ServerStats&) {
        return diag::map_json(map, s);
      });
      a->type = "application/json";
      break;
    case DiagRoute::kMetrics:
      a->body = snapshot([](const diag::Snapshot& s, const diag::ServerStats& st) {
        return diag::metrics_text(s, st);
      });
      a->type = "text/plain; version=0.0.4; charset=utf-8";
      break;
    case DiagRoute::kFrame: {
      std::int64_t t = 0;
      if (frame_png(&a->body, &t)) {
        a->type = "image/png";
        a->headers.emplace_back("X-Frame-Exposure-Ns", std::to_string(t));
      } else {
        a->status = 503;
        a->body = "no camera frame yet\n";
        a->headers.emplace_back("Retry-After", "1");
      }
      break;
    }
    default:
      break;
  }
}

DiagServer::DiagServer(const config::Config& cfg, const LandmarkMap* map, DiagHandoff& handoff,
                       FrameTap& frames, const char* mode)
    : impl_(std::make_unique<Impl>(cfg, map, handoff, frames, mode)) {}

DiagServer::~DiagServer() { stop(); }

diag::ServerStats DiagServer::stats() const { return impl_->stats(); }

bool DiagServer::start(std::string* error) {
  Impl& m = *impl_;
  if (!m.http.start(error)) return false;
  port_ = m.http.port();
  const bool v6 = m.cfg.bind_address.find(':') != std::string::npos;
  std::printf("diag: serving http://%s%s%s:%d/ (%s)\n", v6 ? "[" : "", m.cfg.bind_address.c_str(),
              v6 ? "]" : "", port_, m.mode);
  std::fflush(stdout);
  return true;
}

void DiagServer::stop() { impl_->http.stop(); }

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
