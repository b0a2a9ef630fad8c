// Gyro (yaw-rate) sample source outside CAN. Backends: drivers/iio (Linux IIO through libiio).
// The CAN gyro (AGV_Gyro) does not use this interface: it arrives as CAN frames (can_bus.hpp).
// No Linux or vendor headers here. read() never blocks longer than the timeout it is given.
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>

namespace agv::hal {

enum class ImuStatus : int {
  kOk = 0,
  kTimeout = 1,          // no sample within the timeout; try again
  kNotStarted = 2,       // start() has not succeeded
  kDisconnected = 3,     // no such device, or it disappeared; stop() and start() to recover
  kInvalidArgument = 4,  // configuration the device cannot do (no anglvel_z, no trigger ...)
  kDeviceError = 5,      // other driver failure; see last_error()
};

inline const char* to_string(ImuStatus s) {
  switch (s) {
    case ImuStatus::kOk:
      return "ok";
    case ImuStatus::kTimeout:
      return "timeout";
    case ImuStatus::kNotStarted:
      return "not started";
    case ImuStatus::kDisconnected:
      return "disconnected";
    case ImuStatus::kInvalidArgument:
      return "invalid argument";
    case ImuStatus::kDeviceError:
      return "device error";
  }
  return "unknown imu status";
}

struct ImuConfig {
  // Device name as the kernel reports it (IIO: /sys/bus/iio/devices/iio:deviceN/name, e.g.
  // "bmi160"), or "iio:deviceN".
  std::string device;
  // Trigger name (e.g. "bmi160-dev0", "sysfstrig0", an hrtimer's name); empty = keep the one
  // the device already has (its own data-ready trigger, if the kernel driver set it).
  std::string trigger;
  // Output data rate asked of the device; 0 = leave it. The device rounds to what it supports;
  // the achieved rate is in ImuStats::rate_hz.
  double rate_hz = 200.0;
  // Samples per kernel buffer read. More = fewer wake-ups, more latency at low rates.
  int buffer_samples = 16;
};

// One gyro sample. Angular rates in rad/s (right-handed about the sensor's axes, the IIO ABI's
// anglvel unit); t_ns on CLOCK_MONOTONIC, the loop clock.
struct GyroSample {
  std::int64_t t_ns = 0;
  double gyro_x_radps = 0.0;  // 0 when the device has no x channel (has_xy false)
  double gyro_y_radps = 0.0;
  double gyro_z_radps = 0.0;
  bool has_xy = false;
};

struct ImuStats {
  std::uint64_t samples = 0;
  std::uint64_t short_reads = 0;  // reads that ended inside a sample (partial sample dropped)
  std::uint64_t errors = 0;
  double rate_hz = 0.0;  // rate the device reports after start() (0 = unknown)
};

class Imu {
 public:
  virtual ~Imu() = default;
  // Opens the device, configures channels, rate, trigger and timestamp clock, starts the buffer.
  // kOk, kDisconnected (no such device), kInvalidArgument, kDeviceError.
  virtual ImuStatus start() = 0;
  // Stops the buffer and releases the device. Idempotent.
  virtual void stop() = 0;
  // Waits up to timeout_ns (0 = poll) for samples and writes up to max of them to out[] in time
  // order; *n = how many. kOk (*n >= 1), kTimeout (*n = 0), kNotStarted, kDisconnected,
  // kDeviceError.
  virtual ImuStatus read(GyroSample* out, std::size_t max, std::size_t* n,
                         std::int64_t timeout_ns) = 0;
  virtual ImuStats stats() const = 0;
  // Human-readable description of the last failure; empty when none.
  virtual const char* last_error() const = 0;
};

}  // namespace agv::hal
