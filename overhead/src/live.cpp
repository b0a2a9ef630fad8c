#include "live.hpp"

#include <chrono>
#include <condition_variable>
#include <cstdio>
#include <cstring>
#include <deque>
#include <mutex>
#include <thread>

#include "agv/camera/common.hpp"
#include "agv/v4l2/v4l2_camera.hpp"
#ifdef AGV_HAVE_LIBCAMERA
#include "agv/libcamera/libcamera_camera.hpp"
#endif

namespace agv::overhead_app {

namespace {

constexpr std::int64_t kFrameWaitNs = 100'000'000;
constexpr auto kReopenEvery = std::chrono::seconds(1);
// Frames waiting per camera: more means the pipeline is behind; the oldest goes (counted).
constexpr std::size_t kQueuePerCamera = 2;

struct LiveFrame {
  std::size_t camera = 0;  // site camera
  std::int64_t t_ns = 0;
  cv::Mat gray;
};

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

void log_camera(const LiveCamera& c, const std::string& what) {
  std::fprintf(stderr, "agvloc-overhead run: camera %s: %s\n", c.id.c_str(), what.c_str());
}

cv::Mat copy_frame(const hal::FrameView& f) {
  cv::Mat out(f.height_px, f.width_px, CV_8UC1);
  for (int y = 0; y < f.height_px; ++y) {
    std::memcpy(out.ptr(y), f.data + static_cast<std::ptrdiff_t>(y) * f.stride_bytes,
                static_cast<std::size_t>(f.width_px));
  }
  return out;
}

// Sleeps until the next reopen, returning early when stopped.
void wait_reopen(const std::atomic<bool>& stop) {
  const auto until = std::chrono::steady_clock::now() + kReopenEvery;
  while (!stop.load() && std::chrono::steady_clock::now() < until) {
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
}

void camera_loop(LiveCamera* c, FrameQueue* q, const std::atomic<bool>& stop,
                 std::atomic<std::uint64_t>* reopens) {
  bool started = false, failing = false;
  while (!stop.load()) {
    if (!started) {
      const hal::CameraStatus st = c->camera->start();
      if (st != hal::CameraStatus::kOk) {
        if (!failing)
          log_camera(*c, std::string("cannot start (") + hal::to_string(st) + ": " +
                             c->camera->last_error() + "); retrying every second");
        failing = true;
        c->camera->stop();
        wait_reopen(stop);
        continue;
      }
      if (failing) log_camera(*c, "streaming again");
      started = true;
      failing = false;
    }
    hal::FrameView f;
    const hal::CameraStatus st = c->camera->next_frame(kFrameWaitNs, &f);
    if (st == hal::CameraStatus::kOk) {
      LiveFrame lf{c->site_camera, f.t_exposure_ns, copy_frame(f)};
      c->camera->release(f);
      q->push(std::move(lf));
    } else if (st == hal::CameraStatus::kEndOfStream) {
      break;
    } else if (st != hal::CameraStatus::kTimeout) {
      log_camera(*c,
                 std::string(hal::to_string(st)) + " (" + c->camera->last_error() + "); reopening");
      c->camera->stop();
      started = false;
      ++*reopens;
    }
  }
  c->camera->stop();
  q->camera_ended();
}

}  // namespace

std::int64_t monotonic_ns() {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(
             std::chrono::steady_clock::now().time_since_epoch())
      .count();
}

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
    if (it->second.driver == "v4l2") {
      lc.camera = std::make_unique<v4l2::V4l2Camera>(dc);
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

LiveCounters run_live(std::vector<LiveCamera>* cams, TrackerCore* core,
                      const std::atomic<bool>& stop, std::int64_t duration_ns) {
  FrameQueue q(cams->size());
  std::atomic<bool> stop_cameras{false};
  std::atomic<std::uint64_t> reopens{0};
  std::vector<std::thread> threads;
  for (LiveCamera& c : *cams) {
    threads.emplace_back(camera_loop, &c, &q, std::cref(stop_cameras), &reopens);
  }
  LiveCounters n;
  const std::int64_t period = core->period_ns();
  const std::int64_t t_end = duration_ns > 0 ? monotonic_ns() + duration_ns : INT64_MAX;
  std::int64_t next_tick = monotonic_ns();
  LiveFrame f;
  while (!stop.load() && !q.finished() && monotonic_ns() < t_end) {
    const auto deadline =
        std::chrono::steady_clock::time_point(std::chrono::nanoseconds(next_tick));
    if (q.pop_until(deadline, &f)) {
      core->process(f.camera, f.t_ns, f.gray);
      continue;
    }
    const std::int64_t now = monotonic_ns();
    if (now < next_tick) continue;
    core->publish(next_tick);
    ++n.ticks;
    next_tick += period;
    if (next_tick + period < now) {  // fell behind by more than a tick: publish now, not late
      n.ticks_skipped += static_cast<std::uint64_t>((now - next_tick) / period);
      next_tick = now;
    }
  }
  stop_cameras.store(true);
  for (std::thread& t : threads) t.join();
  while (q.pop_until(std::chrono::steady_clock::now(), &f)) core->process(f.camera, f.t_ns, f.gray);
  core->publish(monotonic_ns());
  ++n.ticks;
  n.frames_dropped = q.dropped();
  n.reopens = reopens.load();
  return n;
}

}  // namespace agv::overhead_app
