// Camera interface. Backends: drivers/libcamera, drivers/v4l2, drivers/replay, drivers/fake.
// No Linux or vendor headers here.
#pragma once

#include <cstdint>
#include <string>

namespace agv::hal {

// Return codes shared by the camera methods.
enum class CameraStatus : int {
  kOk = 0,
  kTimeout = 1,       // no frame within the timeout; try again
  kEndOfStream = 2,   // replay finished; no more frames will come
  kNotStarted = 3,    // start() has not succeeded
  kDisconnected = 4,  // the device disappeared or stopped delivering; reopen to recover
  kInvalidArgument = 5,
  kDeviceError = 6,  // driver-specific failure; see last_error()
};

// Short name for logs ("ok", "timeout", ...). Inline so that users need only agv_hal.
inline const char* to_string(CameraStatus s) {
  switch (s) {
    case CameraStatus::kOk:
      return "ok";
    case CameraStatus::kTimeout:
      return "timeout";
    case CameraStatus::kEndOfStream:
      return "end of stream";
    case CameraStatus::kNotStarted:
      return "not started";
    case CameraStatus::kDisconnected:
      return "disconnected";
    case CameraStatus::kInvalidArgument:
      return "invalid argument";
    case CameraStatus::kDeviceError:
      return "device error";
  }
  return "unknown camera status";
}

// Which pixel formats a live driver may ask the sensor for. Every format ends up as 8-bit gray:
// GREY/R8 and the Y plane of NV12/YU12 are used in place; YUYV and packed RGB need one copy.
enum class PixelFormatPreference : int {
  kAuto = 0,  // gray if the camera offers it, else planar YUV, else YUYV, else packed RGB
  kGray = 1,  // only 8-bit monochrome (GREY / R8)
  kYuv = 2,   // only YUV (NV12, YU12, YUYV); for colour sensors
};

// Configuration shared by the live camera drivers (drivers/libcamera, drivers/v4l2).
// Validated by agv::camera::validate_config (drivers/camera_common). Trade-offs:
// docs/guide/camera.md.
struct CameraConfig {
  // libcamera: camera id (e.g. "/base/soc/i2c0mux/i2c@1/imx296@1a") or empty for "first camera
  // that matches `model`". V4L2: device node, e.g. "/dev/video0" (required).
  std::string id;
  // libcamera only: properties::Model to match (e.g. "imx296"); empty matches any.
  std::string model;
  int width_px = 640;
  int height_px = 480;
  // Frame rate. Higher gives more chances to see a landmark, costs CPU; the exposure must fit
  // into one frame period.
  double fps = 30.0;
  // Fixed exposure. Short = less motion blur (blur_px = v * t_exp / mm_per_px) but darker
  // images; compensate with light and gain. Default 500 us: 1 mm of blur at 2 m/s.
  int exposure_us = 500;
  // Fixed analogue gain (>= 1). Higher brightens but adds noise.
  double analogue_gain = 1.0;
  PixelFormatPreference pixel_format = PixelFormatPreference::kAuto;
  // Driver buffers in flight. More survive longer processing hiccups, cost memory and latency.
  int buffer_count = 4;
  // Rolling-shutter readout time from the first to the last row (0 for a global shutter);
  // shifts the frame timestamp to the centre row.
  int readout_us = 0;
};

// One 8-bit grayscale frame, borrowed from the driver. `data` stays valid until the frame is
// returned with release(); the driver owns the memory (no copy on the hot path).
struct FrameView {
  const std::uint8_t* data = nullptr;
  int width_px = 0;
  int height_px = 0;
  int stride_bytes = 0;
  // Exposure mid-time on the monotonic clock (CLOCK_MONOTONIC), nanoseconds.
  std::int64_t t_exposure_ns = 0;
  std::uint64_t sequence = 0;  // driver frame counter; gaps mean frames dropped by the driver
  int slot = -1;               // driver buffer index, passed back to release()
};

struct CameraStats {
  std::uint64_t frames_delivered = 0;
  std::uint64_t frames_dropped = 0;  // detected by sequence gaps or full queues
  std::uint64_t errors = 0;
};

class Camera {
 public:
  virtual ~Camera() = default;
  // Opens the device and starts streaming. kOk, kDisconnected (no such device),
  // kInvalidArgument (configuration not supported), kDeviceError.
  virtual CameraStatus start() = 0;
  // Stops streaming and releases device buffers. Idempotent. Frames not yet released become
  // invalid.
  virtual void stop() = 0;
  // Waits up to timeout_ns for the next frame. kOk fills *frame (which must be released);
  // kTimeout, kEndOfStream, kNotStarted, kDisconnected otherwise.
  virtual CameraStatus next_frame(std::int64_t timeout_ns, FrameView* frame) = 0;
  // Returns a frame's buffer to the driver. Releasing twice or a foreign slot is ignored.
  virtual void release(const FrameView& frame) = 0;
  virtual CameraStats stats() const = 0;
  // Human-readable description of the last failure; empty when none.
  virtual const char* last_error() const = 0;
};

}  // namespace agv::hal
