// The second camera in the threaded loop (`agvloc run`, `replay --realtime`): its own thread takes
// each frame from the driver, reads the rack landmarks in it (RackObserver) with the output
// thread's published pose as the prior (SnapshotSlot: the worker never calls the core), and hands
// the observations to the output step through the ranging ring. A camera that fails is reopened
// once a second; meanwhile the vehicle runs on its other aids.
#pragma once

#include <atomic>
#include <cstdint>
#include <functional>
#include <thread>

#include "agv/hal/camera.hpp"
#include "agv/hal/clock.hpp"
#include "output_loop.hpp"
#include "ranging_stream.hpp"
#include "snapshot_slot.hpp"

namespace agv::app {

class RangingWorker {
 public:
  // offset_ns: ranging_camera.time_offset_ms, the second camera's clock to the vehicle's.
  // thread_setup (may be empty) runs first on the worker's thread: its CPUs and priority, those of
  // the floor camera's vision thread, so that it never delays the output thread.
  RangingWorker(hal::Camera* camera, RackObserver* observer, RangingCounts* counts,
                RangingRing* ring, SnapshotSlot* snapshot, hal::Clock* clock,
                std::int64_t offset_ns, std::function<void()> thread_setup = {});
  ~RangingWorker();
  RangingWorker(const RangingWorker&) = delete;
  RangingWorker& operator=(const RangingWorker&) = delete;

  void start();
  void stop();  // joins; idempotent
  // The camera delivered its last frame (a replayed stream) and it has been handed over.
  bool ended() const { return ended_.load(); }
  bool busy() const { return busy_.load(); }

 private:
  void main();
  bool read_once(std::int64_t* retry_at_ns);  // false at the end of the stream
  void observe(const hal::FrameView& f);
  void watch_stall(bool frame);

  hal::Camera* camera_;
  RackObserver* observer_;
  RangingCounts* counts_;  // written by the worker; read after stop()
  RangingRing* ring_;
  SnapshotSlot* snapshot_;
  hal::Clock* clock_;
  const std::int64_t offset_ns_;
  std::function<void()> thread_setup_;
  std::atomic<bool> done_{false}, ended_{false}, busy_{false}, error_{false};
  RangingRecord rec_;
  std::int64_t last_frame_ns_ = 0;  // loop clock: the last frame, or the camera's (re)start
  bool stalled_ = false;
  std::thread thread_;
};

}  // namespace agv::app
