// agvloc record --config FILE --out DIR: the live camera (and the second camera with
// ranging_camera.enabled), CAN odometry and the gyro (AGV_Gyro with can.gyro.enabled, the IIO
// device with imu.source iio), streamed in the recording format
// (docs/guide/recording.md) for later replay. The recording itself is app::Recorder.
#include <CLI/CLI.hpp>
#include <cstdio>
#include <filesystem>
#include <memory>

#include "agv/can/socketcan.hpp"
#include "agv/posix/posix_clock.hpp"
#include "agv/recording/recording.hpp"
#include "cli_parse.hpp"
#include "commands.hpp"
#include "config.hpp"
#include "live_devices.hpp"
#include "recorder.hpp"
#include "signals.hpp"

namespace agv::cmd {

int record(int argc, char** argv) {
  CLI::App app{
      "Record the live camera, CAN odometry and the gyro as a recording (docs/guide/recording.md)"};
  std::string config_file, out_dir;
  double duration_s = 0.0;
  app.add_option("--config", config_file, "configuration YAML")->required();
  app.add_option("--out", out_dir, "recording directory to create")->required();
  app.add_option("--duration-s", duration_s, "stop after this many seconds (0 = until Ctrl-C)");
  if (const int parse_rc = cli::parse(app, argc, argv); parse_rc >= 0) return parse_rc;
  config::Config cfg;
  if (!config::load_config_or_report(config_file, "agvloc record", &cfg)) return 2;
  std::string err;
  if (std::filesystem::exists(std::filesystem::path(out_dir) / "frames.csv")) {
    std::fprintf(stderr, "agvloc record: %s already holds a recording; not overwriting\n",
                 out_dir.c_str());
    return 2;
  }
  auto camera = app::make_live_camera(cfg, &err);
  if (!camera) {
    std::fprintf(stderr, "agvloc record: %s\n", err.c_str());
    return 2;
  }
  std::unique_ptr<hal::Camera> ranging_camera;  // ranging_camera.enabled: into ranging/
  if (cfg.ranging_camera.enabled) {
    const config::RangingCameraSection& rc = cfg.ranging_camera;
    ranging_camera = app::make_live_camera(rc.driver, rc.camera, "ranging_camera", &err);
    if (!ranging_camera) {
      std::fprintf(stderr, "agvloc record: %s\n", err.c_str());
      return 2;
    }
  }
  std::unique_ptr<hal::Imu> imu;  // imu.source iio: the same device and reader as `agvloc run`
  if (cfg.imu.source == config::ImuSource::kIio) {
    imu = app::make_live_imu(cfg, &err);
    if (!imu) {
      std::fprintf(stderr, "agvloc record: %s\n", err.c_str());
      return 2;
    }
  }
  recording::Meta meta;
  meta.camera = cfg.camera_model;
  meta.landmark_size_mm = cfg.landmark_size_mm;
  // The configured family is what the floor was taken to carry: replay runs it without --config.
  meta.landmark_family = landmark_family_name(cfg.vision.family);
  meta.source = "agvloc record --config " + config_file;
  if (!recording::write_meta(out_dir, meta, &err)) {
    std::fprintf(stderr, "agvloc record: %s\n", err.c_str());
    return 1;
  }
  can::SocketCanConfig sc;
  sc.iface = cfg.can.interface;
  can::SocketCanBus bus(sc);
  const protocol::ProtocolConfig pc = config::protocol_config(cfg);  // AGV_Gyro when enabled

  install_stop_signals();
  posix::PosixClock clock;
  const std::int64_t t_end =
      duration_s > 0 ? clock.now_ns() + static_cast<std::int64_t>(duration_s * 1e9) : INT64_MAX;
  app::Recorder recorder(out_dir, pc, *camera, bus, std::move(imu), clock, {},
                         ranging_camera.get());
  if (!recorder.start(&err)) {
    std::fprintf(stderr, "agvloc record: %s\n", err.c_str());
    return 1;
  }
  while (!stop_requested().load() && clock.now_ns() < t_end) recorder.step(20'000'000);
  const bool ok = recorder.stop();
  std::fputs(recorder.summary().c_str(), stdout);
  return ok ? 0 : 1;
}

}  // namespace agv::cmd
