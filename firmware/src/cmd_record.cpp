// agvloc record --config FILE --out DIR: the live camera, CAN odometry and (with can.gyro.enabled)
// the CAN gyro, written in the recording format (docs/recording.md) for later replay.
#include <CLI/CLI.hpp>
#include <algorithm>
#include <cinttypes>
#include <cstdio>
#include <filesystem>
#include <opencv2/core.hpp>
#include <thread>

#include "agv/can/socketcan.hpp"
#include "agv/localizer/localizer.hpp"
#include "agv/posix/posix_clock.hpp"
#include "agv/protocol/codec.hpp"
#include "agv/recording/recording.hpp"
#include "commands.hpp"
#include "config.hpp"
#include "handoff.hpp"
#include "live_devices.hpp"
#include "signals.hpp"

namespace agv::cmd {

int record(int argc, char** argv) {
  CLI::App app{
      "Record the live camera, CAN odometry and CAN gyro as a recording (docs/recording.md)"};
  std::string config_file, out_dir;
  double duration_s = 0.0;
  app.add_option("--config", config_file, "configuration YAML")->required();
  app.add_option("--out", out_dir, "recording directory to create")->required();
  app.add_option("--duration-s", duration_s, "stop after this many seconds (0 = until Ctrl-C)");
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return app.exit(e) == 0 ? 0 : 2;
  }
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
  recording::Meta meta;
  meta.camera = cfg.camera_model;
  meta.landmark_size_mm = cfg.landmark_size_mm;
  meta.source = "agvloc record --config " + config_file;
  if (!recording::write_meta(out_dir, meta, &err)) {
    std::fprintf(stderr, "agvloc record: %s\n", err.c_str());
    return 1;
  }
  can::SocketCanConfig sc;
  sc.iface = cfg.can.interface;
  can::SocketCanBus bus(sc);
  protocol::ProtocolConfig pc = config::protocol_config(cfg);
  pc.gyro = config::gyro_protocol_config(cfg);  // AGV_Gyro is received only when enabled
  protocol::OdometryDecoder decoder(pc);
  protocol::GyroDecoder gyro_decoder(pc);
  // The same filters as `agvloc run`: one per enabled input of the signal table.
  hal::CanFilter filters[localizer::Localizer::kMaxReceiveFilters];
  const int n_filters =
      localizer::receive_filters(pc, filters, localizer::Localizer::kMaxReceiveFilters);
  bus.set_filters(filters, static_cast<std::size_t>(
                               std::min(n_filters, localizer::Localizer::kMaxReceiveFilters)));

  install_stop_signals();
  posix::PosixClock clock;
  const std::int64_t t_end =
      duration_s > 0 ? clock.now_ns() + static_cast<std::int64_t>(duration_s * 1e9) : INT64_MAX;
  if (camera->start() != hal::CameraStatus::kOk) {
    std::fprintf(stderr, "agvloc record: camera did not start: %s\n", camera->last_error());
    return 1;
  }
  // Capture thread -> writer (this thread's helper): PNG encoding is slow, so the newest frame
  // wins and drops are counted rather than stalling the camera.
  app::FrameMailbox mailbox;
  std::vector<recording::FrameRow> frames;
  std::vector<recording::OdomRow> odom;
  std::vector<recording::ImuRow> imu;
  std::uint64_t gyro_saturated = 0;  // left out of imu.csv: the localizer does not fuse them
  std::atomic<bool> done{false};
  std::atomic<std::uint64_t> write_errors{0};
  std::thread writer([&] {
    hal::FrameView f;
    while (mailbox.take(100'000'000, &f) || !mailbox.closed()) {
      if (!f.data) continue;
      char name[64];
      std::snprintf(name, sizeof name, "frames/%08zu.png", frames.size());
      const cv::Mat img(f.height_px, f.width_px, CV_8UC1, const_cast<std::uint8_t*>(f.data),
                        static_cast<size_t>(f.stride_bytes));
      std::string e;
      if (recording::write_frame_png(out_dir, name, img, &e)) {
        frames.push_back({f.t_exposure_ns, name});
      } else {
        ++write_errors;
        std::fprintf(stderr, "agvloc record: %s\n", e.c_str());
      }
      camera->release(f);
      f = hal::FrameView{};
    }
  });
  std::thread capture([&] {
    while (!done.load()) {
      hal::FrameView f;
      const auto s = camera->next_frame(50'000'000, &f);
      if (s == hal::CameraStatus::kOk) {
        hal::FrameView old;
        if (mailbox.put(f, &old)) camera->release(old);
      } else if (s != hal::CameraStatus::kTimeout) {
        std::fprintf(stderr, "agvloc record: camera: %s (%s)\n", hal::to_string(s),
                     camera->last_error());
        break;
      }
    }
    mailbox.close();
  });
  hal::CanFrame cf;
  while (!stop_requested().load() && clock.now_ns() < t_end) {
    if (bus.receive(&cf, 20'000'000) != hal::CanStatus::kOk) continue;
    protocol::OdomSample s;
    protocol::GyroSample g;
    if (decoder.decode(cf, &s) == protocol::DecodeResult::kOk &&
        (odom.empty() || s.t_ns > odom.back().t_ns)) {
      odom.push_back({s.t_ns, s.v_mps, s.omega_radps});
    } else if (pc.gyro.enabled && gyro_decoder.decode(cf, &g) == protocol::DecodeResult::kOk &&
               (imu.empty() || g.t_ns > imu.back().t_ns)) {
      if (g.saturated) {
        ++gyro_saturated;
      } else {
        imu.push_back({g.t_ns, g.gyro_z_radps});
      }
    }
  }
  done = true;
  capture.join();
  writer.join();
  camera->stop();
  // imu.csv only when gyro samples arrived: an absent file is what "no gyro" means.
  bool ok = recording::write_frames_csv(out_dir, frames, &err) &&
            recording::write_odom_csv(out_dir, odom, &err) &&
            (imu.empty() || recording::write_imu_csv(out_dir, imu, &err));
  if (!ok) std::fprintf(stderr, "agvloc record: %s\n", err.c_str());
  std::printf("agvloc record: %zu frames (%" PRIu64
              " dropped while encoding), %zu odometry samples "
              "(%" PRIu64 " rejected), %zu gyro samples (%" PRIu64 " rejected, %" PRIu64
              " saturated left out) -> %s\n",
              frames.size(), mailbox.dropped(), odom.size(), decoder.counters().rejected(),
              imu.size(), gyro_decoder.counters().rejected(), gyro_saturated, out_dir.c_str());
  return ok && write_errors.load() == 0 ? 0 : 1;
}

}  // namespace agv::cmd
