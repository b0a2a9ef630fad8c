// Thread hand-off primitives of the loop. Fixed capacity, no allocation after construction.
#pragma once

#include <array>
#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <mutex>

#include "agv/hal/camera.hpp"

namespace agv::app {

// Capture -> vision: holds at most one frame, the newest. A frame that is replaced before the
// vision worker takes it is handed back to the caller for release and counted as dropped, so
// processing never lags behind and nothing queues without bound.
class FrameMailbox {
 public:
  // Stores `f`. Returns true and sets *displaced when an untaken frame was replaced.
  bool put(const hal::FrameView& f, hal::FrameView* displaced) {
    bool had = false;
    {
      std::lock_guard<std::mutex> lk(m_);
      if (full_) {
        *displaced = frame_;
        had = true;
        ++dropped_;
      }
      frame_ = f;
      full_ = true;
    }
    cv_.notify_one();
    return had;
  }
  // Waits up to timeout for a frame; false on timeout or close().
  bool take(std::int64_t timeout_ns, hal::FrameView* out) {
    std::unique_lock<std::mutex> lk(m_);
    cv_.wait_for(lk, std::chrono::nanoseconds(timeout_ns), [&] { return full_ || closed_; });
    if (!full_) return false;
    *out = frame_;
    full_ = false;
    return true;
  }
  // Returns the untaken frame, if any, so the owner can release it at shutdown.
  bool drain(hal::FrameView* out) {
    std::lock_guard<std::mutex> lk(m_);
    if (!full_) return false;
    *out = frame_;
    full_ = false;
    return true;
  }
  void close() {
    {
      std::lock_guard<std::mutex> lk(m_);
      closed_ = true;
    }
    cv_.notify_all();
  }
  bool closed() const {
    std::lock_guard<std::mutex> lk(m_);
    return closed_;
  }
  std::uint64_t dropped() const {
    std::lock_guard<std::mutex> lk(m_);
    return dropped_;
  }

 private:
  mutable std::mutex m_;
  std::condition_variable cv_;
  hal::FrameView frame_;
  bool full_ = false;
  bool closed_ = false;
  std::uint64_t dropped_ = 0;
};

// Single-producer single-consumer ring (vision -> output). When full the newest item is
// dropped and counted: fixes are small and arrive at frame rate, the consumer drains every
// period, so this only happens when the output thread is stalled.
template <typename T, std::size_t N>
class SpscRing {
 public:
  bool push(const T& v) {
    const std::size_t h = head_.load(std::memory_order_relaxed);
    const std::size_t next = (h + 1) % N;
    if (next == tail_.load(std::memory_order_acquire)) {
      dropped_.fetch_add(1, std::memory_order_relaxed);
      return false;
    }
    buf_[h] = v;
    head_.store(next, std::memory_order_release);
    return true;
  }
  bool pop(T* out) {
    const std::size_t t = tail_.load(std::memory_order_relaxed);
    if (t == head_.load(std::memory_order_acquire)) return false;
    *out = buf_[t];
    tail_.store((t + 1) % N, std::memory_order_release);
    return true;
  }
  // Consumer only: the oldest item without taking it.
  bool front(T* out) const {
    const std::size_t t = tail_.load(std::memory_order_relaxed);
    if (t == head_.load(std::memory_order_acquire)) return false;
    *out = buf_[t];
    return true;
  }
  std::uint64_t dropped() const { return dropped_.load(std::memory_order_relaxed); }

 private:
  std::array<T, N> buf_{};
  std::atomic<std::size_t> head_{0};
  std::atomic<std::size_t> tail_{0};
  std::atomic<std::uint64_t> dropped_{0};
};

}  // namespace agv::app
