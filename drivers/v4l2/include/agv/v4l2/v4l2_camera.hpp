// V4L2 memory-mapped streaming camera (single-planar capture devices: UVC, vivid, many
// global-shutter modules). Formats GREY, NV12, YU12 are delivered in place (no copy); YUYV is
// converted to gray with one copy. Timestamps follow the buffer flags: CLOCK_MONOTONIC stamps
// marking start of exposure or end of frame are turned into exposure mid-time; drivers with
// other clocks fall back to the dequeue time (treated as end of frame).
//
//   agv::hal::CameraConfig cfg;
//   cfg.id = "/dev/video0"; cfg.width_px = 640; cfg.height_px = 480; cfg.fps = 30;
//   agv::v4l2::V4l2Camera cam(cfg);
//   if (cam.start() != agv::hal::CameraStatus::kOk) fail(cam.last_error());
//   agv::hal::FrameView f;
//   while (cam.next_frame(200'000'000, &f) == agv::hal::CameraStatus::kOk) { use(f);
//   cam.release(f); }
//
// One consumer thread calls next_frame/release; stats()/last_error() may be called from others.
#pragma once

#include <cstdint>
#include <memory>
#include <string>

#include "agv/camera/common.hpp"
#include "agv/hal/camera.hpp"

namespace agv::v4l2 {

// Meaning of a V4L2 buffer's timestamp, from its flags.
struct TimestampKind {
  bool monotonic = false;  // V4L2_BUF_FLAG_TIMESTAMP_MONOTONIC
  camera::TimestampRef ref = camera::TimestampRef::kEndOfFrame;  // TSTAMP_SRC_SOE / _EOF
};
TimestampKind timestamp_kind(std::uint32_t buffer_flags);

// Exposure mid-time on CLOCK_MONOTONIC for one dequeued buffer. Non-monotonic stamps are
// replaced by `dequeue_mono_ns` (the best end-of-frame estimate available).
std::int64_t frame_time_ns(std::uint32_t buffer_flags, std::int64_t buffer_ts_ns,
                           std::int64_t dequeue_mono_ns, std::int64_t exposure_ns,
                           std::int64_t readout_ns);

class V4l2Camera : public hal::Camera {
 public:
  explicit V4l2Camera(hal::CameraConfig config);
  ~V4l2Camera() override;
  V4l2Camera(const V4l2Camera&) = delete;
  V4l2Camera& operator=(const V4l2Camera&) = delete;

  hal::CameraStatus start() override;
  void stop() override;
  hal::CameraStatus next_frame(std::int64_t timeout_ns, hal::FrameView* frame) override;
  void release(const hal::FrameView& frame) override;
  hal::CameraStats stats() const override;
  const char* last_error() const override;

  // Use exactly this format (one of those acceptable under kAuto) instead of the preference
  // order, for cameras whose "best" format is worse in practice (e.g. a UVC camera that
  // delivers NV12 at a lower rate than YUYV). 0 restores the automatic choice. Before start().
  void force_fourcc(std::uint32_t fourcc);

  // After start(): negotiated format and what the device accepted.
  std::uint32_t fourcc() const;
  int stride_bytes() const;
  bool exposure_applied() const;  // false: device has no manual exposure control
  int buffers() const;            // buffers granted by the driver
  // Frame period the device reports after the rate request (0: unknown). Devices with discrete
  // rates pick the nearest one, e.g. vivid gives 40 ms for a 30 fps request at 640x480.
  std::int64_t frame_period_ns() const;
  // Frames handed out and not released.
  int frames_outstanding() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace agv::v4l2
