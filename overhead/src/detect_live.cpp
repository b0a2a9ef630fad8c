#include <chrono>
#include <condition_variable>
#include <cstdio>
#include <mutex>
#include <optional>

#include "detect.hpp"

namespace agv::overhead_app {
namespace {

// The newest frame not yet detected. A newer one replaces it: a detector behind its camera
// works on the present, the tracker has no use for a late frame it will get a newer one of.
class NewestFrame {
 public:
  void put(LiveFrame&& f) {
    {
      const std::lock_guard<std::mutex> lock(m_);
      if (slot_) ++replaced_;
      slot_ = std::move(f);
    }
    cv_.notify_one();
  }
  void end() {
    {
      const std::lock_guard<std::mutex> lock(m_);
      ended_ = true;
    }
    cv_.notify_one();
  }
  // False when nothing came by the deadline.
  bool take_until(std::chrono::steady_clock::time_point deadline, LiveFrame* out) {
    std::unique_lock<std::mutex> lock(m_);
    cv_.wait_until(lock, deadline, [this] { return slot_.has_value() || ended_; });
    if (!slot_) return false;
    *out = std::move(*slot_);
    slot_.reset();
    return true;
  }
  bool ended() const {
    const std::lock_guard<std::mutex> lock(m_);
    return ended_ && !slot_;
  }
  std::uint64_t replaced() const {
    const std::lock_guard<std::mutex> lock(m_);
    return replaced_;
  }

 private:
  mutable std::mutex m_;
  std::condition_variable cv_;
  std::optional<LiveFrame> slot_;
  std::uint64_t replaced_ = 0;
  bool ended_ = false;
};

constexpr std::int64_t kPollNs = 100'000'000;  // how often the stop flag is looked at
constexpr std::uint64_t kRefusalsLogged = 5;

}  // namespace

CameraDetector::CameraDetector(const site::Site& site, const OverheadConfig& cfg,
                               std::size_t site_camera)
    : camera_(site_camera),
      processor_(site.cameras, site.fleet, cfg.detect, cfg.search),
      local_(site.fleet.size(), cfg.tracker) {
  processor_.set_tray_fit(cfg.tray_fit, cfg.tray);
  processor_.set_tray_plane_sigma(cfg.tray_plane);
  msg_.camera_id = site.cameras.at(site_camera).id;
}

const overhead::DetectionMsg* CameraDetector::detect(std::int64_t t_ns, const cv::Mat& gray,
                                                     std::string* error) {
  dets_.clear();
  if (!processor_.process(camera_, t_ns, gray, &local_, &dets_, error)) return nullptr;
  ++msg_.seq;
  msg_.t_ns = t_ns;
  msg_.tags.clear();
  for (const overhead::Detection& d : dets_) msg_.tags.push_back({d.tag, d.level});
  tags_ += msg_.tags.size();
  return &msg_;
}

LiveDetectCounters run_detect_live(
    LiveCamera* cam, CameraDetector* det,
    const std::function<void(const overhead::DetectionMsg&)>& publish,
    const std::atomic<bool>& stop, std::int64_t duration_ns) {
  std::vector<LiveCamera> cams;
  cams.push_back(std::move(*cam));
  NewestFrame newest;
  CameraFeed feed(
      &cams, "agvloc-overhead detect", [&newest](LiveFrame&& f) { newest.put(std::move(f)); },
      [&newest] { newest.end(); });
  feed.start();
  LiveDetectCounters n;
  const std::int64_t t_end = duration_ns > 0 ? monotonic_ns() + duration_ns : INT64_MAX;
  LiveFrame f;
  std::string err;
  while (!stop.load() && !newest.ended() && monotonic_ns() < t_end) {
    const auto deadline = std::chrono::steady_clock::time_point(
        std::chrono::nanoseconds(std::min(monotonic_ns() + kPollNs, t_end)));
    if (!newest.take_until(deadline, &f)) continue;
    if (const overhead::DetectionMsg* m = det->detect(f.t_ns, f.gray, &err)) {
      publish(*m);
      ++n.frames_detected;
    } else if (++n.frames_refused <= kRefusalsLogged) {
      std::fprintf(stderr, "agvloc-overhead detect: frame refused: %s\n", err.c_str());
    }
  }
  feed.stop();
  n.frames_replaced = newest.replaced();
  n.health = feed.health().at(0);
  *cam = std::move(cams[0]);
  return n;
}

}  // namespace agv::overhead_app
