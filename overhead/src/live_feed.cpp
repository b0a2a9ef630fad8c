#include "live_feed.hpp"

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstring>

#include "agv/common/clock_map.hpp"
#ifdef AGV_HAVE_ARAVIS
#include "agv/aravis/aravis_camera.hpp"
#endif

namespace agv::overhead_app {

namespace {

constexpr std::int64_t kFrameWaitNs = 100'000'000;
constexpr auto kReopenEvery = std::chrono::seconds(1);

cv::Mat copy_frame(const hal::FrameView& f) {
  cv::Mat out(f.height_px, f.width_px, CV_8UC1);
  for (int y = 0; y < f.height_px; ++y) {
    std::memcpy(out.ptr(y), f.data + static_cast<std::ptrdiff_t>(y) * f.stride_bytes,
                static_cast<std::size_t>(f.width_px));
  }
  return out;
}

// The driver's camera-clock mapping, for drivers that have one.
const ClockMap* camera_clock([[maybe_unused]] const hal::Camera& cam) {
#ifdef AGV_HAVE_ARAVIS
  if (const auto* a = dynamic_cast<const aravis::AravisCamera*>(&cam)) return &a->clock();
#endif
  return nullptr;
}

std::string plural(std::uint64_t n, const char* one, const char* many) {
  return std::to_string(n) + " " + (n == 1 ? one : many);
}

std::string clock_state(const ClockMap& m) {
  char buf[160];
  if (m.drift_locked()) {
    std::snprintf(buf, sizeof buf, "offset %lld ns, drift %+.2f ppm",
                  static_cast<long long>(m.offset_ns()), m.drift_ppm());
  } else {
    std::snprintf(buf, sizeof buf, "offset %lld ns, drift not yet estimated",
                  static_cast<long long>(m.offset_ns()));
  }
  return buf;
}

// Sleeps until the next reopen, returning early when stopped.
void wait_reopen(const std::atomic<bool>& stop) {
  const auto until = std::chrono::steady_clock::now() + kReopenEvery;
  while (!stop.load() && std::chrono::steady_clock::now() < until) {
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
}

}  // namespace

std::int64_t monotonic_ns() {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(
             std::chrono::steady_clock::now().time_since_epoch())
      .count();
}

std::string describe(const std::string& id, const CameraHealth& h) {
  std::string s = id + ": " + plural(h.frames, "frame", "frames") + ", " +
                  plural(h.faults, "fault", "faults") + ", " +
                  plural(h.recoveries, "recovery", "recoveries") + ", " +
                  std::to_string(h.stamps_backwards) + " stamps not increasing, " +
                  std::to_string(h.driver_dropped) + " dropped by the driver";
  char buf[200];
  if (h.frames > 0) {
    std::snprintf(buf, sizeof buf, ", exposure to arrival %.3f..%.3f ms",
                  static_cast<double>(h.age_min_ns) / 1e6, static_cast<double>(h.age_max_ns) / 1e6);
    s += buf;
  }
  if (h.clock_mapped) {
    std::snprintf(buf, sizeof buf, ", camera clock offset %lld ns drift %+.2f ppm, %llu jumps",
                  static_cast<long long>(h.clock_offset_ns), h.clock_drift_ppm,
                  static_cast<unsigned long long>(h.clock_jumps));
    s += buf;
  }
  return s;
}

std::vector<std::string> clock_news(const ClockMap& m, ClockWatch* w) {
  std::vector<std::string> out;
  w->jumps_seen = std::min(w->jumps_seen, m.jumps());  // a counter that was reset
  if (!m.has_offset()) return out;
  if (!w->offset_logged) out.push_back("camera clock mapped onto the host's: " + clock_state(m));
  if (!w->drift_logged && m.drift_locked()) {
    out.push_back("camera clock drift estimated: " + clock_state(m));
    w->drift_logged = true;
  }
  if (m.jumps() > w->jumps_seen) {
    w->jumps_total += m.jumps() - w->jumps_seen;
    out.push_back("camera clock jumped; mapping restarted: " + clock_state(m));
  }
  w->offset_logged = true;
  w->jumps_seen = m.jumps();
  return out;
}

CameraFeed::CameraFeed(std::vector<LiveCamera>* cams, std::string log_prefix, Sink sink,
                       std::function<void()> ended)
    : cams_(cams),
      prefix_(std::move(log_prefix)),
      sink_(std::move(sink)),
      ended_(std::move(ended)),
      health_(cams->size()),
      shared_(cams->size()) {}

std::vector<CameraHealth> CameraFeed::health_now() const {
  std::lock_guard<std::mutex> lock(shared_mutex_);
  return shared_;
}

CameraFeed::~CameraFeed() { stop(); }

void CameraFeed::start() {
  stop_.store(false);
  for (std::size_t i = 0; i < cams_->size(); ++i)
    threads_.emplace_back([this, i] { camera_loop(i); });
}

void CameraFeed::stop() {
  stop_.store(true);
  for (std::thread& t : threads_) t.join();
  threads_.clear();
}

void CameraFeed::log(std::size_t i, const std::string& what) const {
  std::fprintf(stderr, "%s: camera %s: %s\n", prefix_.c_str(), (*cams_)[i].id.c_str(),
               what.c_str());
}

void CameraFeed::camera_loop(std::size_t i) {
  LiveCamera& c = (*cams_)[i];
  CameraHealth& h = health_[i];
  const ClockMap* clock = camera_clock(*c.camera);
  ClockWatch watch;
  bool started = false, failing = false;
  std::int64_t last_t_ns = std::numeric_limits<std::int64_t>::min();
  auto share = [&] {
    h.failing = failing;
    std::lock_guard<std::mutex> lock(shared_mutex_);
    shared_[i] = h;
  };
  auto fault = [&](const std::string& what, const char* then) {
    if (!failing) {
      ++h.faults;
      h.last_fault = what;
      log(i, "fault after " + plural(h.frames, "frame", "frames") + ": " + what + "; " + then);
    }
    failing = true;
    share();
  };
  while (!stop_.load()) {
    if (!started) {
      const hal::CameraStatus st = c.camera->start();
      if (st != hal::CameraStatus::kOk) {
        fault(std::string("cannot start (") + hal::to_string(st) + ": " + c.camera->last_error() +
                  ")",
              "retrying every second");
        c.camera->stop();
        wait_reopen(stop_);
        continue;
      }
      if (failing) {
        ++h.recoveries;
        log(i, "streaming again after " + plural(h.frames, "frame", "frames"));
      }
      started = true;
      failing = false;
      watch.restart();
      share();
    }
    hal::FrameView f;
    const hal::CameraStatus st = c.camera->next_frame(kFrameWaitNs, &f);
    if (st == hal::CameraStatus::kOk) {
      LiveFrame lf{c.site_camera, f.t_exposure_ns, monotonic_ns(), copy_frame(f)};
      c.camera->release(f);
      ++h.frames;
      if (lf.t_ns <= last_t_ns) ++h.stamps_backwards;
      last_t_ns = std::max(last_t_ns, lf.t_ns);
      h.age_min_ns = std::min(h.age_min_ns, lf.rx_ns - lf.t_ns);
      h.age_max_ns = std::max(h.age_max_ns, lf.rx_ns - lf.t_ns);
      if (clock != nullptr) {
        for (const std::string& line : clock_news(*clock, &watch)) log(i, line);
        h.clock_jumps = watch.jumps_total;
        h.clock_mapped = clock->has_offset();
        h.clock_offset_ns = clock->offset_ns();
        h.clock_drift_ppm = clock->drift_ppm();
      }
      share();
      sink_(std::move(lf));
    } else if (st == hal::CameraStatus::kEndOfStream) {
      break;
    } else if (st != hal::CameraStatus::kTimeout) {
      fault(std::string(hal::to_string(st)) + " (" + c.camera->last_error() + ")", "reopening");
      c.camera->stop();
      started = false;
      ++h.reopens;
    }
  }
  h.driver_dropped = c.camera->stats().frames_dropped;
  c.camera->stop();
  ended_();
}

}  // namespace agv::overhead_app
