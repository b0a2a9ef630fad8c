// The gyro reader thread of `agvloc run` with imu.source iio: reads a hal::Imu (drivers/iio)
// and hands the samples to the output thread through a lock-free ring, so the real-time thread
// never waits on the device. A device that fails is reopened once a second; meanwhile no
// samples arrive and the core raises FaultImuTimeout (can.gyro.timeout_ms) as for the CAN gyro.
#pragma once

#include <atomic>
#include <cstdint>
#include <memory>
#include <string>
#include <thread>

#include "agv/hal/imu.hpp"
#include "handoff.hpp"

namespace agv::app {

struct GyroRow {
  std::int64_t t_ns = 0;  // CLOCK_MONOTONIC, the loop clock
  double gyro_z_radps = 0.0;
};

// Reader -> output thread. 512 samples = 2.5 s at 200 Hz: far longer than any output period.
using GyroRing = SpscRing<GyroRow, 512>;

struct GyroReaderCounters {
  std::uint64_t samples = 0;   // pushed into the ring
  std::uint64_t failures = 0;  // read or reopen failures
  std::uint64_t reopens = 0;   // successful restarts after a failure
};

class GyroReader {
 public:
  GyroReader(std::unique_ptr<hal::Imu> imu, GyroRing& ring) : imu_(std::move(imu)), ring_(ring) {}
  ~GyroReader() { stop(); }
  GyroReader(const GyroReader&) = delete;
  GyroReader& operator=(const GyroReader&) = delete;

  // Starts the device here (a missing IMU fails `agvloc run` at once, with the driver's reason),
  // then the thread. False with *error on failure.
  bool start(std::string* error);
  // Stops the thread and the device. Idempotent.
  void stop();
  GyroReaderCounters counters() const;
  double rate_hz() const { return imu_ ? imu_->stats().rate_hz : 0.0; }

 private:
  void run();

  std::unique_ptr<hal::Imu> imu_;
  GyroRing& ring_;
  std::thread thread_;
  std::atomic<bool> stop_{false};
  std::atomic<std::uint64_t> samples_{0};
  std::atomic<std::uint64_t> failures_{0};
  std::atomic<std::uint64_t> reopens_{0};
};

// One line for the end-of-run statistics.
std::string format_gyro_counters(const GyroReaderCounters& c, std::uint64_t ring_dropped);

}  // namespace agv::app
