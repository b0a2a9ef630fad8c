// Gyro from a Linux IIO device through libiio's local backend (hal::Imu).
// start(): finds the device by name, enables anglvel_z (and anglvel_x/y when the device has
// them) and the timestamp, sets current_timestamp_clock to "monotonic" so that sample times are
// on the loop clock, sets sampling_frequency when the device has it, attaches the configured
// trigger, and enables a kernel buffer. read(): polls the buffer's fd, reads whole scans and
// converts them with the channel's scan format, scale and offset (anglvel in rad/s).
// Not thread-safe: one reader thread owns the object.
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>

#include "agv/hal/imu.hpp"
#include "agv/iio/scan_format.hpp"

struct iio_context;
struct iio_device;
struct iio_channel;
struct iio_buffer;

namespace agv::iio {

class IioImu final : public hal::Imu {
 public:
  explicit IioImu(hal::ImuConfig cfg) : cfg_(std::move(cfg)) {}
  ~IioImu() override { stop(); }
  IioImu(const IioImu&) = delete;
  IioImu& operator=(const IioImu&) = delete;

  hal::ImuStatus start() override;
  void stop() override;
  hal::ImuStatus read(hal::GyroSample* out, std::size_t max, std::size_t* n,
                      std::int64_t timeout_ns) override;
  hal::ImuStats stats() const override { return stats_; }
  const char* last_error() const override { return error_.c_str(); }

  // For checks and logs after start(): the scale applied to anglvel_z (rad/s per LSB), its
  // scan format, and the trigger in use.
  double z_scale() const { return axis_[2].scale; }
  const ScanFormat& z_format() const { return axis_[2].format; }
  const std::string& trigger_name() const { return trigger_in_use_; }

 private:
  struct Axis {
    iio_channel* ch = nullptr;
    ScanFormat format;
    double scale = 1.0;
    double offset = 0.0;
  };
  hal::ImuStatus fail(hal::ImuStatus s, const std::string& msg);
  hal::ImuStatus setup_axis(const char* name, Axis* a, bool required);
  hal::ImuStatus setup_rate();
  hal::ImuStatus setup_trigger();
  // Converts the scans between the buffer's start and end into out[]; returns how many.
  std::size_t convert(hal::GyroSample* out, std::size_t max);

  hal::ImuConfig cfg_;
  iio_context* ctx_ = nullptr;
  iio_device* dev_ = nullptr;
  iio_buffer* buf_ = nullptr;
  Axis axis_[3];  // x, y, z
  Axis ts_;
  bool has_xy_ = false;
  // Scans read but not yet handed out (read() got more than max): next call first.
  std::size_t pending_first_ = 0;
  std::size_t pending_count_ = 0;
  std::string trigger_in_use_;
  hal::ImuStats stats_;
  std::string error_;
};

}  // namespace agv::iio
