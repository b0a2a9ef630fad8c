// agvloc-overhead's live loop (overhead/src/live.cpp) on scripted cameras: frames rendered from
// the test site reach the tracker from one thread per camera, every vehicle is published at the
// configured rate on the monotonic clock, a camera that disconnects is reopened, and cameras that
// cannot be opened are named, never a crash.
#include <gtest/gtest.h>

#include <atomic>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <map>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "../support/loopback_client.hpp"
#include "agv/fakecamera/fake_camera.hpp"
#include "agv/posix/posix_clock.hpp"
#include "agv/sim/site_render.hpp"
#include "core.hpp"
#include "diag.hpp"
#include "inputs.hpp"
#include "live.hpp"
#include "two_camera_frames.hpp"

namespace agv::overhead_app {
namespace {

namespace fs = std::filesystem;

constexpr std::int64_t kFramePeriodNs = 100'000'000;  // 10 fps
constexpr int kFrames = 12;

// tracks.csv rows by vehicle: (t_ns, x, y, theta, state).
struct Row {
  std::int64_t t_ns;
  double x, y, theta;
  std::string state;
};
std::map<std::string, std::vector<Row>> read_tracks(const fs::path& p) {
  std::ifstream f(p);
  std::string line;
  std::getline(f, line);
  std::map<std::string, std::vector<Row>> out;
  while (std::getline(f, line)) {
    std::stringstream ss(line);
    std::vector<std::string> v;
    for (std::string cell; std::getline(ss, cell, ',');) v.push_back(cell);
    if (v.size() != 10) continue;
    out[v[1]].push_back(
        {std::stoll(v[0]), std::stod(v[2]), std::stod(v[3]), std::stod(v[4]), v[9]});
  }
  return out;
}

class OverheadLive : public ::testing::Test {
 protected:
  void SetUp() override {
    out_ = fs::temp_directory_path() /
           ("overhead_live_" +
            std::string(::testing::UnitTest::GetInstance()->current_test_info()->name()));
    fs::remove_all(out_);
  }
  void TearDown() override { fs::remove_all(out_); }
  fs::path out_;
};

TEST_F(OverheadLive, TracksTwoCamerasAtTheRateAndReopensADisconnectedCamera) {
  const site::Site s = test::two_camera_site();
  ASSERT_EQ(s.cameras.size(), 2u);
  const std::vector<sim::AgvState> agvs = test::two_vehicles();
  posix::PosixClock clock;
  const fakecamera::FakeCamera::Options opt = test::scripted_camera(&clock);
  std::vector<LiveCamera> cams;
  std::vector<fakecamera::FakeCamera*> fakes;
  const fakecamera::FakeImage imgs[2] = {test::render_fake_frame(s, 0, agvs),
                                         test::render_fake_frame(s, 1, agvs)};
  OverheadConfig cfg;
  TrackerCore core(cfg, s);  // before the stamps start (DiagnosticsServeMetricsWhileRunning)
  std::string err;
  ASSERT_TRUE(core.open_outputs(out_.string(), &err)) << err;
  const std::int64_t t0 = monotonic_ns();
  for (std::size_t c = 0; c < 2; ++c) {
    auto fake = std::make_unique<fakecamera::FakeCamera>(opt);
    const fakecamera::FakeImage& img = imgs[c];
    for (int k = 0; k < kFrames; ++k) {
      fake->push_stall(kFramePeriodNs);
      fake->push_frame(img, t0 + (k + 1) * kFramePeriodNs - 30'000'000);
      if (c == 1 && k == kFrames - 3) fake->push_disconnect();
    }
    fakes.push_back(fake.get());
    cams.push_back({s.cameras[c].id, c, std::move(fake)});
  }
  const std::atomic<bool> stop{false};
  const LiveCounters n = run_live(&cams, &core, stop, 20'000'000'000);
  ASSERT_TRUE(core.finish("test", cams.size(), &err)) << err;

  // A slow machine (an emulator) drops frames when the pipeline falls behind; none is lost.
  EXPECT_EQ(core.frames() + n.frames_dropped, 2u * kFrames);
  EXPECT_EQ(n.reopens, 1u);
  EXPECT_EQ(fakes[1]->start_calls(), 2);
  EXPECT_EQ(fakes[0]->start_calls(), 1);
  EXPECT_GE(n.ticks, 30u);  // ~1.2 s of frames and the 1 s reopen at 30 Hz
  const auto tracks = read_tracks(out_ / "tracks.csv");
  ASSERT_EQ(tracks.size(), 2u);
  for (std::size_t i = 0; i < 2; ++i) {
    const std::vector<Row>& rows = tracks.at(s.fleet[i].id);
    // A tick is stamped on the host's clock: on a loaded machine (a sanitizer build beside other
    // tests) the newest processed fix may be older than coast_after_ms at the tick, and the
    // parked vehicle is reported coasting instead of confirmed. Both are reported poses.
    int confirmed = 0;
    int reported = 0;
    for (const Row& r : rows) {
      if (r.state != "confirmed" && r.state != "coasting") continue;
      ++reported;
      confirmed += r.state == "confirmed";
      EXPECT_NEAR(r.x, agvs[i].pose.x_mm, 5.0) << s.fleet[i].id << " t " << r.t_ns;
      EXPECT_NEAR(r.y, agvs[i].pose.y_mm, 5.0) << s.fleet[i].id << " t " << r.t_ns;
      EXPECT_NEAR(std::remainder(r.theta - agvs[i].pose.theta_rad, 2 * M_PI), 0.0, 0.01);
    }
    EXPECT_GE(confirmed, 1) << s.fleet[i].id;
    EXPECT_GE(reported, 5) << s.fleet[i].id;
    // Ticks at the configured period (30 Hz) on the monotonic clock; a tick late by more than a
    // period (a loaded machine) is published at once, so the spacing is never shorter.
    std::size_t on_time = 0;
    for (std::size_t k = 1; k + 1 < rows.size(); ++k) {
      EXPECT_GE(rows[k].t_ns - rows[k - 1].t_ns, core.period_ns()) << k;
      on_time += rows[k].t_ns - rows[k - 1].t_ns == core.period_ns();
    }
    EXPECT_GE(on_time * 2, rows.size()) << s.fleet[i].id;
  }
}

// Publish ticks run on the host's clock and may be ahead of the newest frame processed (frames
// queued on a loaded machine): a tentative track is not dropped for the age of its fix at the
// tick, and the next frame's fix continues it instead of starting it again.
TEST_F(OverheadLive, APipelineBehindItsCamerasKeepsItsTentativeTracks) {
  const site::Site s = test::two_camera_site();
  const fakecamera::FakeImage img = test::render_fake_frame(s, 0, test::two_vehicles());
  const cv::Mat gray(img.height_px, img.width_px, CV_8UC1,
                     const_cast<std::uint8_t*>(img.gray.data()));
  OverheadConfig cfg;
  TrackerCore core(cfg, s);
  const std::int64_t t1 = 5'000'000'000;
  core.process(0, t1, gray);
  ASSERT_EQ(core.tracker().counters().started, 1u);
  core.publish(t1 + 600'000'000);  // twice coast_after_ms past the fix, no frame since
  core.process(0, t1 + 100'000'000, gray);
  EXPECT_EQ(core.tracker().counters().started, 1u);
  EXPECT_EQ(core.tracker().counters().applied, 1u);
}

TEST_F(OverheadLive, CamerasWithoutDeviceOrWithBadSettingsAreRefused) {
  const site::Site s = test::two_camera_site();
  OverheadConfig cfg;
  std::vector<LiveCamera> cams;
  std::string err;
  EXPECT_FALSE(make_live_cameras(cfg, s, &cams, &err));
  EXPECT_NE(err.find("cameras.<id>.device"), std::string::npos) << err;
  cfg.cameras["cam-east"].device = "/dev/video97";
  cfg.cameras["cam-east"].exposure_us = 900'000;  // longer than a frame at 30 fps
  EXPECT_FALSE(make_live_cameras(cfg, s, &cams, &err));
  EXPECT_NE(err.find("cameras.cam-east: "), std::string::npos) << err;
  cfg.cameras["cam-east"].exposure_us = 500;
  ASSERT_TRUE(make_live_cameras(cfg, s, &cams, &err)) << err;
  ASSERT_EQ(cams.size(), 1u);
  EXPECT_EQ(cams[0].site_camera, 1u);
  const hal::CameraConfig dc = driver_config(cfg.cameras["cam-east"], s.cameras[1]);
  EXPECT_EQ(dc.width_px, 640);
  EXPECT_EQ(dc.height_px, 400);
  EXPECT_EQ(dc.id, "/dev/video97");
}

// A device that does not exist: the loop keeps retrying it and publishing until stopped.
TEST_F(OverheadLive, MissingDeviceIsRetriedWithoutCrash) {
  const site::Site s = test::two_camera_site();
  OverheadConfig cfg;
  cfg.cameras["cam-west"].device = "/dev/agvloc-no-such-video";
  std::vector<LiveCamera> cams;
  std::string err;
  ASSERT_TRUE(make_live_cameras(cfg, s, &cams, &err)) << err;
  TrackerCore core(cfg, s);
  const std::atomic<bool> stop{false};
  const LiveCounters n = run_live(&cams, &core, stop, 300'000'000);
  EXPECT_EQ(core.frames(), 0u);
  EXPECT_GE(n.ticks, 5u);
}

// The value of a metric line "name{labels} value" in a /metrics text; NaN when absent.
double metric(const std::string& text, const std::string& name_and_labels) {
  const std::size_t at = text.find("\n" + name_and_labels + " ");
  if (at == std::string::npos) return std::nan("");
  return std::stod(text.substr(at + name_and_labels.size() + 2));
}

// The diagnostics page of `run` while the loop runs: /metrics over loopback shows both cameras'
// frames and rate, the disconnected camera's fault, and both vehicles confirmed on their tags with
// a sigma under the lost limit and a fix within the coasting limit; /api/status.json and the page
// are served, the vehicle page's map and image are not.
TEST_F(OverheadLive, DiagnosticsServeMetricsWhileRunning) {
  const site::Site s = test::two_camera_site();
  const std::vector<sim::AgvState> agvs = test::two_vehicles();
  posix::PosixClock clock;
  const fakecamera::FakeCamera::Options opt = test::scripted_camera(&clock);
  std::vector<LiveCamera> cams;
  const fakecamera::FakeImage imgs[2] = {test::render_fake_frame(s, 0, agvs),
                                         test::render_fake_frame(s, 1, agvs)};
  OverheadConfig cfg;
  cfg.diag.enabled = true;
  // The page is under test, not the pipeline's latency: a sanitizer build or a loaded machine
  // processes a frame later than the 300 ms after which a track coasts by default.
  cfg.tracker.coast_after_ms = 3000.0;
  cfg.tracker.lost_after_ms = 6000.0;
  cfg.diag.port = 0;  // any free port
  OverheadDiag diag(cfg.diag);
  std::string err;
  ASSERT_TRUE(diag.start(&err)) << err;
  ASSERT_GT(diag.port(), 0);
  LiveDiag ld;
  ld.server = &diag;
  for (const site::FleetAgv& a : s.fleet) ld.agv_ids.push_back(a.id);
  TrackerCore core(cfg, s);
  // The frames' stamps count from here, after the tracker's construction (libapriltag's tables take
  // a few hundred milliseconds on a loaded machine): stamps from before it would leave every fix
  // that much older at the ticks, near the coasting limit.
  const std::int64_t t0 = monotonic_ns();
  constexpr int kLongRunFrames = 30;  // 3 s at 10 fps
  for (std::size_t c = 0; c < 2; ++c) {
    auto fake = std::make_unique<fakecamera::FakeCamera>(opt);
    for (int k = 0; k < kLongRunFrames; ++k) {
      fake->push_stall(kFramePeriodNs);
      fake->push_frame(imgs[c], t0 + (k + 1) * kFramePeriodNs - 30'000'000);
      if (c == 1 && k == 8) fake->push_disconnect();
    }
    cams.push_back({s.cameras[c].id, c, std::move(fake)});
  }
  std::atomic<bool> stop{false};
  std::thread loop([&] { run_live(&cams, &core, stop, 20'000'000'000, ld); });
  // Each vehicle seen confirmed at some poll: not both at one poll, which on a loaded machine
  // may never happen (cam-east's frames after its 1 s reopen carry the stamps they were scheduled
  // for, a second old, so its vehicle's newest fix is never younger than a second again).
  std::vector<std::uint8_t> seen_confirmed(s.fleet.size(), 0);
  bool confirmed = false, fault_seen = false, fps_seen = false;
  std::string text;
  const auto until = std::chrono::steady_clock::now() + std::chrono::seconds(8);
  while (std::chrono::steady_clock::now() < until && !(confirmed && fault_seen && fps_seen)) {
    text = agv::test::http_get_raw(diag.port(), "/metrics");
    confirmed = true;
    for (std::size_t i = 0; i < s.fleet.size(); ++i) {
      const site::FleetAgv& a = s.fleet[i];
      const std::string l = "{agv=\"" + a.id + "\"";
      seen_confirmed[i] =
          seen_confirmed[i] ||
          (metric(text, "agvloc_overhead_agv_state{agv=\"" + a.id + "\",state=\"confirmed\"}") ==
               1.0 &&
           metric(text, "agvloc_overhead_agv_fix_source{agv=\"" + a.id + "\",source=\"tag\"}") ==
               1.0 &&
           metric(text, "agvloc_overhead_agv_sigma_xy_mm" + l + "}") > 0.0 &&
           metric(text, "agvloc_overhead_agv_sigma_xy_mm" + l + "}") < cfg.tracker.lost_sigma_mm &&
           metric(text, "agvloc_overhead_agv_last_fix_age_seconds" + l + "}") < 3.0);
      confirmed = confirmed && seen_confirmed[i];
    }
    fault_seen = fault_seen ||
                 metric(text, "agvloc_overhead_camera_faults_total{camera=\"cam-east\"}") == 1.0;
    fps_seen = fps_seen || metric(text, "agvloc_overhead_camera_fps{camera=\"cam-west\"}") > 5.0;
    std::this_thread::sleep_for(std::chrono::milliseconds(100));
  }
  const std::string status = agv::test::http_get_raw(diag.port(), "/api/status.json");
  const std::string page = agv::test::http_get_raw(diag.port(), "/");
  const std::string map = agv::test::http_get_raw(diag.port(), "/api/map.json");
  stop.store(true);
  loop.join();
  EXPECT_TRUE(confirmed) << text;
  EXPECT_TRUE(fault_seen) << text;
  EXPECT_TRUE(fps_seen) << text;
  EXPECT_NE(text.find("HTTP/1.1 200"), std::string::npos) << text.substr(0, 200);
  EXPECT_NE(text.find("# TYPE agvloc_overhead_camera_frames_total counter"), std::string::npos);
  EXPECT_GT(metric(text, "agvloc_overhead_camera_frames_total{camera=\"cam-west\"}"), 0.0);
  EXPECT_GE(metric(text, "agvloc_overhead_ticks_total"), 1.0);
  EXPECT_NE(status.find("\"agvs\":[{\"id\":\"agv-1\""), std::string::npos) << status;
  EXPECT_NE(page.find("<title>agvloc-overhead</title>"), std::string::npos) << page.substr(0, 300);
  EXPECT_NE(map.find("HTTP/1.1 404"), std::string::npos) << map.substr(0, 200);
  diag.stop();
}

// A page not on loopback needs diag.allow_remote, as the vehicle's.
TEST_F(OverheadLive, DiagnosticsRefuseARemoteAddressUnlessAllowed) {
  DiagOutput d;
  d.bind_address = "0.0.0.0";
  d.port = 0;
  OverheadDiag diag(d);
  std::string err;
  EXPECT_FALSE(diag.start(&err));
  EXPECT_NE(err.find("diag.bind_address 0.0.0.0 is not loopback"), std::string::npos) << err;
}

}  // namespace
}  // namespace agv::overhead_app
