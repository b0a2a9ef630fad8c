// GigE Vision / USB3 Vision camera through Aravis (libaravis-0.8). Mono8 only: the frames are
// handed out in place, no copy. Each frame's stamp comes from the camera's own clock (taken at
// the start of exposure by the cameras we know of), mapped onto CLOCK_MONOTONIC with a ClockMap
// fed by the host's receive time of the frame's first packet; cameras without a clock fall back
// to the receive time. Frame id gaps count as dropped frames.
//
//   agv::hal::CameraConfig cfg;
//   cfg.id = "Basler-acA1920-40gm-21234567";  // Aravis device id, an IP address, or "" = first
//   agv::aravis::AravisCamera cam(cfg);
//
// A GigE camera opened by device id is reached through the interface of whichever discovery answer
// Aravis kept; one reachable through several interfaces (only the loopback fake camera, in
// practice) is opened by IP address instead, which picks the interface by subnet.
//   if (cam.start() != agv::hal::CameraStatus::kOk) fail(cam.last_error());
//
// A camera that stops answering is reported as kDisconnected: Aravis's heartbeat reports lost
// control (GigE) or an unplug (USB3); besides, while a GigE camera sends nothing, the driver asks
// it for a register over its own socket, so a dead camera is known within disconnect_after_ns
// (or at once where the host answers "port unreachable") instead of after Aravis's 5 s of retries.
//
// One consumer thread calls next_frame/release; stats()/last_error() may be called from others.
#pragma once

#include <cstdint>
#include <memory>
#include <string>

#include "agv/common/clock_map.hpp"
#include "agv/hal/camera.hpp"

namespace agv::aravis {

// Frames missing between two GigE Vision / USB3 Vision frame ids. 16-bit ids (GigE Vision 1.x
// block ids) wrap from 65535 to 1, skipping 0; 64-bit ids do not wrap. An id that did not
// advance (a repeated or older frame) is no gap.
std::uint64_t frame_id_gap(std::uint64_t previous_id, std::uint64_t id);

// Linear gain factor (CameraConfig::analogue_gain) in the dB GenICam's Gain uses.
double gain_to_db(double gain);

struct AravisOptions {
  // Silence (no frame) after which a GigE camera is asked whether it is still there.
  std::int64_t probe_after_ns = 500'000'000;
  // Silence with no answer to those questions after which the camera counts as gone.
  std::int64_t disconnect_after_ns = 2'000'000'000;
  ClockMapConfig clock;
};

// The last frame's stamps, for logs and the clock's diagnostics.
struct FrameStamps {
  std::uint64_t frame_id = 0;
  std::uint64_t camera_ns = 0;  // arv_buffer_get_timestamp: the camera's clock (0: none)
  std::int64_t receive_ns = 0;  // host receive time of the first packet, CLOCK_MONOTONIC
  std::int64_t mapped_ns = 0;   // camera_ns on CLOCK_MONOTONIC (receive_ns without a clock)
  ClockSample clock_sample = ClockSample::kRefused;
};

class AravisCamera : public hal::Camera {
 public:
  explicit AravisCamera(hal::CameraConfig config, AravisOptions options = {});
  ~AravisCamera() override;
  AravisCamera(const AravisCamera&) = delete;
  AravisCamera& operator=(const AravisCamera&) = delete;

  hal::CameraStatus start() override;
  void stop() override;
  hal::CameraStatus next_frame(std::int64_t timeout_ns, hal::FrameView* frame) override;
  void release(const hal::FrameView& frame) override;
  hal::CameraStats stats() const override;
  const char* last_error() const override;

  // After start(): the camera's serial number and model, and what it accepted.
  std::string serial() const;
  std::string model() const;
  double frame_rate_hz() const;  // 0: the camera has no rate control
  double exposure_us() const;    // 0: no exposure control
  double gain_db() const;        // as the camera took it (some step in whole dB); NaN: none
  int buffers() const;
  int frames_outstanding() const;
  FrameStamps last_stamps() const;
  // The camera-to-host clock mapping (offset, drift, jumps). From the consumer thread only.
  const ClockMap& clock() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace agv::aravis
