#include "gyro_reader.hpp"

#include <chrono>
#include <cinttypes>
#include <cstdio>

namespace agv::app {

bool GyroReader::start(std::string* error) {
  if (!imu_) {
    *error = "imu: no device";
    return false;
  }
  const hal::ImuStatus s = imu_->start();
  if (s != hal::ImuStatus::kOk) {
    *error = std::string("imu: ") + hal::to_string(s) + ": " + imu_->last_error();
    return false;
  }
  stop_ = false;
  thread_ = std::thread([this] { run(); });
  return true;
}

void GyroReader::stop() {
  stop_ = true;
  if (thread_.joinable()) thread_.join();
  if (imu_) imu_->stop();
}

void GyroReader::run() {
  hal::GyroSample batch[32];
  bool reported = false;
  while (!stop_) {
    std::size_t n = 0;
    // 100 ms: how long stop() may wait for this thread.
    const hal::ImuStatus s = imu_->read(batch, 32, &n, 100'000'000);
    if (s == hal::ImuStatus::kOk) {
      for (std::size_t i = 0; i < n; ++i) {
        if (ring_.push({batch[i].t_ns, batch[i].gyro_z_radps})) ++samples_;
      }
      reported = false;
      continue;
    }
    if (s == hal::ImuStatus::kTimeout) continue;
    ++failures_;
    if (!reported) {  // once per outage, not once a second
      std::fprintf(stderr, "agvloc: imu: %s (%s); reopening every second\n", hal::to_string(s),
                   imu_->last_error());
      reported = true;
    }
    imu_->stop();
    for (int i = 0; i < 10 && !stop_; ++i)
      std::this_thread::sleep_for(std::chrono::milliseconds(100));
    if (stop_) break;
    if (imu_->start() == hal::ImuStatus::kOk) {
      ++reopens_;
      std::fprintf(stderr, "agvloc: imu: reopened\n");
    }
  }
}

GyroReaderCounters GyroReader::counters() const {
  return {samples_.load(), failures_.load(), reopens_.load()};
}

std::string format_gyro_counters(const GyroReaderCounters& c, std::uint64_t ring_dropped) {
  char buf[192];
  std::snprintf(buf, sizeof buf,
                "imu (iio): %" PRIu64 " samples, %" PRIu64 " dropped (ring full), %" PRIu64
                " failures, %" PRIu64 " reopens\n",
                c.samples, ring_dropped, c.failures, c.reopens);
  return buf;
}

}  // namespace agv::app
