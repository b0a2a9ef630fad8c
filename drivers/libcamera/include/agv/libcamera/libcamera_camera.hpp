// libcamera capture driver (Raspberry Pi cameras, vimc, any sensor with a libcamera pipeline).
// Camera chosen by CameraConfig::id or ::model; stream format GREY/R8 or YUV (NV12, YU12 used in
// place; YUYV copied to gray); fixed ExposureTime and AnalogueGain with auto exposure off;
// FrameDurationLimits pinned to 1/fps. SensorTimestamp (start of exposure of the first row) is
// turned into exposure mid-time on CLOCK_MONOTONIC. The requestCompleted callback only hands the
// request to a bounded newest-wins queue; all processing runs on the thread calling next_frame.
// cameraRemoved, cancelled requests or no frame for `stall_timeout_ns()` -> kDisconnected.
//
//   agv::hal::CameraConfig cfg;
//   cfg.model = "imx296"; cfg.width_px = 1280; cfg.height_px = 800; cfg.exposure_us = 300;
//   agv::libcam::LibcameraCamera cam(cfg);
//   if (cam.start() != agv::hal::CameraStatus::kOk) fail(cam.last_error());
//   agv::hal::FrameView f;
//   if (cam.next_frame(100'000'000, &f) == agv::hal::CameraStatus::kOk) { use(f); cam.release(f); }
//
// libcamera allows one CameraManager per process: one LibcameraCamera started at a time.
#pragma once

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "agv/hal/camera.hpp"

namespace agv::libcam {

struct CameraInfo {
  std::string id;
  std::string model;
};

// Index of the camera to use: exact id match when `id` is set (and the model must match too when
// both are set); else the first camera whose model equals `model`; else, with both empty, the
// first camera. -1 when none matches.
int select_camera(const std::vector<CameraInfo>& cameras, const std::string& id,
                  const std::string& model);

// Cameras libcamera sees right now (starts and stops a CameraManager; not while a
// LibcameraCamera is started). Empty with *error set on failure.
std::vector<CameraInfo> list_cameras(std::string* error);

class LibcameraCamera : public hal::Camera {
 public:
  explicit LibcameraCamera(hal::CameraConfig config);
  ~LibcameraCamera() override;
  LibcameraCamera(const LibcameraCamera&) = delete;
  LibcameraCamera& operator=(const LibcameraCamera&) = delete;

  hal::CameraStatus start() override;
  void stop() override;
  hal::CameraStatus next_frame(std::int64_t timeout_ns, hal::FrameView* frame) override;
  void release(const hal::FrameView& frame) override;
  hal::CameraStats stats() const override;
  const char* last_error() const override;

  // After start().
  std::string camera_id() const;
  std::uint32_t fourcc() const;
  int stride_bytes() const;
  bool exposure_applied() const;  // false: the pipeline has no ExposureTime control
  int buffers() const;
  int frames_outstanding() const;
  // No completed request for this long while the camera holds buffers -> kDisconnected.
  // max(2 s, 20 frame periods).
  std::int64_t stall_timeout_ns() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace agv::libcam
