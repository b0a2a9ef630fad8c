// Scripted in-process camera for unit tests of the localization loop. The test pushes events
// (frames, stalls, disconnects, end of stream); next_frame() plays them back in order.
// Behaves like the live drivers where it matters for the loop: a fixed number of buffer slots
// (a frame that finds no free slot is dropped and counted, like a starved V4L2 queue), frames
// stay valid until release(), kDisconnected is sticky until stop()+start().
//
//   agv::fakecamera::FakeCamera cam;
//   cam.push_frame(agv::fakecamera::FakeCamera::solid(640, 480, 128), 1'000'000);
//   cam.push_stall(50'000'000);   // 50 ms without frames
//   cam.push_disconnect();
//   cam.start();
//   agv::hal::FrameView f;
//   if (cam.next_frame(100'000'000, &f) == agv::hal::CameraStatus::kOk) { ...; cam.release(f); }
//
// Thread-safe: events may be pushed from another thread while the loop consumes them.
#pragma once

#include <condition_variable>
#include <cstdint>
#include <deque>
#include <mutex>
#include <string>
#include <vector>

#include "agv/hal/camera.hpp"
#include "agv/hal/clock.hpp"

namespace agv::fakecamera {

struct FakeImage {
  int width_px = 0;
  int height_px = 0;
  std::vector<std::uint8_t> gray;  // width*height bytes, row-major, stride = width
};

class FakeCamera : public hal::Camera {
 public:
  struct Options {
    int slots = 3;  // buffers the "driver" owns; like CameraConfig::buffer_count
    // Stalls and timeouts: with a clock, time passes on that clock (sleep_until_ns, so a
    // simulated clock just advances); without one they are instantaneous.
    hal::Clock* clock = nullptr;
    // When the script is empty: true -> kEndOfStream, false -> kTimeout (a camera that
    // delivers nothing; with `wait_for_events` next_frame blocks up to the timeout for a push).
    bool end_of_stream_when_empty = false;
    bool wait_for_events = false;
    // Status start() returns (e.g. kDisconnected to simulate a missing camera).
    hal::CameraStatus start_status = hal::CameraStatus::kOk;
  };

  FakeCamera();
  explicit FakeCamera(Options options);

  // Script. `sequence` < 0 means "previous + 1".
  void push_frame(FakeImage image, std::int64_t t_exposure_ns, std::int64_t sequence = -1);
  void push_stall(std::int64_t duration_ns);
  void push_disconnect();
  void push_end_of_stream();
  void set_start_status(hal::CameraStatus s);

  static FakeImage solid(int width_px, int height_px, std::uint8_t value);

  // hal::Camera
  hal::CameraStatus start() override;
  void stop() override;
  hal::CameraStatus next_frame(std::int64_t timeout_ns, hal::FrameView* frame) override;
  void release(const hal::FrameView& frame) override;
  hal::CameraStats stats() const override;
  const char* last_error() const override;

  // Inspection for tests.
  int frames_outstanding() const;  // handed out, not yet released
  int start_calls() const;
  int stop_calls() const;
  std::size_t events_pending() const;

 private:
  enum class Kind { kFrame, kStall, kDisconnect, kEndOfStream };
  struct Event {
    Kind kind = Kind::kFrame;
    FakeImage image;
    std::int64_t t_ns = 0;  // frame: exposure mid-time; stall: remaining duration
    std::uint64_t sequence = 0;
  };
  struct Slot {
    bool busy = false;
    FakeImage image;
  };

  // Queues an event for next_frame; a frame is numbered `sequence`, or previous + 1 when that is
  // < 0.
  void push_event(Kind kind, std::int64_t t_ns = 0, FakeImage image = {},
                  std::int64_t sequence = -1);
  void wait_ns(std::int64_t ns);

  Options options_;
  mutable std::mutex mutex_;
  std::condition_variable cv_;
  std::deque<Event> events_;
  std::vector<Slot> slots_;
  bool started_ = false;
  bool disconnected_ = false;
  bool ended_ = false;
  std::uint64_t next_sequence_ = 0;
  std::int64_t last_sequence_ = -1;
  hal::CameraStats stats_;
  std::string error_;
  int start_calls_ = 0;
  int stop_calls_ = 0;
};

}  // namespace agv::fakecamera
