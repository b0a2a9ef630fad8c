// agvloc replay RECORDING [--out DIR] [--config FILE] [--map FILE] [--can IFACE]
//                         [--odom-from-can] [--realtime [--speed X] | --fast] [--overlay LIST]
//                         [--serve]
#include <CLI/CLI.hpp>
#include <algorithm>
#include <atomic>
#include <chrono>
#include <csignal>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <memory>
#include <sstream>
#include <thread>

#include "agv/adapters/scaled_clock.hpp"
#include "agv/adapters/stepped_clock.hpp"
#include "agv/can/candump_file.hpp"
#include "agv/can/log_only_bus.hpp"
#include "agv/can/socketcan.hpp"
#include "agv/config/yaml_keys.hpp"
#include "agv/posix/posix_clock.hpp"
#include "agv/posix/realtime.hpp"
#include "agv/recording/png_io.hpp"
#include "agv/recording/replay_camera.hpp"
#include "commands.hpp"
#include "config.hpp"
#include "diag_server.hpp"
#include "mqtt_publisher.hpp"
#include "pipeline.hpp"
#include "replay_meta.hpp"
#include "replay_report.hpp"
#include "signals.hpp"

namespace agv::cmd {

namespace {

// Output periods one replay simulates at most: 10^6 tick records (360 MB) and poses.csv lines
// (~130 MB); 2.8 h of recording at the default 100 Hz (docs/guide/replay.md).
constexpr std::int64_t kMaxReplayTicks = 1'000'000;
// Seconds a real-time replay's record runs past the recording: 6000 tick records (2.2 MB) at
// 100 Hz, where 7 s were needed under load in the HIL VM.
constexpr double kRealtimeRecordSlackS = 60.0;
// The record of received odometry (odom_received.csv) is sized for twice the recording's
// odometry rate (the sender normally plays it), and at least this rate: 24 bytes a sample,
// 340 kB for a 10 s recording at 100 Hz plus the slack above, 48 MB for 2.8 hours.
constexpr double kMinReceivedOdometryRecordHz = 200.0;

void write_overlays(const config::Config& cfg, const LandmarkMap* map,
                    const recording::Recording& rec, const std::vector<int>& frames,
                    const std::string& out_dir) {
  LandmarkGeometry g;
  g.size_mm = cfg.landmark_size_mm;
  vision::LandmarkLocalizer loc(cfg.vision, cfg.camera_model, g, map);
  for (int i : frames) {
    cv::Mat img, bgr;
    std::string err;
    if (i < 0 || static_cast<size_t>(i) >= rec.frames.size() ||
        !recording::load_frame(rec, static_cast<size_t>(i), &img, &err)) {
      std::fprintf(stderr, "replay: overlay frame %d: %s\n", i,
                   err.empty() ? "no such frame" : err.c_str());
      continue;
    }
    vision::LandmarkFix fix;
    loc.process(img, &fix);
    loc.draw_overlay(img, fix, &bgr);
    char name[64];
    std::snprintf(name, sizeof name, "overlay_%06d.png", i);
    if (!png::write((std::filesystem::path(out_dir) / name).string(), bgr, &err)) {
      std::fprintf(stderr, "replay: %s\n", err.c_str());
    }
  }
}

// Waits for the first valid odometry frame on the bus and returns its receive time (monotonic),
// or -1 when stopped first; *first is that frame (the caller hands it on to fusion). With
// --odom-from-can the sender plays the recording's odometry from its first row: anchoring the
// replay clock there puts frames and odometry on one time line, whatever the delay between our
// start and the sender's (it varies with load, and every 10 ms of it would shift the camera against
// the odometry by 10 ms of travel).
std::int64_t wait_first_odometry(hal::CanBus& bus, const config::Config& cfg,
                                 hal::CanFrame* first) {
  protocol::OdometryDecoder decoder(config::protocol_config(cfg));
  std::fprintf(stderr, "replay: waiting for the first odometry frame on the bus\n");
  while (!stop_requested().load()) {
    hal::CanFrame f;
    if (bus.receive(&f, 100'000'000) != hal::CanStatus::kOk) continue;
    protocol::OdomSample s;
    if (decoder.decode(f, &s) == protocol::DecodeResult::kOk) {
      *first = f;
      return f.t_ns;
    }
  }
  return -1;
}

// The summary's gyro line: what fusion was given (imu.csv, or AGV_Gyro on the bus) and refused.
std::string gyro_summary(const localizer::OutputStats& o, const recording::Recording& rec,
                         bool imu_fed) {
  std::string source;
  if (rec.has_imu && imu_fed) {
    source = "imu.csv: " + std::to_string(rec.imu.size()) + " rows";
  } else if (rec.has_imu) {
    source = "imu.csv not used with --odom-from-can: the inputs come from the bus";
  } else if (o.gyro_samples == 0) {
    return "gyro: none (no imu.csv: wheel odometry only)\n";
  } else {
    source = "CAN";
  }
  char buf[200];
  std::snprintf(buf, sizeof buf, "gyro: %llu samples fused, %llu rejected (%s)\n",
                static_cast<unsigned long long>(o.gyro_samples - o.gyro_rejected),
                static_cast<unsigned long long>(o.gyro_rejected), source.c_str());
  return buf;
}

}  // namespace

int replay(int argc, char** argv) {
  CLI::App app{"Run the localizer on a recording (frames + odometry), docs/guide/replay.md"};
  std::string rec_dir, out_dir = "replay_out", config_file, map_file, can_iface, can_log;
  bool realtime = false, fast = false, odom_from_can = false, quiet = false, serve = false;
  double speed = 1.0;
  std::vector<int> overlay_frames;
  app.add_option("recording", rec_dir, "recording directory (docs/guide/recording.md)")->required();
  app.add_option("--out", out_dir, "output directory (poses.csv, fixes.csv, summary.txt, ...)");
  app.add_option("--config", config_file,
                 "configuration YAML; a camera, mounting or landmark.size_mm key it sets is used "
                 "instead of meta.yaml's (each difference printed)");
  app.add_option("--map", map_file, "landmark map (default: RECORDING/map.csv if present)");
  app.add_option("--can", can_iface, "send output frames on this SocketCAN interface");
  app.add_flag("--odom-from-can", odom_from_can,
               "take odometry from the CAN bus instead of odom.csv (needs --can, --realtime)");
  app.add_option("--can-log", can_log,
                 "without --can: write sent frames as a candump -l log (default OUT/can.log); with "
                 "--can log the interface with candump -l instead");
  auto* rt = app.add_flag("--realtime", realtime, "pace the replay by the clock (threads as live)");
  auto* ft = app.add_flag("--fast", fast, "as fast as possible, deterministic (default)");
  rt->excludes(ft);
  app.add_option("--speed", speed, "pace for --realtime: 1 = real time, 0.5 = half speed")
      ->check(CLI::Range(0.01, 100.0));
  app.add_option("--overlay", overlay_frames, "frame indices to write debug overlays for");
  app.add_flag("--quiet", quiet, "no progress or periodic lines");
  app.add_flag("--serve", serve,
               "serve the diagnostics page and /metrics during the replay and after it until "
               "SIGINT / SIGTERM (address and port: diag.* keys; docs/guide/diagnostics.md)");
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return app.exit(e) == 0 ? 0 : 2;
  }
  if (odom_from_can && (can_iface.empty() || !realtime)) {
    std::fprintf(stderr, "replay: --odom-from-can needs --can IFACE and --realtime\n");
    return 2;
  }

  recording::Recording rec;
  std::string err;
  if (!recording::read_recording(rec_dir, &rec, &err)) {
    std::fprintf(stderr, "replay: %s\n", err.c_str());
    return 1;
  }
  for (const auto& w : rec.warnings) std::fprintf(stderr, "replay: warning: %s\n", w.c_str());
  config::Config cfg;
  if (!config_file.empty()) {
    if (!config::load_config_or_report(config_file, "replay", &cfg, config::ConfigUse::kReplay)) {
      return 2;
    }
  }
  // Every output period from the first to the last recorded time is simulated and written to
  // poses.csv: bound it, so odometry rows at t = 1e10 and 9e18 cannot run without end.
  const auto period_ns = static_cast<std::int64_t>(1e9 / cfg.loop.output_rate_hz);
  if (!recording::check_replay_span(rec, period_ns, kMaxReplayTicks, &err)) {
    std::fprintf(stderr, "replay: %s: %s\n", rec_dir.c_str(), err.c_str());
    return 2;
  }
  // One rule for meta.yaml against --config (docs/guide/replay.md): what --config sets is used (a
  // calibrated mounting is replayed as calibrated, as calibrate vehicle --config does), the
  // recording gives the rest; each value that differs is printed.
  std::vector<std::string> config_keys;
  if (!config_file.empty()) {
    std::string text;
    std::vector<config::YamlEntry> entries;
    if (!recording::read_file_bounded(config_file, config::kMaxConfigBytes, &text, &err) ||
        !config::yaml_entries(text, &entries, &err)) {
      std::fprintf(stderr, "replay: config: %s: %s\n", config_file.c_str(), err.c_str());
      return 2;
    }
    for (const auto& e : entries) config_keys.push_back(e.key);
  }
  std::vector<std::string> differ;
  if (!app::apply_recording_meta(rec.meta, config_keys, config_file, &cfg, &differ, &err)) {
    std::fprintf(stderr, "replay: %s\n", err.c_str());
    return 2;
  }
  for (const auto& d : differ) std::fprintf(stderr, "replay: %s\n", d.c_str());
  if (map_file.empty() && std::filesystem::exists(std::filesystem::path(rec_dir) / "map.csv")) {
    map_file = (std::filesystem::path(rec_dir) / "map.csv").string();
  }
  if (map_file.empty() && !cfg.map_file.empty()) map_file = cfg.map_file;
  LandmarkMap map;
  const LandmarkMap* map_ptr = nullptr;
  if (!map_file.empty()) {
    if (!config::load_map_file(map_file, &map, &err)) {
      std::fprintf(stderr, "replay: map: %s\n", err.c_str());
      return 2;
    }
    map_ptr = &map;
  }
  std::error_code ec;
  std::filesystem::create_directories(out_dir, ec);
  if (ec) {
    std::fprintf(stderr, "replay: cannot create %s: %s\n", out_dir.c_str(), ec.message().c_str());
    return 1;
  }
  if (can_log.empty()) can_log = (std::filesystem::path(out_dir) / "can.log").string();

  install_stop_signals();
  std::vector<app::TickRecord> ticks;
  std::vector<app::FrameRecord> fixes;
  // --odom-from-can: the odometry fusion got from the bus, on the replay clock. With the
  // recording's frames it is a recording of this run's inputs: `agvloc replay` of it reproduces
  // the run without the bus's timing (tests/hil compares against that).
  std::vector<recording::OdomRow> odom_received;
  app::RunResult result;
  // With --odom-from-can the vehicle's inputs come from the bus, gyro included (a replay of
  // odom_received.csv with the frames must reproduce the run), so imu.csv is not fed then.
  const bool imu_fed = rec.has_imu && !odom_from_can;
  std::printf("replay: %s: %zu frames, %zu odometry samples%s%s, map %s, mode %s\n",
              rec_dir.c_str(), rec.frames.size(), rec.odom.size(),
              rec.has_imu ? (", " + std::to_string(rec.imu.size()) + " gyro samples").c_str() : "",
              rec.has_truth ? ", truth" : "", map_ptr ? map_file.c_str() : "(payload poses only)",
              realtime ? "realtime" : "fast");

  can::CandumpWriter log;
  std::unique_ptr<can::SocketCanBus> socket_bus;
  if (!can_iface.empty()) {
    can::SocketCanConfig sc;
    sc.iface = can_iface;
    socket_bus = std::make_unique<can::SocketCanBus>(sc);
    if (socket_bus->state() == hal::CanBusState::kDown) {
      std::fprintf(stderr, "replay: CAN %s not available yet (%s); will keep retrying\n",
                   can_iface.c_str(), socket_bus->last_error());
    }
  } else if (!log.open(can_log, &err)) {
    std::fprintf(stderr, "replay: %s\n", err.c_str());
    return 1;
  }

  // VDA 5050 (vda5050.enabled): stamped in recording time, so a message matches poses.csv.
  app::MqttHandoff mqtt_handoff;
  std::unique_ptr<app::MqttPublisher> mqtt;
  if (cfg.vda5050.enabled) {
    mqtt = std::make_unique<app::MqttPublisher>(cfg.vda5050, mqtt_handoff, app::StampClock::kLoop,
                                                cfg.loop.service_cpus);
    if (!mqtt->start(&err)) {
      std::fprintf(stderr, "replay: %s\n", err.c_str());
      return 2;
    }
  }
  app::MqttHandoff* mqtt_io = mqtt ? &mqtt_handoff : nullptr;

  // Diagnostics page (--serve): the same page as `agvloc run`, in recording time.
  app::DiagHandoff diag_handoff;
  app::FrameTap diag_frames;
  std::unique_ptr<app::DiagServer> diag;
  if (serve) {
    cfg.diag.enabled = true;
    diag = std::make_unique<app::DiagServer>(cfg, map_ptr, diag_handoff, diag_frames, "replay");
    if (!diag->start(&err)) {
      std::fprintf(stderr, "replay: %s\n", err.c_str());
      return 2;
    }
  }

  if (realtime) {
    // Same real-time setup as `agvloc run` (threads get their priorities in run_threads).
    if (cfg.loop.lock_memory) {
      const int e = posix::lock_all_memory();
      if (e)
        std::fprintf(stderr, "replay: %s\n", posix::explain_realtime_error("mlockall", e).c_str());
    }
    posix::PosixClock mono;
    std::int64_t t_first = rec.frames.empty() ? (rec.odom.empty() ? 0 : rec.odom.front().t_ns)
                                              : rec.frames.front().t_ns;
    hal::CanFrame first_odometry{};
    std::int64_t mono0 = mono.now_ns();
    if (odom_from_can) {
      mono0 = wait_first_odometry(*socket_bus, cfg, &first_odometry);
      if (mono0 < 0) return 1;
      if (!rec.odom.empty()) t_first = rec.odom.front().t_ns;
    }
    adapters::ScaledClock clock(mono, t_first, speed, mono0);
    recording::ReplayCamera camera(rec, &clock);
    std::unique_ptr<hal::CanBus> bus;
    if (socket_bus) {
      auto mapped = std::make_unique<adapters::TimeMappedBus>(*socket_bus, &clock);
      // The anchoring frame is odometry like the rest (the HIL found it missing from fusion).
      if (odom_from_can) mapped->unread(first_odometry);
      bus = std::move(mapped);
    } else {
      bus = std::make_unique<can::LogOnlyBus>(log, clock, "can0");
    }
    const double duration_s =
        static_cast<double>((rec.odom.empty() ? t_first : rec.odom.back().t_ns) - t_first) / 1e9;
    // A real-time run can outlast the recording: it ends when the last frame is processed and
    // the odometry has stopped, and a loaded machine (or a VM) delivers frames late. With the
    // record 5 s longer than the recording, a HIL run under load lost 206 ticks' rows (2 s past
    // it). The record is allocated once; a run past it is reported
    // (RunResult::ticks_not_recorded), not silently cut.
    ticks.reserve(
        static_cast<size_t>((duration_s + kRealtimeRecordSlackS) * cfg.loop.output_rate_hz) + 16);
    fixes.reserve(rec.frames.size() + 16);
    if (odom_from_can) {
      const double rec_hz =
          duration_s > 0.0 ? static_cast<double>(rec.odom.size()) / duration_s : 0.0;
      odom_received.reserve(
          static_cast<size_t>((duration_s + kRealtimeRecordSlackS) *
                              std::max(2.0 * rec_hz, kMinReceivedOdometryRecordHz)));
    }
    app::PipelineIo io;
    io.camera = &camera;
    io.bus = bus.get();
    io.clock = &clock;
    io.odometry = odom_from_can ? nullptr : &rec.odom;
    io.imu = imu_fed ? &rec.imu : nullptr;
    io.ticks = &ticks;
    io.fixes = &fixes;
    io.odometry_received = odom_from_can ? &odom_received : nullptr;
    if (odom_from_can && !rec.odom.empty()) io.can_odometry_end_ns = rec.odom.back().t_ns;
    io.stop = &stop_requested();
    io.quiet = quiet;
    io.mqtt = mqtt_io;
    io.diag = diag ? &diag_handoff : nullptr;
    io.diag_frames = diag ? &diag_frames : nullptr;
    const std::int64_t w0 = posix::monotonic_now_ns();
    app::run_threads(cfg, map_ptr, io, &result);
    result.wall_ns = posix::monotonic_now_ns() - w0;
  } else {
    // The span is bounded above, so this is at most kMaxReplayTicks records, allocated once.
    const std::int64_t t0 = std::min(rec.frames.empty() ? INT64_MAX : rec.frames.front().t_ns,
                                     rec.odom.empty() ? INT64_MAX : rec.odom.front().t_ns);
    const std::int64_t t1 = std::max(rec.frames.empty() ? 0 : rec.frames.back().t_ns,
                                     rec.odom.empty() ? 0 : rec.odom.back().t_ns);
    if (t1 >= t0) ticks.reserve(static_cast<size_t>((t1 - t0) / period_ns) + 16);
    fixes.reserve(rec.frames.size());  // at most one record per frame
    adapters::SteppedClock clock;
    can::LogOnlyBus bus(log, clock, "can0");
    app::run_fast(cfg, map_ptr, rec, &bus, &clock, &ticks, &fixes, &stop_requested(), &result,
                  !quiet, mqtt_io, diag ? &diag_handoff : nullptr, diag ? &diag_frames : nullptr);
  }
  if (can_iface.empty() && !log.close()) {
    std::fprintf(stderr, "replay: writing %s failed\n", can_log.c_str());
  }

  std::string mqtt_line;
  if (mqtt) {
    mqtt->stop();
    mqtt_line = app::format_mqtt_counters(mqtt->counters(), mqtt_handoff);
  }

  int rc = 0;
  // Say what happened to unreadable frames; a replay that could read no frame at all failed.
  if (result.camera.errors > 0) {
    std::fprintf(stderr, "replay: %llu of %zu frames could not be read (last: %s)\n",
                 static_cast<unsigned long long>(result.camera.errors), rec.frames.size(),
                 result.camera_error.c_str());
  }
  if (!rec.frames.empty() && result.camera.frames_delivered == 0 && !stop_requested().load()) {
    std::fprintf(stderr, "replay: no frame of %s could be read: the run used odometry only\n",
                 rec_dir.c_str());
    rc = 1;
  }
  if (result.ticks_not_recorded > 0 || result.fixes_not_recorded > 0 ||
      result.odometry_not_recorded > 0) {
    std::fprintf(stderr,
                 "replay: the record was full: %llu output ticks, %llu vision results and %llu "
                 "received odometry samples are not in %s\n",
                 static_cast<unsigned long long>(result.ticks_not_recorded),
                 static_cast<unsigned long long>(result.fixes_not_recorded),
                 static_cast<unsigned long long>(result.odometry_not_recorded), out_dir.c_str());
  }
  const std::string poses = (std::filesystem::path(out_dir) / "poses.csv").string();
  const std::string fixes_csv = (std::filesystem::path(out_dir) / "fixes.csv").string();
  const std::string odom_csv = (std::filesystem::path(out_dir) / "odom_received.csv").string();
  if (!app::write_poses_csv(poses, ticks, &err) || !app::write_fixes_csv(fixes_csv, fixes, &err) ||
      (odom_from_can && !app::write_odometry_csv(odom_csv, odom_received, &err))) {
    std::fprintf(stderr, "replay: %s\n", err.c_str());
    rc = 1;
  }
  if (!overlay_frames.empty()) write_overlays(cfg, map_ptr, rec, overlay_frames, out_dir);
  // Frames but no fix at all: the likely cause, beside the other diagnostics (exit code unchanged:
  // an odometry-only replay is still a replay).
  app::NoFixContext why;
  why.family = cfg.vision.family;
  if (std::find(config_keys.begin(), config_keys.end(), "landmark.family") != config_keys.end()) {
    why.family_source = "--config";
  } else if (!rec.meta.landmark_family.empty()) {
    why.family_source = "meta.yaml";
  }
  why.have_map = map_ptr != nullptr;
  why.height_mm = cfg.camera_model.mount.height_mm;
  why.size_mm = cfg.landmark_size_mm;
  std::fputs(app::no_fix_hint(result, fixes, why).c_str(), stderr);

  std::string summary;
  char buf[256];
  std::snprintf(
      buf, sizeof buf,
      "replay summary: %zu frames, %llu landmark fixes fused, %zu output ticks, wall %.1f s\n",
      rec.frames.size(), static_cast<unsigned long long>(result.output.fixes_fused), ticks.size(),
      static_cast<double>(result.wall_ns) / 1e9);
  summary += buf;
  summary += gyro_summary(result.output, rec, imu_fed);
  for (const auto& d : differ) summary += "camera from --config over meta.yaml: " + d + "\n";
  summary += app::format_statistics(result);
  summary += mqtt_line;
  // Accuracy against truth and the plot are desk tools, not in the vehicle binary.
  if (rec.has_truth) {
    summary += "truth.csv present: accuracy and trajectory.svg with `agvloc-desk report " +
               out_dir + " --recording " + rec_dir + "`\n";
  }
  summary += "outputs: " + poses + ", " + fixes_csv + (can_iface.empty() ? ", " + can_log : "") +
             (odom_from_can ? ", " + odom_csv : "") + "\n";
  std::fputs(summary.c_str(), stdout);
  std::ofstream(std::filesystem::path(out_dir) / "summary.txt") << summary;
  if (diag) {
    // The page keeps the replay's final state (pose, statistics, trajectory, newest frame) until
    // the user is done with it.
    std::printf(
        "diag: replay finished; serving its final state on port %d until SIGINT / "
        "SIGTERM\n",
        diag->port());
    std::fflush(stdout);
    while (!stop_requested().load()) std::this_thread::sleep_for(std::chrono::milliseconds(100));
    diag->stop();
    std::fputs(app::format_diag_counters(diag->stats()).c_str(), stdout);
  }
  return rc;
}

}  // namespace agv::cmd
