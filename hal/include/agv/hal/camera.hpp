// Camera interface. Backends: drivers/libcamera, drivers/v4l2, drivers/replay, drivers/fake.
// No Linux or vendor headers here.
#pragma once

#include <cstdint>

namespace agv::hal {

// Return codes shared by the camera methods.
enum class CameraStatus : int {
  kOk = 0,
  kTimeout = 1,        // no frame within the timeout; try again
  kEndOfStream = 2,    // replay finished; no more frames will come
  kNotStarted = 3,     // start() has not succeeded
  kDisconnected = 4,   // the device disappeared or stopped delivering; reopen to recover
  kInvalidArgument = 5,
  kDeviceError = 6,    // driver-specific failure; see last_error()
};

const char* to_string(CameraStatus s);

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
  std::uint64_t frames_dropped = 0;   // detected by sequence gaps or full queues
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
