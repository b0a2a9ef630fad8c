#include "agv/iio/iio_imu.hpp"

#include <iio.h>
#include <poll.h>

#include <cerrno>
#include <cstring>
#include <fstream>

namespace agv::iio {

using hal::ImuStatus;

namespace {

std::string errno_text(int err) {
  char buf[128];
  iio_strerror(err, buf, sizeof buf);
  return buf;
}

// The scan format from sysfs (scan_elements/in_<ch>_type, the kernel's own text); libiio's
// parsed copy when the file is not readable (a non-local backend).
bool channel_format(iio_device* dev, iio_channel* ch, ScanFormat* f) {
  const char* id = iio_device_get_id(dev);
  const std::string path = std::string("/sys/bus/iio/devices/") + id + "/scan_elements/in_" +
                           iio_channel_get_id(ch) + "_type";
  std::ifstream in(path);
  std::string text;
  if (in && std::getline(in, text)) return parse_scan_format(text, f);
  const iio_data_format* d = iio_channel_get_data_format(ch);
  if (!d) return false;
  f->big_endian = d->is_be;
  f->is_signed = d->is_signed;
  f->bits = static_cast<int>(d->bits);
  f->storage_bits = static_cast<int>(d->length);
  f->shift = static_cast<int>(d->shift);
  f->repeat = static_cast<int>(d->repeat);
  return f->bits >= 1 && f->bits + f->shift <= f->storage_bits;
}

// Errors after which the device must be reopened.
bool is_gone(int err) { return err == ENODEV || err == ENXIO || err == EBADF || err == EIO; }

}  // namespace

ImuStatus IioImu::fail(ImuStatus s, const std::string& msg) {
  error_ = msg;
  ++stats_.errors;
  return s;
}

ImuStatus IioImu::setup_axis(const char* name, Axis* a, bool required) {
  a->ch = iio_device_find_channel(dev_, name, false);
  if (!a->ch || !iio_channel_is_scan_element(a->ch)) {
    a->ch = nullptr;
    if (!required) return ImuStatus::kOk;
    return fail(ImuStatus::kInvalidArgument,
                std::string("device '") + cfg_.device + "' has no buffered channel " + name);
  }
  if (!channel_format(dev_, a->ch, &a->format) || a->format.repeat != 1) {
    return fail(ImuStatus::kInvalidArgument, std::string("unusable scan format of ") + name);
  }
  // Timestamps have no scale; anglvel must have one (rad/s per LSB), offset is optional.
  a->scale = 1.0;
  a->offset = 0.0;
  if (iio_channel_find_attr(a->ch, "scale")) {
    if (iio_channel_attr_read_double(a->ch, "scale", &a->scale) < 0 || !(a->scale > 0.0)) {
      return fail(ImuStatus::kDeviceError, std::string("cannot read the scale of ") + name);
    }
  } else if (std::strcmp(name, "timestamp") != 0) {
    return fail(ImuStatus::kInvalidArgument, std::string(name) + " has no scale attribute");
  }
  if (iio_channel_find_attr(a->ch, "offset"))
    iio_channel_attr_read_double(a->ch, "offset", &a->offset);
  iio_channel_enable(a->ch);
  return ImuStatus::kOk;
}

ImuStatus IioImu::setup_rate() {
  if (cfg_.rate_hz <= 0.0) return ImuStatus::kOk;
  // Shared by type (in_anglvel_sampling_frequency) or by the whole device.
  iio_channel* ch = axis_[2].ch;
  int r = -ENOENT;
  if (iio_channel_find_attr(ch, "sampling_frequency")) {
    r = iio_channel_attr_write_double(ch, "sampling_frequency", cfg_.rate_hz);
    if (r >= 0) r = iio_channel_attr_read_double(ch, "sampling_frequency", &stats_.rate_hz);
  } else if (iio_device_find_attr(dev_, "sampling_frequency")) {
    r = iio_device_attr_write_double(dev_, "sampling_frequency", cfg_.rate_hz);
    if (r >= 0) r = iio_device_attr_read_double(dev_, "sampling_frequency", &stats_.rate_hz);
  } else {
    return ImuStatus::kOk;  // the trigger sets the rate (e.g. an hrtimer's own frequency)
  }
  if (r < 0) {
    return fail(ImuStatus::kInvalidArgument,
                "sampling_frequency " + std::to_string(cfg_.rate_hz) + ": " + errno_text(-r));
  }
  return ImuStatus::kOk;
}

ImuStatus IioImu::setup_trigger() {
  if (!cfg_.trigger.empty()) {
    const iio_device* trig = iio_context_find_device(ctx_, cfg_.trigger.c_str());
    if (!trig || !iio_device_is_trigger(trig)) {
      return fail(ImuStatus::kInvalidArgument, "no IIO trigger named '" + cfg_.trigger + "'");
    }
    const int r = iio_device_set_trigger(dev_, trig);
    if (r < 0) return fail(ImuStatus::kDeviceError, "set trigger: " + errno_text(-r));
    trigger_in_use_ = cfg_.trigger;
    return ImuStatus::kOk;
  }
  const iio_device* trig = nullptr;
  if (iio_device_get_trigger(dev_, &trig) < 0 || !trig) {
    return fail(ImuStatus::kInvalidArgument,
                "device '" + cfg_.device + "' has no trigger; name one (imu.iio.trigger)");
  }
  const char* name = iio_device_get_name(trig);
  trigger_in_use_ = name ? name : iio_device_get_id(trig);
  return ImuStatus::kOk;
}

ImuStatus IioImu::start() {
  stop();
  error_.clear();
  if (cfg_.device.empty()) return fail(ImuStatus::kInvalidArgument, "no IIO device name");
  if (cfg_.buffer_samples < 1) return fail(ImuStatus::kInvalidArgument, "buffer_samples < 1");
  ctx_ = iio_create_local_context();
  if (!ctx_) return fail(ImuStatus::kDisconnected, "no IIO context: " + errno_text(errno));
  dev_ = iio_context_find_device(ctx_, cfg_.device.c_str());
  if (!dev_) {
    stop();
    return fail(ImuStatus::kDisconnected, "no IIO device '" + cfg_.device + "'");
  }
  // Only our channels in the scan: fewer bytes per sample and a known layout.
  for (unsigned i = 0; i < iio_device_get_channels_count(dev_); ++i) {
    iio_channel_disable(iio_device_get_channel(dev_, i));
  }
  ImuStatus s = ImuStatus::kOk;
  if (s == ImuStatus::kOk) s = setup_axis("anglvel_z", &axis_[2], true);
  if (s == ImuStatus::kOk) s = setup_axis("anglvel_x", &axis_[0], false);
  if (s == ImuStatus::kOk) s = setup_axis("anglvel_y", &axis_[1], false);
  if (s == ImuStatus::kOk) s = setup_axis("timestamp", &ts_, true);
  if (s == ImuStatus::kOk && ts_.format.storage_bits != 64) {
    s = fail(ImuStatus::kInvalidArgument, "timestamp is not 64 bits wide");
  }
  // The kernel stamps samples on CLOCK_REALTIME unless told otherwise: the loop clock is
  // CLOCK_MONOTONIC, and realtime jumps with NTP.
  if (s == ImuStatus::kOk && iio_device_find_attr(dev_, "current_timestamp_clock") &&
      iio_device_attr_write(dev_, "current_timestamp_clock", "monotonic") < 0) {
    s = fail(ImuStatus::kDeviceError, "cannot set current_timestamp_clock to monotonic");
  }
  if (s == ImuStatus::kOk) s = setup_rate();
  if (s == ImuStatus::kOk) s = setup_trigger();
  if (s != ImuStatus::kOk) {
    const std::string e = error_;
    stop();
    error_ = e;
    return s;
  }
  has_xy_ = axis_[0].ch && axis_[1].ch;
  if (!has_xy_) {
    if (axis_[0].ch) iio_channel_disable(axis_[0].ch);
    if (axis_[1].ch) iio_channel_disable(axis_[1].ch);
    axis_[0].ch = axis_[1].ch = nullptr;
  }
  buf_ = iio_device_create_buffer(dev_, static_cast<std::size_t>(cfg_.buffer_samples), false);
  if (!buf_) {
    const int err = errno;
    stop();
    return fail(is_gone(err) ? ImuStatus::kDisconnected : ImuStatus::kDeviceError,
                "cannot enable the buffer: " + errno_text(err));
  }
  iio_buffer_set_blocking_mode(buf_, false);  // read() waits in poll() with its own timeout
  pending_first_ = pending_count_ = 0;
  return ImuStatus::kOk;
}

void IioImu::stop() {
  if (buf_) iio_buffer_destroy(buf_);
  buf_ = nullptr;
  if (ctx_) iio_context_destroy(ctx_);
  ctx_ = nullptr;
  dev_ = nullptr;
  for (Axis& a : axis_) a.ch = nullptr;
  ts_.ch = nullptr;
}

std::size_t IioImu::convert(hal::GyroSample* out, std::size_t max) {
  const std::ptrdiff_t step = iio_buffer_step(buf_);
  const auto* ts = static_cast<const std::uint8_t*>(iio_buffer_first(buf_, ts_.ch));
  const auto* z = static_cast<const std::uint8_t*>(iio_buffer_first(buf_, axis_[2].ch));
  const std::uint8_t* x = nullptr;
  const std::uint8_t* y = nullptr;
  if (has_xy_) {
    x = static_cast<const std::uint8_t*>(iio_buffer_first(buf_, axis_[0].ch));
    y = static_cast<const std::uint8_t*>(iio_buffer_first(buf_, axis_[1].ch));
  }
  std::size_t n = 0;
  while (n < max && pending_count_ > 0) {
    const std::ptrdiff_t o = static_cast<std::ptrdiff_t>(pending_first_) * step;
    hal::GyroSample& s = out[n++];
    s.t_ns = decode_raw(ts + o, ts_.format);
    s.gyro_z_radps =
        apply_scale(decode_raw(z + o, axis_[2].format), axis_[2].scale, axis_[2].offset);
    s.has_xy = has_xy_;
    if (has_xy_) {
      s.gyro_x_radps =
          apply_scale(decode_raw(x + o, axis_[0].format), axis_[0].scale, axis_[0].offset);
      s.gyro_y_radps =
          apply_scale(decode_raw(y + o, axis_[1].format), axis_[1].scale, axis_[1].offset);
    } else {
      s.gyro_x_radps = s.gyro_y_radps = 0.0;
    }
    ++pending_first_;
    --pending_count_;
  }
  stats_.samples += n;
  return n;
}

ImuStatus IioImu::read(hal::GyroSample* out, std::size_t max, std::size_t* n,
                       std::int64_t timeout_ns) {
  *n = 0;
  if (!buf_) return ImuStatus::kNotStarted;
  if (max == 0) return ImuStatus::kOk;
  if (pending_count_ == 0) {
    // The buffer's watermark may be more than one scan: wait for it up to the timeout, then
    // take whatever is there (non-blocking refill).
    pollfd p{iio_buffer_get_poll_fd(buf_), POLLIN, 0};
    const int ms = timeout_ns <= 0 ? 0 : static_cast<int>((timeout_ns + 999'999) / 1'000'000);
    const int pr = poll(&p, 1, ms);
    if (pr < 0 && errno != EINTR)
      return fail(ImuStatus::kDeviceError, "poll: " + errno_text(errno));
    if (pr > 0 && (p.revents & (POLLERR | POLLHUP | POLLNVAL)) != 0 && (p.revents & POLLIN) == 0) {
      return fail(ImuStatus::kDisconnected, "IIO buffer hung up (device removed?)");
    }
    const ssize_t got = iio_buffer_refill(buf_);
    if (got == -EAGAIN || got == 0) return ImuStatus::kTimeout;
    if (got < 0) {
      const int err = static_cast<int>(-got);
      return fail(is_gone(err) ? ImuStatus::kDisconnected : ImuStatus::kDeviceError,
                  "buffer read: " + errno_text(err));
    }
    const std::size_t step = static_cast<std::size_t>(iio_buffer_step(buf_));
    if (step == 0) return fail(ImuStatus::kDeviceError, "zero scan size");
    if (static_cast<std::size_t>(got) % step != 0) ++stats_.short_reads;  // tail dropped
    pending_first_ = 0;
    pending_count_ = static_cast<std::size_t>(got) / step;
    if (pending_count_ == 0) return ImuStatus::kTimeout;
  }
  *n = convert(out, max);
  return ImuStatus::kOk;
}

}  // namespace agv::iio
