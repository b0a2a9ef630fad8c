// agvloc run --config FILE: live camera, vision, fusion, CAN output; odometry from CAN.
#include <CLI/CLI.hpp>
#include <chrono>
#include <cstdio>
#include <memory>
#include <vector>

#include "agv/can/socketcan.hpp"
#include "agv/posix/posix_clock.hpp"
#include "agv/posix/realtime.hpp"
#include "agv/protocol/dbc.hpp"
#include "cli_parse.hpp"
#include "commands.hpp"
#include "config.hpp"
#include "diag_server.hpp"
#include "gyro_reader.hpp"
#include "live_devices.hpp"
#include "mqtt_publisher.hpp"
#include "pipeline.hpp"
#include "ranging_stream.hpp"
#include "signals.hpp"

namespace agv::cmd {

namespace {

struct RunArgs {
  std::string config_file;
  bool check_only = false, print_dbc = false;
};

// The command line; -1 to go on, else the exit code.
int parse_args(int argc, char** argv, RunArgs* a) {
  CLI::App app{"Live localization: camera -> vision -> fusion -> CAN (docs/guide/config.md)"};
  app.add_option("--config", a->config_file, "configuration YAML")->required();
  app.add_flag("--check-config", a->check_only, "validate the configuration and exit");
  app.add_flag("--print-dbc", a->print_dbc,
               "print the DBC of this configuration (IDs, ID types, cycle times from "
               "loop.output_rate_hz) and exit");
  return cli::parse(app, argc, argv);
}

// What a live run needs before it starts, checked.
struct LiveSetup {
  config::Config cfg;
  LandmarkMap map;
  const LandmarkMap* map_ptr = nullptr;  // null: payload poses only
  std::unique_ptr<hal::Camera> camera;
  std::unique_ptr<hal::Imu> imu;  // imu.source iio (docs/design/fusion.md "Gyro from a Linux IIO
                                  // device"); null otherwise
  // ranging_camera.enabled: the second camera, the site's landmarks on racks and their observer.
  std::unique_ptr<hal::Camera> ranging_camera;
  app::RackSite rack_site;
  std::unique_ptr<app::RackObserver> rack;
  app::RangingCounts ranging_counts;
};

int run_fail(const std::string& what, int rc = 2) {
  std::fprintf(stderr, "agvloc: %s\n", what.c_str());
  return rc;
}

// ranging_camera.enabled: its driver, the site's landmarks and the observer. -1 to go on, else
// the exit code.
int prepare_ranging(LiveSetup* s) {
  const config::RangingCameraSection& rc = s->cfg.ranging_camera;
  if (!rc.enabled) return -1;
  std::string err;
  s->ranging_camera = app::make_live_camera(rc.driver, rc.camera, "ranging_camera", &err);
  if (!s->ranging_camera) return run_fail(err);
  if (!app::load_rack_site(rc.site_file, &s->rack_site, &err)) return run_fail(err);
  s->rack = std::make_unique<app::RackObserver>(rc, s->rack_site);
  if (!s->rack->ok(&err)) return run_fail(err);
  return -1;
}

// The configuration, the map and the devices: -1 to go on, else the exit code (--print-dbc and
// --check-config end here).
int prepare(const RunArgs& a, LiveSetup* s) {
  config::Config& cfg = s->cfg;
  if (!config::load_config_or_report(a.config_file, "agvloc", &cfg)) return 2;
  std::vector<std::string> errors;
  if (cfg.vda5050.enabled && !app::check_vda5050_files(cfg.vda5050, &errors)) {
    for (const auto& e : errors) run_fail("config: " + e);
    return 2;
  }
  if (a.print_dbc) {
    std::fputs(protocol::render_dbc(config::protocol_config(cfg)).c_str(), stdout);
    return 0;
  }
  std::string err;
  if (!cfg.map_file.empty()) {
    if (!config::load_map_file(cfg.map_file, &s->map, &err)) return run_fail("map: " + err);
    s->map_ptr = &s->map;
  }
  if (!config::check_can_localize(cfg, s->map_ptr, &errors)) {
    for (const auto& e : errors) run_fail("config: " + e);
    return 2;
  }
  s->camera = app::make_live_camera(cfg, &err);
  if (!s->camera) return run_fail(err);
  if (cfg.imu.source == config::ImuSource::kIio) {
    s->imu = app::make_live_imu(cfg, &err);
    if (!s->imu) return run_fail(err);
  }
  if (const int rc = prepare_ranging(s); rc >= 0) return rc;
  if (a.check_only) {
    std::printf("agvloc: configuration %s is valid; checked:\n%s", a.config_file.c_str(),
                config::config_summary(cfg, s->map_ptr).c_str());
    return 0;
  }
  return -1;
}

// The outputs besides CAN, started: the VDA 5050 publisher and the diagnostics page (each only
// when enabled), their hand-offs added to io's sinks.
struct Outputs {
  app::MqttHandoff mqtt_handoff;
  std::unique_ptr<app::MqttPublisher> mqtt;
  app::DiagHandoff diag_handoff;
  app::FrameTap diag_frames;
  std::unique_ptr<app::DiagServer> diag;

  bool start(const LiveSetup& s, app::PipelineIo* io, std::string* err) {
    const config::Config& cfg = s.cfg;
    if (cfg.vda5050.enabled) {
      // VDA 5050 wants wall-clock stamps; the loop runs on the monotonic clock.
      mqtt = std::make_unique<app::MqttPublisher>(cfg.vda5050, mqtt_handoff, app::StampClock::kWall,
                                                  cfg.loop.service_cpus);
      if (!mqtt->start(err)) return false;
      io->sinks.push_back(&mqtt_handoff);
    }
    // Diagnostics page (docs/guide/diagnostics.md): its own threads, never the loop's.
    if (cfg.diag.enabled) {
      diag = std::make_unique<app::DiagServer>(cfg, s.map_ptr, diag_handoff, diag_frames, "run");
      if (!diag->start(err)) return false;
      io->sinks.push_back(&diag_handoff);
      io->diag_frames = &diag_frames;
    }
    return true;
  }
  // Stops them; their counter lines.
  std::string stop() {
    std::string lines;
    if (mqtt) {
      mqtt->stop();
      lines += app::format_mqtt_counters(mqtt->counters(), mqtt_handoff);
    }
    if (diag) {
      diag->stop();
      lines += app::format_diag_counters(diag->stats());
    }
    return lines;
  }
};

int run_live(LiveSetup& s) {
  const config::Config& cfg = s.cfg;
  if (cfg.loop.lock_memory) {
    const int e = posix::lock_all_memory();
    if (e) run_fail(posix::explain_realtime_error("mlockall", e));
  }
  can::SocketCanConfig sc;
  sc.iface = cfg.can.interface;
  can::SocketCanBus bus(sc);
  if (bus.state() == hal::CanBusState::kDown) {
    std::fprintf(stderr, "agvloc: CAN %s not available yet (%s); retrying in the loop\n",
                 sc.iface.c_str(), bus.last_error());
  }
  posix::PosixClock clock;
  install_stop_signals();
  app::PipelineIo io;
  io.camera = s.camera.get();
  io.bus = &bus;
  io.clock = &clock;
  io.stop = &stop_requested();
  io.stop_at_end_of_stream = false;
  if (s.rack) {
    io.ranging_camera = s.ranging_camera.get();
    io.rack_observer = s.rack.get();
    io.ranging_counts = &s.ranging_counts;
  }
  std::string err;
  app::GyroRing gyro_ring;
  app::GyroReader gyro_reader(std::move(s.imu), gyro_ring);
  if (cfg.imu.source == config::ImuSource::kIio) {
    if (!gyro_reader.start(&err)) return run_fail(err);
    std::printf("agvloc: gyro from IIO device %s at %.1f Hz\n", cfg.imu.iio_device.c_str(),
                gyro_reader.rate_hz());
    io.live_gyro = &gyro_ring;
  }
  Outputs outputs;
  if (!outputs.start(s, &io, &err)) return run_fail(err);
  std::printf("agvloc %s: running (camera %s, CAN %s, %.0f Hz); Ctrl-C to stop\n", AGV_VERSION,
              config::camera_driver_name(cfg.camera.driver), sc.iface.c_str(),
              cfg.loop.output_rate_hz);
  app::RunResult result;
  const std::int64_t t0 = clock.now_ns();
  app::run_threads(cfg, s.map_ptr, io, &result);
  result.wall_ns = clock.now_ns() - t0;
  gyro_reader.stop();
  if (io.live_gyro) {
    std::fputs(app::format_gyro_counters(gyro_reader.counters(), gyro_ring.dropped()).c_str(),
               stdout);
  }
  const std::string lines = outputs.stop();
  std::printf("agvloc: stopped after %.1f s\n%s%s", static_cast<double>(result.wall_ns) / 1e9,
              app::format_statistics(result).c_str(), lines.c_str());
  if (s.rack) std::fputs(app::ranging_summary(s.ranging_counts, result.output).c_str(), stdout);
  return 0;
}

}  // namespace

int run(int argc, char** argv) {
  RunArgs args;
  if (const int rc = parse_args(argc, argv, &args); rc >= 0) return rc;
  LiveSetup setup;
  if (const int rc = prepare(args, &setup); rc >= 0) return rc;
  return run_live(setup);
}

}  // namespace agv::cmd
