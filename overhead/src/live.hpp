// agvloc-overhead run: live ceiling cameras through the camera drivers (V4L2, libcamera, and
// GigE Vision / USB3 Vision through Aravis where built with it; drivers/). The camera feed
// (live_feed.hpp) takes each camera's frames into a bounded queue; the calling thread runs the
// pipeline on them in arrival order and publishes every vehicle's state at output.rate_hz on
// CLOCK_MONOTONIC, the clock of the drivers' exposure stamps. A camera that fails or disconnects
// is a camera fault, reopened at once, then every second while it fails; its vehicles coast on
// the others meanwhile.
#pragma once

#include <atomic>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "agv/hal/camera.hpp"
#include "agv/site/site.hpp"
#include "config.hpp"
#include "core.hpp"
#include "diag.hpp"
#include "live_feed.hpp"
#include "mqtt_in.hpp"

namespace agv::overhead_app {

// The driver's settings for a site camera: its image size from the site's intrinsics, the rest
// from cameras.<id>.
hal::CameraConfig driver_config(const CameraSettings& s, const site::CeilingCamera& cam);

// Every site camera with a cameras.<id>.device, as a (not started) driver. False with *error
// when none has a device, a driver is not in this build, or the settings are refused.
bool make_live_cameras(const OverheadConfig& cfg, const site::Site& site,
                       std::vector<LiveCamera>* out, std::string* error);

// What run and record start from.
struct LiveInputs {
  OverheadConfig cfg;
  site::Site site;
  std::vector<LiveCamera> cams;  // the site's cameras as drivers, not started
};

// Loads the configuration and the site, makes the cameras' drivers and has SIGINT and SIGTERM call
// on_stop. False after printing each problem as "agvloc-overhead COMMAND: ..." on stderr.
bool start_live(const char* command, const std::string& config_path, const std::string& site_path,
                void (*on_stop)(int), LiveInputs* in);

struct LiveCounters {
  std::uint64_t ticks = 0, ticks_skipped = 0, frames_dropped = 0, reopens = 0;
  std::vector<CameraHealth> cameras;  // as the cameras were given
};

// Where run_live hands its diagnostics view at every tick (server null: none).
struct LiveDiag {
  OverheadDiag* server = nullptr;
  std::vector<std::string> agv_ids;  // the site's fleet, in order
  // When set: for every frame processed, the time from its exposure stamp to the return of the
  // first publish after it (every vehicle handed to the MQTT client), ns (bench_overhead_latency).
  std::vector<std::int64_t>* exposure_to_publish_ns = nullptr;
};

// Runs until `stop` is set, duration_ns has passed (0: no limit) or every camera has ended
// (kEndOfStream, a scripted camera). Status lines go to stderr.
// With `orders` (orders.subscribe), the vehicles' orders it has queued are applied at every tick.
LiveCounters run_live(std::vector<LiveCamera>* cams, TrackerCore* core,
                      const std::atomic<bool>& stop, std::int64_t duration_ns,
                      const LiveDiag& diag = {}, MqttIn* orders = nullptr);

}  // namespace agv::overhead_app
