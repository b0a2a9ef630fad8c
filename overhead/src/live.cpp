#include "live.hpp"

#include <chrono>
#include <condition_variable>
#include <csignal>
#include <cstdio>
#include <cstring>
#include <deque>
#include <mutex>
#include <thread>

#include "agv/camera/common.hpp"
#include "agv/v4l2/v4l2_camera.hpp"
#include "inputs.hpp"
#ifdef AGV_HAVE_LIBCAMERA
#include "agv/libcamera/libcamera_camera.hpp"
#endif
#ifdef AGV_HAVE_ARAVIS
#include "agv/aravis/aravis_camera.hpp"
#endif

namespace agv::overhead_app {

namespace {

// Frames waiting per camera: more means the pipeline is behind; the oldest goes (counted).
constexpr std::size_t kQueuePerCamera = 2;

class FrameQueue {
 public:
  FrameQueue(std::size_t cameras) : capacity_(cameras * kQueuePerCamera), alive_(cameras) {}

  void push(LiveFrame f) {
    std::lock_guard<std::mutex> lock(m_);
    if (q_.size() >= capacity_) {
      q_.pop_front();
      ++dropped_;
    }
    q_.push_back(std::move(f));
    cv_.notify_one();
  }
  void camera_ended() {
    std::lock_guard<std::mutex> lock(m_);
    --alive_;
    cv_.notify_one();
  }
  // The next frame, waiting until the deadline; false when none came.
  bool pop_until(std::chrono::steady_clock::time_point deadline, LiveFrame* out) {
    std::unique_lock<std::mutex> lock(m_);
    cv_.wait_until(lock, deadline, [this] { return !q_.empty() || alive_ == 0; });
    if (q_.empty()) return false;
    *out = std::move(q_.front());
    q_.pop_front();
    return true;
  }
  bool finished() {
    std::lock_guard<std::mutex> lock(m_);
    return alive_ == 0 && q_.empty();
  }
  std::uint64_t dropped() {
    std::lock_guard<std::mutex> lock(m_);
    return dropped_;
  }

 private:
  std::mutex m_;
  std::condition_variable cv_;
  std::deque<LiveFrame> q_;
  std::size_t capacity_;
  std::size_t alive_;
  std::uint64_t dropped_ = 0;
};

// The diagnostics view of the loop: the cameras' health (their frame rate over about a second)
// and every vehicle's track, and whether its last fix came from its tag (a detection applied at
// that exposure time) or from its tray's box.
class DiagFeeder {
 public:
  DiagFeeder(const LiveDiag& d, std::size_t cameras, std::size_t agvs)
      : d_(d), rate_(cameras), tag_fix_ns_(agvs, INT64_MIN) {}

  void frame_done(const TrackerCore& core, const LiveFrame& f) {
    if (!d_.server) return;
    const std::int64_t t_ns = f.t_ns;
    d_.server->offer_frame(f.camera, t_ns, f.gray, core.tracker(), core.last_detections());
    for (const overhead::Detection& det : core.last_detections()) {
      if (det.in_fleet && det.agv < tag_fix_ns_.size() &&
          (det.result == overhead::FixResult::kApplied ||
           det.result == overhead::FixResult::kStarted)) {
        tag_fix_ns_[det.agv] = t_ns;
      }
    }
  }

  void tick(const std::vector<LiveCamera>& cams, const CameraFeed& feed, const TrackerCore& core,
            const LiveCounters& n, std::uint64_t dropped, std::int64_t t_ns) {
    if (!d_.server) return;
    DiagView v;
    v.t_ns = t_ns;
    v.ticks = n.ticks;
    v.ticks_skipped = n.ticks_skipped;
    v.frames = core.frames();
    v.frames_dropped = dropped;
    const std::vector<CameraHealth> h = feed.health_now();
    for (std::size_t i = 0; i < cams.size() && i < h.size(); ++i) {
      Rate& r = rate_[i];
      if (t_ns - r.t_ns >= kRateWindowNs) {
        if (r.t_ns != 0) {
          r.fps = static_cast<double>(h[i].frames - r.frames) * 1e9 /
                  static_cast<double>(t_ns - r.t_ns);
        }
        r.t_ns = t_ns;
        r.frames = h[i].frames;
      }
      v.cameras.push_back({cams[i].id, h[i], r.fps});
    }
    for (std::size_t a = 0; a < d_.agv_ids.size(); ++a) {
      AgvDiag g;
      g.id = d_.agv_ids[a];
      g.track = core.tracker().output(a, t_ns);
      if (g.track.state != overhead::TrackState::kNone) {
        g.source =
            a < tag_fix_ns_.size() && g.track.last_fix_t_ns == tag_fix_ns_[a] ? "tag" : "tray";
      }
      v.agvs.push_back(std::move(g));
    }
    core.fill_orders_diag(&v);
    core.fill_tray_diag(&v);
    d_.server->update(std::move(v));
  }

 private:
  static constexpr std::int64_t kRateWindowNs = 1'000'000'000;
  struct Rate {
    std::int64_t t_ns = 0;
    std::uint64_t frames = 0;
    double fps = 0.0;
  };
  const LiveDiag& d_;
  std::vector<Rate> rate_;
  std::vector<std::int64_t> tag_fix_ns_;
};

}  // namespace

hal::CameraConfig driver_config(const CameraSettings& s, const site::CeilingCamera& cam) {
  hal::CameraConfig c;
  c.id = s.device;
  c.width_px = cam.intrinsics.width_px;
  c.height_px = cam.intrinsics.height_px;
  c.fps = s.fps;
  c.exposure_us = static_cast<int>(s.exposure_us);
  c.analogue_gain = s.analogue_gain;
  return c;
}

bool make_live_cameras(const OverheadConfig& cfg, const site::Site& site,
                       std::vector<LiveCamera>* out, std::string* error) {
  for (std::size_t i = 0; i < site.cameras.size(); ++i) {
    const auto it = cfg.cameras.find(site.cameras[i].id);
    if (it == cfg.cameras.end() || it->second.device.empty()) continue;
    const std::string key = "cameras." + site.cameras[i].id;
    const hal::CameraConfig dc = driver_config(it->second, site.cameras[i]);
    const std::string verr = camera::validate_config(dc);
    if (!verr.empty()) return (*error = key + ": " + verr, false);
    LiveCamera lc{site.cameras[i].id, i, nullptr};
    const std::string& driver = it->second.driver;
    if (driver == "v4l2") {
      lc.camera = std::make_unique<v4l2::V4l2Camera>(dc);
    } else if (driver == "aravis") {
#ifdef AGV_HAVE_ARAVIS
      lc.camera = std::make_unique<aravis::AravisCamera>(dc);
#else
      return (*error = key +
                       ".driver: aravis is not available in this build (rebuild with "
                       "libaravis-dev installed)",
              false);
#endif
    } else {
#ifdef AGV_HAVE_LIBCAMERA
      lc.camera = std::make_unique<libcam::LibcameraCamera>(dc);
#else
      return (*error = key +
                       ".driver: libcamera is not available in this build (use v4l2 or "
                       "rebuild with libcamera-dev installed)",
              false);
#endif
    }
    out->push_back(std::move(lc));
  }
  if (out->empty()) {
    *error = "no camera to open: set cameras.<id>.device for the site's cameras";
    return false;
  }
  return true;
}

// Orders applied per publish tick at most (each is read strictly, up to 1 MiB of JSON).
constexpr int kOrdersPerTick = 8;

LiveCounters run_live(std::vector<LiveCamera>* cams, TrackerCore* core,
                      const std::atomic<bool>& stop, std::int64_t duration_ns, const LiveDiag& diag,
                      MqttIn* orders) {
  FrameQueue q(cams->size());
  CameraFeed feed(
      cams, "agvloc-overhead run", [&q](LiveFrame&& f) { q.push(std::move(f)); },
      [&q] { q.camera_ended(); });
  feed.start();
  LiveCounters n;
  DiagFeeder feeder(diag, cams->size(), diag.agv_ids.size());
  if (diag.server) diag.server->attach(core->site(), core->config().search);
  // Each camera's fault state as last published (none yet).
  std::vector<int> published_fault(cams->size(), -1);
  std::vector<std::uint64_t> published_faults(cams->size(), 0);
  std::vector<std::int64_t> unpublished;  // exposure stamps of frames not yet published
  const std::int64_t period = core->period_ns();
  const std::int64_t t_end = duration_ns > 0 ? monotonic_ns() + duration_ns : INT64_MAX;
  std::int64_t next_tick = monotonic_ns();
  LiveFrame f;
  while (!stop.load() && !q.finished() && monotonic_ns() < t_end) {
    const auto deadline =
        std::chrono::steady_clock::time_point(std::chrono::nanoseconds(next_tick));
    if (q.pop_until(deadline, &f)) {
      core->process(f.camera, f.t_ns, f.gray);
      feeder.frame_done(*core, f);
      if (diag.exposure_to_publish_ns) unpublished.push_back(f.t_ns);
      continue;
    }
    const std::int64_t now = monotonic_ns();
    if (now < next_tick) continue;
    // A few per tick: a flood of orders delays the next ticks' publication by no more than this.
    MqttMessage m;
    for (int k = 0; k < kOrdersPerTick && orders && orders->pop(&m, 0); ++k)
      core->apply_order(m.topic, m.payload, now);
    core->publish(next_tick);
    ++n.ticks;
    if (diag.exposure_to_publish_ns) {
      const std::int64_t published = monotonic_ns();
      for (const std::int64_t t : unpublished)
        diag.exposure_to_publish_ns->push_back(published - t);
      unpublished.clear();
    }
    feeder.tick(*cams, feed, *core, n, q.dropped(), next_tick);
    const std::vector<CameraHealth> health = feed.health_now();
    for (std::size_t i = 0; i < cams->size() && i < health.size(); ++i) {
      const CameraHealth& h = health[i];
      if (h.frames == 0 && h.faults == 0) continue;  // not started yet: nothing to say
      const int fault = h.failing ? 1 : 0;
      if (fault == published_fault[i] && h.faults == published_faults[i]) continue;
      core->publish_camera_state((*cams)[i].id, h.failing, h.last_fault);
      published_fault[i] = fault;
      published_faults[i] = h.faults;
    }
    next_tick += period;
    if (next_tick + period < now) {  // fell behind by more than a tick: publish now, not late
      n.ticks_skipped += static_cast<std::uint64_t>((now - next_tick) / period);
      next_tick = now;
    }
  }
  feed.stop();
  while (q.pop_until(std::chrono::steady_clock::now(), &f)) core->process(f.camera, f.t_ns, f.gray);
  core->publish(monotonic_ns());
  ++n.ticks;
  n.frames_dropped = q.dropped();
  n.cameras = feed.health();
  for (const CameraHealth& h : n.cameras) n.reopens += h.reopens;
  return n;
}

bool start_live(const char* command, const std::string& config_path, const std::string& site_path,
                void (*on_stop)(int), LiveInputs* in) {
  if (!load_config_and_site(command, config_path, site_path, &in->cfg, &in->site)) return false;
  std::string err;
  if (!make_live_cameras(in->cfg, in->site, &in->cams, &err)) {
    command_fail(command, 2, config_path + ": " + err);
    return false;
  }
  struct sigaction sa {};
  sa.sa_handler = on_stop;
  sigemptyset(&sa.sa_mask);
  sigaction(SIGINT, &sa, nullptr);
  sigaction(SIGTERM, &sa, nullptr);
  return true;
}

}  // namespace agv::overhead_app
