// agvloc run --config FILE: live camera, vision, fusion, CAN output; odometry from CAN.
#include <CLI/CLI.hpp>
#include <chrono>
#include <cstdio>
#include <memory>

#include "agv/can/socketcan.hpp"
#include "agv/posix/posix_clock.hpp"
#include "agv/posix/realtime.hpp"
#include "agv/protocol/dbc.hpp"
#include "commands.hpp"
#include "config.hpp"
#include "diag_server.hpp"
#include "gyro_reader.hpp"
#include "live_devices.hpp"
#include "mqtt_publisher.hpp"
#include "pipeline.hpp"
#include "signals.hpp"

namespace agv::cmd {

int run(int argc, char** argv) {
  CLI::App app{"Live localization: camera -> vision -> fusion -> CAN (docs/guide/config.md)"};
  std::string config_file;
  bool check_only = false, print_dbc = false;
  app.add_option("--config", config_file, "configuration YAML")->required();
  app.add_flag("--check-config", check_only, "validate the configuration and exit");
  app.add_flag("--print-dbc", print_dbc,
               "print the DBC of this configuration (IDs, ID types, cycle times from "
               "loop.output_rate_hz) and exit");
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return app.exit(e) == 0 ? 0 : 2;
  }
  config::Config cfg;
  if (!config::load_config_or_report(config_file, "agvloc", &cfg)) return 2;
  std::vector<std::string> file_errors;
  if (cfg.vda5050.enabled && !app::check_vda5050_files(cfg.vda5050, &file_errors)) {
    for (const auto& e : file_errors) std::fprintf(stderr, "agvloc: config: %s\n", e.c_str());
    return 2;
  }
  if (print_dbc) {
    protocol::ProtocolConfig pc = config::protocol_config(cfg);
    pc.gyro = config::gyro_protocol_config(cfg);
    std::fputs(protocol::render_dbc(pc).c_str(), stdout);
    return 0;
  }
  LandmarkMap map;
  const LandmarkMap* map_ptr = nullptr;
  std::string err;
  if (!cfg.map_file.empty()) {
    if (!config::load_map_file(cfg.map_file, &map, &err)) {
      std::fprintf(stderr, "agvloc: map: %s\n", err.c_str());
      return 2;
    }
    map_ptr = &map;
  }
  std::vector<std::string> cannot;
  if (!config::check_can_localize(cfg, map_ptr, &cannot)) {
    for (const auto& e : cannot) std::fprintf(stderr, "agvloc: config: %s\n", e.c_str());
    return 2;
  }
  auto camera = app::make_live_camera(cfg, &err);
  if (!camera) {
    std::fprintf(stderr, "agvloc: %s\n", err.c_str());
    return 2;
  }
  std::unique_ptr<hal::Imu>
      imu;  // imu.source iio (docs/design/fusion.md "Gyro from a Linux IIO device")
  if (cfg.imu.source == "iio") {
    imu = app::make_live_imu(cfg, &err);
    if (!imu) {
      std::fprintf(stderr, "agvloc: %s\n", err.c_str());
      return 2;
    }
  }
  if (check_only) {
    std::printf("agvloc: configuration %s is valid; checked:\n%s", config_file.c_str(),
                config::config_summary(cfg, map_ptr).c_str());
    return 0;
  }
  if (cfg.loop.lock_memory) {
    const int e = posix::lock_all_memory();
    if (e)
      std::fprintf(stderr, "agvloc: %s\n", posix::explain_realtime_error("mlockall", e).c_str());
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
  io.camera = camera.get();
  io.bus = &bus;
  io.clock = &clock;
  io.stop = &stop_requested();
  io.stop_at_end_of_stream = false;
  app::GyroRing gyro_ring;
  app::GyroReader gyro_reader(std::move(imu), gyro_ring);
  if (cfg.imu.source == "iio") {
    if (!gyro_reader.start(&err)) {
      std::fprintf(stderr, "agvloc: %s\n", err.c_str());
      return 2;
    }
    std::printf("agvloc: gyro from IIO device %s at %.1f Hz\n", cfg.imu.iio_device.c_str(),
                gyro_reader.rate_hz());
    io.live_gyro = &gyro_ring;
  }
  // VDA 5050 wants wall-clock stamps; the loop runs on the monotonic clock.
  app::MqttHandoff mqtt_handoff;
  std::unique_ptr<app::MqttPublisher> mqtt;
  if (cfg.vda5050.enabled) {
    mqtt = std::make_unique<app::MqttPublisher>(cfg.vda5050, mqtt_handoff, app::StampClock::kWall,
                                                cfg.loop.service_cpus);
    if (!mqtt->start(&err)) {
      std::fprintf(stderr, "agvloc: %s\n", err.c_str());
      return 2;
    }
    io.mqtt = &mqtt_handoff;
  }
  // Diagnostics page (diag.enabled, docs/guide/diagnostics.md): its own threads, never the loop's.
  app::DiagHandoff diag_handoff;
  app::FrameTap diag_frames;
  std::unique_ptr<app::DiagServer> diag;
  if (cfg.diag.enabled) {
    diag = std::make_unique<app::DiagServer>(cfg, map_ptr, diag_handoff, diag_frames, "run");
    if (!diag->start(&err)) {
      std::fprintf(stderr, "agvloc: %s\n", err.c_str());
      return 2;
    }
    io.diag = &diag_handoff;
    io.diag_frames = &diag_frames;
  }
  std::printf("agvloc %s: running (camera %s, CAN %s, %.0f Hz); Ctrl-C to stop\n", AGV_VERSION,
              cfg.camera.driver.c_str(), sc.iface.c_str(), cfg.loop.output_rate_hz);
  app::RunResult result;
  const std::int64_t t0 = clock.now_ns();
  app::run_threads(cfg, map_ptr, io, &result);
  result.wall_ns = clock.now_ns() - t0;
  gyro_reader.stop();
  if (io.live_gyro) {
    std::fputs(app::format_gyro_counters(gyro_reader.counters(), gyro_ring.dropped()).c_str(),
               stdout);
  }
  std::string mqtt_line;
  if (mqtt) {
    mqtt->stop();
    mqtt_line = app::format_mqtt_counters(mqtt->counters(), mqtt_handoff);
  }
  std::string diag_line;
  if (diag) {
    diag->stop();
    diag_line = app::format_diag_counters(diag->stats());
  }
  std::printf("agvloc: stopped after %.1f s\n%s%s%s", static_cast<double>(result.wall_ns) / 1e9,
              app::format_statistics(result).c_str(), mqtt_line.c_str(), diag_line.c_str());
  return 0;
}

}  // namespace agv::cmd
