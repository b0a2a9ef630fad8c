#include "agv/fakecamera/fake_camera.hpp"

#include <algorithm>
#include <chrono>
#include <utility>

#include "agv/camera/common.hpp"

namespace agv::fakecamera {

using hal::CameraStatus;

FakeCamera::FakeCamera() : FakeCamera(Options{}) {}

FakeCamera::FakeCamera(Options options) : options_(options) {
  slots_.resize(static_cast<std::size_t>(std::max(1, options_.slots)));
}

FakeImage FakeCamera::solid(int width_px, int height_px, std::uint8_t value) {
  FakeImage img;
  img.width_px = width_px;
  img.height_px = height_px;
  img.gray.assign(static_cast<std::size_t>(width_px) * static_cast<std::size_t>(height_px), value);
  return img;
}

void FakeCamera::push_frame(FakeImage image, std::int64_t t_exposure_ns, std::int64_t sequence) {
  push_event(Kind::kFrame, t_exposure_ns, std::move(image), sequence);
}

void FakeCamera::push_stall(std::int64_t duration_ns) {
  push_event(Kind::kStall, std::max<std::int64_t>(0, duration_ns));
}

void FakeCamera::push_disconnect() { push_event(Kind::kDisconnect); }

void FakeCamera::push_end_of_stream() { push_event(Kind::kEndOfStream); }

void FakeCamera::push_event(Kind kind, std::int64_t t_ns, FakeImage image, std::int64_t sequence) {
  std::lock_guard<std::mutex> lock(mutex_);
  Event e;
  e.kind = kind;
  e.t_ns = t_ns;
  e.image = std::move(image);
  if (kind == Kind::kFrame) {
    e.sequence = sequence < 0 ? next_sequence_ : static_cast<std::uint64_t>(sequence);
    next_sequence_ = e.sequence + 1;
  }
  events_.push_back(std::move(e));
  cv_.notify_all();
}

void FakeCamera::set_start_status(CameraStatus s) {
  std::lock_guard<std::mutex> lock(mutex_);
  options_.start_status = s;
}

CameraStatus FakeCamera::start() {
  std::lock_guard<std::mutex> lock(mutex_);
  ++start_calls_;
  if (options_.start_status != CameraStatus::kOk) {
    error_ = std::string("fake camera: start() scripted to fail: ") +
             hal::to_string(options_.start_status);
    return options_.start_status;
  }
  started_ = true;
  disconnected_ = false;
  error_.clear();
  return CameraStatus::kOk;
}

void FakeCamera::stop() {
  std::lock_guard<std::mutex> lock(mutex_);
  ++stop_calls_;
  started_ = false;
  for (Slot& s : slots_) s.busy = false;  // outstanding frames become invalid, as documented
}

void FakeCamera::wait_ns(std::int64_t ns) {
  if (ns <= 0 || options_.clock == nullptr) return;
  options_.clock->sleep_until_ns(options_.clock->now_ns() + ns);
}

CameraStatus FakeCamera::next_frame(std::int64_t timeout_ns, hal::FrameView* frame) {
  if (frame == nullptr) return CameraStatus::kInvalidArgument;
  std::unique_lock<std::mutex> lock(mutex_);
  if (!started_) return CameraStatus::kNotStarted;
  if (disconnected_) return CameraStatus::kDisconnected;
  if (ended_) return CameraStatus::kEndOfStream;
  std::int64_t remaining_ns = std::max<std::int64_t>(0, timeout_ns);
  for (;;) {
    if (events_.empty()) {
      if (options_.end_of_stream_when_empty) {
        ended_ = true;
        return CameraStatus::kEndOfStream;
      }
      if (options_.wait_for_events && remaining_ns > 0) {
        const bool got = cv_.wait_for(lock, std::chrono::nanoseconds(remaining_ns),
                                      [&] { return !events_.empty() || !started_; });
        if (!started_) return CameraStatus::kNotStarted;
        if (got) {
          remaining_ns = 0;  // real time passed; only events that need no waiting now
          continue;
        }
        return CameraStatus::kTimeout;
      }
      lock.unlock();
      wait_ns(remaining_ns);
      return CameraStatus::kTimeout;
    }
    Event& e = events_.front();
    switch (e.kind) {
      case Kind::kStall: {
        const std::int64_t consumed = std::min(remaining_ns, e.t_ns);
        e.t_ns -= consumed;
        remaining_ns -= consumed;
        const bool stall_over = e.t_ns == 0;
        if (stall_over) events_.pop_front();
        lock.unlock();
        wait_ns(consumed);
        lock.lock();
        if (!stall_over) return CameraStatus::kTimeout;
        if (!started_) return CameraStatus::kNotStarted;
        continue;
      }
      case Kind::kDisconnect:
        events_.pop_front();
        disconnected_ = true;
        ++stats_.errors;
        error_ = "fake camera: disconnected (scripted)";
        return CameraStatus::kDisconnected;
      case Kind::kEndOfStream:
        events_.pop_front();
        ended_ = true;
        return CameraStatus::kEndOfStream;
      case Kind::kFrame: {
        Event ev = std::move(e);
        events_.pop_front();
        stats_.frames_dropped += camera::frames_skipped(last_sequence_, ev.sequence);
        last_sequence_ = static_cast<std::int64_t>(ev.sequence);
        auto free_slot =
            std::find_if(slots_.begin(), slots_.end(), [](const Slot& s) { return !s.busy; });
        if (free_slot == slots_.end()) {  // every buffer held by the consumer: frame lost
          ++stats_.frames_dropped;
          continue;
        }
        const std::size_t expected = static_cast<std::size_t>(std::max(0, ev.image.width_px)) *
                                     static_cast<std::size_t>(std::max(0, ev.image.height_px));
        if (ev.image.width_px <= 0 || ev.image.height_px <= 0 || ev.image.gray.size() != expected) {
          ++stats_.errors;
          error_ = "fake camera: scripted frame has inconsistent size";
          return CameraStatus::kDeviceError;
        }
        free_slot->busy = true;
        free_slot->image = std::move(ev.image);
        frame->data = free_slot->image.gray.data();
        frame->width_px = free_slot->image.width_px;
        frame->height_px = free_slot->image.height_px;
        frame->stride_bytes = free_slot->image.width_px;
        frame->t_exposure_ns = ev.t_ns;
        frame->sequence = ev.sequence;
        frame->slot = static_cast<int>(free_slot - slots_.begin());
        ++stats_.frames_delivered;
        return CameraStatus::kOk;
      }
    }
  }
}

void FakeCamera::release(const hal::FrameView& frame) {
  std::lock_guard<std::mutex> lock(mutex_);
  if (frame.slot < 0 || frame.slot >= static_cast<int>(slots_.size())) return;
  Slot& s = slots_[static_cast<std::size_t>(frame.slot)];
  if (!s.busy || s.image.gray.data() != frame.data) return;  // double or foreign release
  s.busy = false;
}

hal::CameraStats FakeCamera::stats() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return stats_;
}

const char* FakeCamera::last_error() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return error_.c_str();
}

int FakeCamera::frames_outstanding() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return static_cast<int>(
      std::count_if(slots_.begin(), slots_.end(), [](const Slot& s) { return s.busy; }));
}

int FakeCamera::start_calls() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return start_calls_;
}

int FakeCamera::stop_calls() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return stop_calls_;
}

std::size_t FakeCamera::events_pending() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return events_.size();
}

}  // namespace agv::fakecamera
