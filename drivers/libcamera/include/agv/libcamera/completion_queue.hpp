// Hand-over from libcamera's thread to ours. The requestCompleted callback only calls push();
// the consumer thread pops with a timeout. Bounded, newest wins: when full, the oldest item is
// moved to a recycle list (the consumer re-queues it to the camera; libcamera's thread never
// does any work for us). A disconnect flag wakes the consumer at once.
#pragma once

#include <chrono>
#include <condition_variable>
#include <cstddef>
#include <cstdint>
#include <deque>
#include <mutex>
#include <vector>

namespace agv::libcam {

template <typename T>
class CompletionQueue {
 public:
  explicit CompletionQueue(std::size_t capacity) : capacity_(capacity < 1 ? 1 : capacity) {}

  // Called on libcamera's thread: O(1), no allocation once the deques have grown.
  void push(T item) {
    {
      std::lock_guard<std::mutex> lock(mutex_);
      if (ready_.size() >= capacity_) {
        recycle_.push_back(ready_.front());
        ready_.pop_front();
        ++dropped_;
      }
      ready_.push_back(item);
    }
    cv_.notify_one();
  }

  void set_disconnected() {
    {
      std::lock_guard<std::mutex> lock(mutex_);
      disconnected_ = true;
    }
    cv_.notify_all();
  }

  enum class Result { kItem, kTimeout, kDisconnected };

  // Waits up to timeout for an item. Items evicted by newest-wins are appended to *recycle in
  // every case, so the caller can give them back to the camera.
  Result pop(std::int64_t timeout_ns, T* out, std::vector<T>* recycle) {
    std::unique_lock<std::mutex> lock(mutex_);
    cv_.wait_for(lock, std::chrono::nanoseconds(timeout_ns < 0 ? 0 : timeout_ns),
                 [&] { return !ready_.empty() || disconnected_; });
    recycle->insert(recycle->end(), recycle_.begin(), recycle_.end());
    recycle_.clear();
    if (!ready_.empty()) {
      *out = ready_.front();
      ready_.pop_front();
      return Result::kItem;
    }
    return disconnected_ ? Result::kDisconnected : Result::kTimeout;
  }

  // Everything still held (ready and evicted), e.g. on stop.
  std::vector<T> drain() {
    std::lock_guard<std::mutex> lock(mutex_);
    std::vector<T> all(recycle_.begin(), recycle_.end());
    all.insert(all.end(), ready_.begin(), ready_.end());
    recycle_.clear();
    ready_.clear();
    return all;
  }

  void reset() {
    std::lock_guard<std::mutex> lock(mutex_);
    ready_.clear();
    recycle_.clear();
    disconnected_ = false;
    dropped_ = 0;
  }

  bool disconnected() const {
    std::lock_guard<std::mutex> lock(mutex_);
    return disconnected_;
  }
  std::uint64_t dropped() const {
    std::lock_guard<std::mutex> lock(mutex_);
    return dropped_;
  }

 private:
  const std::size_t capacity_;
  mutable std::mutex mutex_;
  std::condition_variable cv_;
  std::deque<T> ready_;
  std::deque<T> recycle_;
  bool disconnected_ = false;
  std::uint64_t dropped_ = 0;
};

}  // namespace agv::libcam
