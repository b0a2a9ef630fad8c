// Frames of every camera merged in the order they reach the tracker (exposure time plus the
// camera's configured latency; fixes keep their exposure time), and every vehicle's state
// published at output.rate_hz on a clock of its own, extrapolated to the tick.
#include "replay.hpp"

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <opencv2/core.hpp>
#include <thread>

#include "core.hpp"
#include "inputs.hpp"

namespace agv::overhead_app {

namespace {

struct FrameEvent {
  std::int64_t arrival_ns = 0;
  std::size_t input = 0;  // index into the camera recordings
  std::size_t frame = 0;
};

std::vector<FrameEvent> merge_frames(const std::vector<CameraRecording>& cams) {
  std::vector<FrameEvent> ev;
  for (std::size_t c = 0; c < cams.size(); ++c) {
    for (std::size_t i = 0; i < cams[c].rec.frames.size(); ++i) {
      ev.push_back({cams[c].rec.frames[i].t_ns + cams[c].latency_ns, c, i});
    }
  }
  std::stable_sort(ev.begin(), ev.end(), [](const FrameEvent& a, const FrameEvent& b) {
    return a.arrival_ns != b.arrival_ns ? a.arrival_ns < b.arrival_ns : a.input < b.input;
  });
  return ev;
}

void pace(std::chrono::steady_clock::time_point wall0, std::int64_t since_ns) {
  std::this_thread::sleep_until(wall0 + std::chrono::nanoseconds(since_ns));
}

void play(const std::vector<CameraRecording>& cams, bool fast, TrackerCore* core) {
  const std::vector<FrameEvent> events = merge_frames(cams);
  const std::int64_t period_ns = core->period_ns();
  const std::int64_t t0 = events.front().arrival_ns;
  const auto wall0 = std::chrono::steady_clock::now();
  std::int64_t next_tick = t0;
  cv::Mat gray;
  for (const FrameEvent& e : events) {
    for (; next_tick <= e.arrival_ns; next_tick += period_ns) {
      if (!fast) pace(wall0, next_tick - t0);
      core->publish(next_tick);
    }
    if (!fast) pace(wall0, e.arrival_ns - t0);
    const CameraRecording& cam = cams[e.input];
    std::string err;
    if (recording::load_frame(cam.rec, e.frame, &gray, &err)) {
      core->process(cam.site_camera, cam.rec.frames[e.frame].t_ns, gray);
    } else {
      core->frame_unreadable(cam.rec.dir + ": " + err);
    }
  }
  core->publish(next_tick);
}

}  // namespace

int run_replay(const ReplayArgs& args) {
  OverheadConfig cfg;
  site::Site site;
  if (!load_config_and_site("replay", args.config_path, args.site_path, &cfg, &site)) return 2;
  std::string err;
  std::vector<CameraRecording> cams;
  std::vector<std::string> warnings;
  if (!open_recordings(args.recordings, site, cfg, &cams, &warnings, &err))
    return command_fail("replay", 2, err);
  for (const std::string& w : warnings) command_fail("replay", 0, "warning: " + w);
  TrackerCore core(cfg, site);
  if (!core.open_outputs(args.out_dir, &err)) return command_fail("replay", 1, err);
  play(cams, args.fast, &core);
  if (!core.finish("agvloc-overhead replay", cams.size(), &err))
    return command_fail("replay", 1, err);
  return 0;
}

}  // namespace agv::overhead_app
