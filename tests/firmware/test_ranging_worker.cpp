// The second camera's worker of the threaded loop (firmware/src/ranging_worker.cpp) on a scripted
// camera: frames of another size are counted, not read; a camera that disconnects is reopened; the
// end of a replayed stream ends the worker; every frame read is handed to the output step.
#include <gtest/gtest.h>

#include <chrono>
#include <thread>
#include <vector>

#include "agv/fakecamera/fake_camera.hpp"
#include "agv/posix/posix_clock.hpp"
#include "ranging_worker.hpp"

namespace agv::app {
namespace {

config::RangingCameraSection section() {
  config::RangingCameraSection rc;
  rc.enabled = true;
  rc.intrinsics = {
      .width_px = 64, .height_px = 48, .fx = 400.0, .fy = 400.0, .cx = 31.5, .cy = 23.5};
  rc.mount.z_mm = 1000.0;
  return rc;
}

// Runs a worker on `cam` (one landmark far out of view) until the camera's stream ends; false when
// it did not end within 20 s.
bool run_to_end(fakecamera::FakeCamera* cam, hal::Clock* clock, RangingCounts* counts,
                RangingRing* ring) {
  const RackSite site{.walls = {{.id = 3, .x_mm = 3000.0, .z_mm = 1000.0}}};
  RackObserver rack(section(), site);
  std::string err;
  EXPECT_TRUE(rack.ok(&err)) << err;
  SnapshotSlot snapshot{localizer::TimeBase{}};
  RangingWorker worker(cam, &rack, counts, ring, &snapshot, clock, 0);
  worker.start();
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(20);
  while (!worker.ended() && std::chrono::steady_clock::now() < deadline) {
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  worker.stop();
  return worker.ended();
}

TEST(RangingWorker, CountsWrongSizedFramesReopensAfterADisconnectAndEndsWithTheStream) {
  posix::PosixClock clock;
  fakecamera::FakeCamera cam({.clock = &clock, .end_of_stream_when_empty = true});
  const std::int64_t t0 = clock.now_ns();
  cam.push_frame(fakecamera::FakeCamera::solid(64, 48, 90), t0 + 1'000'000);
  cam.push_frame(fakecamera::FakeCamera::solid(32, 24, 90), t0 + 2'000'000);  // not the camera's
  cam.push_disconnect();
  cam.push_frame(fakecamera::FakeCamera::solid(64, 48, 90), t0 + 3'000'000);
  RangingCounts counts;
  RangingRing ring;
  ASSERT_TRUE(run_to_end(&cam, &clock, &counts, &ring));
  EXPECT_EQ(counts.frames, 2u);        // the two of the configured size, searched whole
  EXPECT_EQ(counts.frame_errors, 2u);  // the wrong size and the disconnect
  EXPECT_EQ(cam.start_calls(), 2);     // reopened once
  RangingRecord rec;
  int handed = 0;
  while (ring.pop(&rec)) {
    EXPECT_EQ(rec.n, 0u);  // plain frames: no landmark
    EXPECT_GE(rec.t_exposure_ns, t0);
    ++handed;
  }
  EXPECT_EQ(handed, 2);
}

TEST(RangingWorker, ACameraSilentForOverASecondIsOneStall) {
  posix::PosixClock clock;
  fakecamera::FakeCamera cam({.clock = &clock, .end_of_stream_when_empty = true});
  const std::int64_t t0 = clock.now_ns();
  cam.push_frame(fakecamera::FakeCamera::solid(64, 48, 90), t0);
  cam.push_stall(kRangingStallNs + 300'000'000);
  cam.push_frame(fakecamera::FakeCamera::solid(64, 48, 90), t0 + kRangingStallNs);
  cam.push_stall(100'000'000);  // short: not a stall
  cam.push_frame(fakecamera::FakeCamera::solid(64, 48, 90), t0 + kRangingStallNs + 1);
  RangingCounts counts;
  RangingRing ring;
  ASSERT_TRUE(run_to_end(&cam, &clock, &counts, &ring));
  EXPECT_EQ(counts.frames, 3u);
  EXPECT_EQ(counts.stalls, 1u);
}

}  // namespace
}  // namespace agv::app

namespace agv::app {
namespace {

// A floor fix that overruled the rack landmarks is said in the summary, with what to check.
TEST(RangingSummary, SaysWhenFloorFixesOverruledTheRackLandmarks) {
  RangingCounts c;
  c.frames = 30;
  localizer::OutputStats o;
  EXPECT_EQ(ranging_summary(c, o).find("overruled"), std::string::npos);
  o.ranging_floor_conflicts = 2;
  o.ranging_suspensions = 1;
  o.ranging_suspended_frames = 17;
  const std::string s = ranging_summary(c, o);
  EXPECT_NE(s.find("floor fixes overruled the rack landmarks 2 times"), std::string::npos) << s;
  EXPECT_NE(s.find("1 suspensions, 17 frames unused"), std::string::npos) << s;
  EXPECT_NE(s.find("mount calibration"), std::string::npos) << s;
  EXPECT_EQ(s.find("disagreed"), std::string::npos) << s;
}

// Floor fixes that disagreed one at a time (conflict_fixes not reached) are said too.
TEST(RangingSummary, SaysWhenLoneFloorFixesDisagreedWithTheRackLandmarks) {
  RangingCounts c;
  c.frames = 30;
  localizer::OutputStats o;
  o.ranging_floor_disputes = 3;
  std::string s = ranging_summary(c, o);
  EXPECT_NE(s.find("3 floor fixes disagreed with the rack landmarks"), std::string::npos) << s;
  EXPECT_EQ(s.find("overruled the rack landmarks"), std::string::npos) << s;
  EXPECT_EQ(s.find("twin"), std::string::npos) << s;
  o.ranging_floor_twin_resyncs = 2;
  s = ranging_summary(c, o);
  EXPECT_NE(s.find("the floor-only twin refused 2 floor fixes"), std::string::npos) << s;
}

}  // namespace
}  // namespace agv::app
