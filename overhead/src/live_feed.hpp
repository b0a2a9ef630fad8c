// The camera side of `run` and `record`: one thread per live camera takes its frames (copied out
// of the driver's buffer at once, stamped with the driver's exposure time) and hands them to a
// sink. A camera that fails or disconnects is a camera fault: logged, counted and reopened at
// once, then every second while it fails. Cameras with a clock of their own (Aravis) have the
// mapping of that clock onto CLOCK_MONOTONIC logged when it is first known, when its drift is
// first estimated and on every jump.
#pragma once

#include <atomic>
#include <cstdint>
#include <functional>
#include <limits>
#include <memory>
#include <mutex>
#include <opencv2/core.hpp>
#include <string>
#include <thread>
#include <vector>

#include "agv/common/clock_map.hpp"
#include "agv/hal/camera.hpp"

namespace agv::overhead_app {

struct LiveCamera {
  std::string id;
  std::size_t site_camera = 0;  // index into site.cameras
  std::unique_ptr<hal::Camera> camera;
};

struct LiveFrame {
  std::size_t camera = 0;  // site camera
  std::int64_t t_ns = 0;   // exposure (the driver's stamp, CLOCK_MONOTONIC)
  std::int64_t rx_ns = 0;  // when the feed took it from the driver, CLOCK_MONOTONIC
  cv::Mat gray;
};

// One camera's record over a feed's life. Written by its thread; read after stop().
struct CameraHealth {
  std::uint64_t frames = 0;
  std::uint64_t faults = 0;      // stream errors and failed starts (a run of them counts once)
  std::uint64_t recoveries = 0;  // streaming again after a fault
  std::uint64_t reopens = 0;     // stream errors (disconnects) followed by a reopen
  std::uint64_t stamps_backwards = 0;  // exposure stamp not after the camera's previous one
  std::uint64_t driver_dropped = 0;    // the driver's own count at the end (CameraStats)
  // Exposure to the feed taking the frame: the stamps are on the host clock when this stays
  // small and positive.
  std::int64_t age_min_ns = std::numeric_limits<std::int64_t>::max();
  std::int64_t age_max_ns = std::numeric_limits<std::int64_t>::min();
  bool clock_mapped = false;  // the camera's own clock is mapped (the values below apply)
  std::int64_t clock_offset_ns = 0;
  double clock_drift_ppm = 0.0;
  std::uint64_t clock_jumps = 0;
  bool failing = false;    // in a fault now (not streaming)
  std::string last_fault;  // what the newest fault was
};

// "cam-west: 120 frames, 1 fault, 1 recovery, ..." for the summaries.
std::string describe(const std::string& id, const CameraHealth& h);

// What of a camera clock's mapping has been logged since its stream started.
struct ClockWatch {
  bool offset_logged = false;
  bool drift_logged = false;
  std::uint64_t jumps_seen = 0;   // the mapping's count when last looked at
  std::uint64_t jumps_total = 0;  // reported since the watch began
  void restart() { offset_logged = drift_logged = false; }
};

// The log lines a camera clock's mapping calls for since *w was last updated: the first offset,
// the first drift estimate, a jump. Empty while the mapping has no offset.
std::vector<std::string> clock_news(const ClockMap& m, ClockWatch* w);

class CameraFeed {
 public:
  using Sink = std::function<void(LiveFrame&&)>;
  // log_prefix starts every status line on stderr ("agvloc-overhead run"). `sink` is called from
  // the camera threads; `ended` once per camera whose stream ended for good (kEndOfStream) or
  // that was stopped.
  CameraFeed(std::vector<LiveCamera>* cams, std::string log_prefix, Sink sink,
             std::function<void()> ended);
  ~CameraFeed();
  CameraFeed(const CameraFeed&) = delete;
  CameraFeed& operator=(const CameraFeed&) = delete;

  void start();
  void stop();  // joins the threads; idempotent
  const std::vector<CameraHealth>& health() const { return health_; }
  // The cameras' health while they run (copied under a lock; for the diagnostics page).
  std::vector<CameraHealth> health_now() const;

 private:
  void camera_loop(std::size_t i);
  void log(std::size_t i, const std::string& what) const;

  std::vector<LiveCamera>* cams_;
  std::string prefix_;
  Sink sink_;
  std::function<void()> ended_;
  std::atomic<bool> stop_{false};
  std::vector<CameraHealth> health_;
  mutable std::mutex shared_mutex_;
  std::vector<CameraHealth> shared_;  // health_ as of each camera's last event
  std::vector<std::thread> threads_;
};

std::int64_t monotonic_ns();

}  // namespace agv::overhead_app
