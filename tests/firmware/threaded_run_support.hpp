// What the tests of the threaded loop (run_threads on real threads, a fake camera and replay
// odometry) share: the camera, the odometry and the inputs they hand the loop.
#pragma once

#include <cstdint>
#include <vector>

#include "agv/fakecamera/fake_camera.hpp"
#include "pipeline.hpp"

namespace agv::test {

// A fake camera on `clock` whose stream ends once its script is played.
inline fakecamera::FakeCamera::Options scripted_camera(hal::Clock* clock) {
  fakecamera::FakeCamera::Options o;
  o.clock = clock;
  o.end_of_stream_when_empty = true;
  return o;
}

// Odometry rows every 10 ms over [from_ns, to_ns), driving straight at v_mps.
inline std::vector<recording::OdomRow> straight_odometry(std::int64_t from_ns, std::int64_t to_ns,
                                                         double v_mps) {
  std::vector<recording::OdomRow> odo;
  for (std::int64_t t = from_ns; t < to_ns; t += 10'000'000) odo.push_back({t, v_mps, 0.0});
  return odo;
}

// run_threads' inputs without the periodic log lines; records (ticks, fixes) are the caller's.
inline app::PipelineIo quiet_io(hal::Camera* camera, hal::CanBus* bus, hal::Clock* clock,
                                const std::vector<recording::OdomRow>* odometry) {
  app::PipelineIo io;
  io.camera = camera;
  io.bus = bus;
  io.clock = clock;
  io.odometry = odometry;
  io.quiet = true;
  return io;
}

}  // namespace agv::test
