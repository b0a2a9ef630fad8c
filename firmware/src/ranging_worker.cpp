#include "ranging_worker.hpp"

#include <time.h>

#include <algorithm>
#include <cstdio>
#include <opencv2/core.hpp>
#include <string>

#include "agv/posix/realtime.hpp"

namespace agv::app {
namespace {

constexpr std::int64_t kFrameWaitNs = 50 * hal::kNsPerMs;
constexpr std::int64_t kReopenPeriodNs = 1000 * hal::kNsPerMs;

std::int64_t thread_cpu_ns() {
  timespec ts{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
  return std::int64_t{ts.tv_sec} * 1'000'000'000 + ts.tv_nsec;
}

}  // namespace

RangingWorker::RangingWorker(hal::Camera* camera, RackObserver* observer, RangingCounts* counts,
                             RangingRing* ring, SnapshotSlot* snapshot, hal::Clock* clock,
                             std::int64_t offset_ns, std::function<void()> thread_setup)
    : camera_(camera),
      observer_(observer),
      counts_(counts),
      ring_(ring),
      snapshot_(snapshot),
      clock_(clock),
      offset_ns_(offset_ns),
      thread_setup_(std::move(thread_setup)) {}

RangingWorker::~RangingWorker() { stop(); }

void RangingWorker::start() {
  if (camera_->start() != hal::CameraStatus::kOk) {
    counts_->last_error = std::string("second camera did not start: ") + camera_->last_error();
    error_ = true;
  }
  thread_ = std::thread([this] { main(); });
}

void RangingWorker::stop() {
  done_ = true;
  if (!thread_.joinable()) return;
  thread_.join();
  camera_->stop();
  // The driver's errors: stream faults, a replayed stream's unreadable images.
  counts_->frame_errors += camera_->stats().errors;
}

void RangingWorker::main() {
  posix::set_thread_name("agv-ranging");
  if (thread_setup_) thread_setup_();
  last_frame_ns_ = clock_->now_ns();
  std::int64_t retry_at_ns = 0;
  while (!done_.load() && read_once(&retry_at_ns)) {
  }
  ended_ = true;
}

bool RangingWorker::read_once(std::int64_t* retry_at_ns) {
  if (error_.load()) {
    if (clock_->now_ns() < *retry_at_ns) {
      clock_->sleep_until_ns(std::min(*retry_at_ns, clock_->now_ns() + kFrameWaitNs));
      return true;
    }
    camera_->stop();
    if (camera_->start() != hal::CameraStatus::kOk) {
      *retry_at_ns = clock_->now_ns() + kReopenPeriodNs;
      return true;
    }
    error_ = false;
    last_frame_ns_ = clock_->now_ns();
  }
  hal::FrameView f;
  const hal::CameraStatus s = camera_->next_frame(kFrameWaitNs, &f);
  watch_stall(s == hal::CameraStatus::kOk);
  if (s == hal::CameraStatus::kOk) {
    busy_ = true;
    observe(f);
    camera_->release(f);
    busy_ = false;
    return true;
  }
  if (s == hal::CameraStatus::kEndOfStream) return false;
  if (s != hal::CameraStatus::kTimeout) {  // counted by the driver (stats().errors, at stop)
    counts_->last_error = std::string("second camera: ") + camera_->last_error();
    error_ = true;
    *retry_at_ns = clock_->now_ns() + kReopenPeriodNs;
  }
  return true;
}

// A stall is counted once, when it passes kRangingStallNs, and its end logged with its length.
void RangingWorker::watch_stall(bool frame) {
  const std::int64_t now = clock_->now_ns();
  if (frame) {
    if (stalled_) {
      std::fprintf(stderr, "agvloc: second camera: frames again after %.1f s\n",
                   static_cast<double>(now - last_frame_ns_) / 1e9);
    }
    stalled_ = false;
    last_frame_ns_ = now;
  } else if (!stalled_ && now - last_frame_ns_ > kRangingStallNs) {
    stalled_ = true;
    ++counts_->stalls;
    std::fprintf(stderr, "agvloc: second camera: no frame for %.1f s (running on the other aids)\n",
                 static_cast<double>(now - last_frame_ns_) / 1e9);
  }
}

void RangingWorker::observe(const hal::FrameView& f) {
  if (!observer_->frame_size_ok(f.width_px, f.height_px)) {
    ++counts_->frame_errors;
    counts_->last_error = "second camera: a frame of " + std::to_string(f.width_px) + "x" +
                          std::to_string(f.height_px) + " px, not the configured size";
    return;
  }
  const cv::Mat img(f.height_px, f.width_px, CV_8UC1, const_cast<std::uint8_t*>(f.data),
                    static_cast<size_t>(f.stride_bytes));
  const vision::Prediction p = snapshot_->predict(
      f.t_exposure_ns + offset_ns_, kSnapshotPosGrowthMmPerS, kSnapshotHeadingGrowthRadPerS);
  ranging::PosePrior prior;
  prior.pose = p.vehicle_in_world;
  prior.cov = p.cov;
  const std::int64_t cpu0 = thread_cpu_ns();
  observer_->observe(img, p.valid ? &prior : nullptr, &rec_, counts_);
  const std::int64_t cpu = thread_cpu_ns() - cpu0;
  counts_->cpu_ns += cpu;
  counts_->cpu_max_ns = std::max(counts_->cpu_max_ns, cpu);
  rec_.t_exposure_ns = f.t_exposure_ns;
  rec_.t_done_ns = clock_->now_ns();
  if (!ring_->push(rec_)) ++counts_->dropped_queue;
}

}  // namespace agv::app
