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
#include "cli_parse.hpp"
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
  vision::LandmarkLocalizer loc(cfg.vision, cfg.camera_model, config::landmark_geometry(cfg), map);
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

struct ReplayArgs {
  std::string rec_dir, out_dir = "replay_out", config_file, map_file, can_iface, can_log;
  bool realtime = false, fast = false, odom_from_can = false, quiet = false, serve = false;
  double speed = 1.0;
  std::vector<int> overlay_frames;
};

// The command line; -1 to go on, else the exit code.
int parse_args(int argc, char** argv, ReplayArgs* a) {
  CLI::App app{"Run the localizer on a recording (frames + odometry), docs/guide/replay.md"};
  app.add_option("recording", a->rec_dir, "recording directory (docs/guide/recording.md)")
      ->required();
  app.add_option("--out", a->out_dir, "output directory (poses.csv, fixes.csv, summary.txt, ...)");
  app.add_option("--config", a->config_file,
                 "configuration YAML; a camera, mounting or landmark.size_mm key it sets is used "
                 "instead of meta.yaml's (each difference printed)");
  app.add_option("--map", a->map_file, "landmark map (default: RECORDING/map.csv if present)");
  app.add_option("--can", a->can_iface, "send output frames on this SocketCAN interface");
  app.add_flag("--odom-from-can", a->odom_from_can,
               "take odometry from the CAN bus instead of odom.csv (needs --can, --realtime)");
  app.add_option("--can-log", a->can_log,
                 "without --can: write sent frames as a candump -l log (default OUT/can.log); with "
                 "--can log the interface with candump -l instead");
  auto* rt =
      app.add_flag("--realtime", a->realtime, "pace the replay by the clock (threads as live)");
  auto* ft = app.add_flag("--fast", a->fast, "as fast as possible, deterministic (default)");
  rt->excludes(ft);
  app.add_option("--speed", a->speed, "pace for --realtime: 1 = real time, 0.5 = half speed")
      ->check(CLI::Range(0.01, 100.0));
  app.add_option("--overlay", a->overlay_frames, "frame indices to write debug overlays for");
  app.add_flag("--quiet", a->quiet, "no progress or periodic lines");
  app.add_flag("--serve", a->serve,
               "serve the diagnostics page and /metrics during the replay and after it until "
               "SIGINT / SIGTERM (address and port: diag.* keys; docs/guide/diagnostics.md)");
  if (const int parse_rc = cli::parse(app, argc, argv); parse_rc >= 0) return parse_rc;
  if (a->odom_from_can && (a->can_iface.empty() || !a->realtime)) {
    std::fprintf(stderr, "replay: --odom-from-can needs --can IFACE and --realtime\n");
    return 2;
  }
  return -1;
}

int replay_fail(const std::string& what, int rc) {
  std::fprintf(stderr, "replay: %s\n", what.c_str());
  return rc;
}

// What the replay reads: the recording, the configuration (with meta.yaml's camera where
// --config does not set it) and the map.
struct ReplayInputs {
  recording::Recording rec;
  config::Config cfg;
  std::vector<std::string> config_keys;  // the keys --config sets
  std::vector<std::string> differ;       // meta.yaml values --config replaced
  std::string map_file;
  LandmarkMap map;
  const LandmarkMap* map_ptr = nullptr;  // null: payload poses only
  std::int64_t period_ns = 0;
  // ranging_camera.enabled: the second stream, its site's landmarks and their observer.
  recording::Recording ranging;
  app::RackSite rack_site;
  std::unique_ptr<app::RackObserver> rack;
  app::RangingCounts ranging_counts;
};

// ranging_camera.enabled: the site's landmarks, the observer and the recording's ranging/
// stream. -1 to go on, else the exit code.
int load_ranging(const ReplayArgs& a, ReplayInputs* in) {
  const config::RangingCameraSection& rc = in->cfg.ranging_camera;
  if (!rc.enabled) return -1;
  std::string err;
  if (!app::load_rack_site(rc.site_file, &in->rack_site, &err)) return replay_fail(err, 2);
  in->rack = std::make_unique<app::RackObserver>(rc, in->rack_site);
  if (!in->rack->ok(&err)) return replay_fail(err, 2);
  std::vector<std::string> warnings;
  if (!app::read_ranging_stream(a.rec_dir, rc, &in->ranging, &warnings, &err)) {
    return replay_fail(a.rec_dir + ": " + err, 1);
  }
  for (const auto& w : warnings) replay_fail("warning: " + w, 0);
  return -1;
}

// The keys a configuration file sets; false with *err.
bool config_file_keys(const std::string& file, std::vector<std::string>* keys, std::string* err) {
  std::string text;
  std::vector<config::YamlEntry> entries;
  if (!recording::read_file_bounded(file, config::kMaxConfigBytes, &text, err) ||
      !config::yaml_entries(text, &entries, err)) {
    return false;
  }
  for (const auto& e : entries) keys->push_back(e.key);
  return true;
}

// -1 to go on, else the exit code.
int load_inputs(ReplayArgs& a, ReplayInputs* in) {
  std::string err;
  if (!recording::read_recording(a.rec_dir, &in->rec, &err)) return replay_fail(err, 1);
  for (const auto& w : in->rec.warnings) replay_fail("warning: " + w, 0);
  config::Config& cfg = in->cfg;
  if (!a.config_file.empty() &&
      !config::load_config_or_report(a.config_file, "replay", &cfg, config::ConfigUse::kReplay)) {
    return 2;
  }
  // Every output period from the first to the last recorded time is simulated and written to
  // poses.csv: bound it, so odometry rows at t = 1e10 and 9e18 cannot run without end.
  in->period_ns = static_cast<std::int64_t>(1e9 / cfg.loop.output_rate_hz);
  if (!recording::check_replay_span(in->rec, in->period_ns, kMaxReplayTicks, &err)) {
    return replay_fail(a.rec_dir + ": " + err, 2);
  }
  // One rule for meta.yaml against --config (docs/guide/replay.md): what --config sets is used (a
  // calibrated mounting is replayed as calibrated, as calibrate vehicle --config does), the
  // recording gives the rest; each value that differs is printed.
  if (!a.config_file.empty() && !config_file_keys(a.config_file, &in->config_keys, &err)) {
    return replay_fail("config: " + a.config_file + ": " + err, 2);
  }
  if (!app::apply_recording_meta(in->rec.meta, in->config_keys, a.config_file, &cfg, &in->differ,
                                 &err)) {
    return replay_fail(err, 2);
  }
  for (const auto& d : in->differ) replay_fail(d, 0);
  in->map_file = a.map_file;
  if (in->map_file.empty() &&
      std::filesystem::exists(std::filesystem::path(a.rec_dir) / "map.csv")) {
    in->map_file = (std::filesystem::path(a.rec_dir) / "map.csv").string();
  }
  if (in->map_file.empty() && !cfg.map_file.empty()) in->map_file = cfg.map_file;
  if (!in->map_file.empty()) {
    if (!config::load_map_file(in->map_file, &in->map, &err)) return replay_fail("map: " + err, 2);
    in->map_ptr = &in->map;
  }
  if (const int rc = load_ranging(a, in); rc >= 0) return rc;
  std::error_code ec;
  std::filesystem::create_directories(a.out_dir, ec);
  if (ec) return replay_fail("cannot create " + a.out_dir + ": " + ec.message(), 1);
  if (a.can_log.empty()) a.can_log = (std::filesystem::path(a.out_dir) / "can.log").string();
  return -1;
}

// Where the replay's outputs go besides its files: the CAN bus (or its log), the VDA 5050
// publisher, the diagnostics page.
struct ReplayOutputs {
  can::CandumpWriter log;
  std::unique_ptr<can::SocketCanBus> socket_bus;
  app::MqttHandoff mqtt_handoff;
  std::unique_ptr<app::MqttPublisher> mqtt;
  app::DiagHandoff diag_handoff;
  app::FrameTap diag_frames;
  std::unique_ptr<app::DiagServer> diag;

  // -1 to go on, else the exit code.
  int open(const ReplayArgs& a, ReplayInputs& in) {
    std::string err;
    if (!a.can_iface.empty()) {
      can::SocketCanConfig sc;
      sc.iface = a.can_iface;
      socket_bus = std::make_unique<can::SocketCanBus>(sc);
      if (socket_bus->state() == hal::CanBusState::kDown) {
        std::fprintf(stderr, "replay: CAN %s not available yet (%s); will keep retrying\n",
                     a.can_iface.c_str(), socket_bus->last_error());
      }
    } else if (!log.open(a.can_log, &err)) {
      return replay_fail(err, 1);
    }
    // VDA 5050 (vda5050.enabled): stamped in recording time, so a message matches poses.csv.
    if (in.cfg.vda5050.enabled) {
      mqtt = std::make_unique<app::MqttPublisher>(in.cfg.vda5050, mqtt_handoff,
                                                  app::StampClock::kLoop, in.cfg.loop.service_cpus);
      if (!mqtt->start(&err)) return replay_fail(err, 2);
    }
    // Diagnostics page (--serve): the same page as `agvloc run`, in recording time.
    if (a.serve) {
      in.cfg.diag.enabled = true;
      diag = std::make_unique<app::DiagServer>(in.cfg, in.map_ptr, diag_handoff, diag_frames,
                                               "replay");
      if (!diag->start(&err)) return replay_fail(err, 2);
    }
    return -1;
  }
  // The loop's sinks, in order, and the page's frame tap.
  void attach(app::PipelineIo* io) {
    if (mqtt) io->sinks.push_back(&mqtt_handoff);
    if (diag) {
      io->sinks.push_back(&diag_handoff);
      io->diag_frames = &diag_frames;
    }
  }
};

// What the run produced.
struct ReplayRecord {
  std::vector<app::TickRecord> ticks;
  std::vector<app::FrameRecord> fixes;
  // --odom-from-can: the odometry fusion got from the bus, on the replay clock. With the
  // recording's frames it is a recording of this run's inputs: `agvloc replay` of it reproduces
  // the run without the bus's timing (tests/hil compares against that).
  std::vector<recording::OdomRow> odom_received;
  app::RunResult result;
};

// --realtime: the threads of `agvloc run` on the recording's clock. -1, or the exit code.
int run_realtime(const ReplayArgs& a, ReplayInputs& in, ReplayOutputs& out, bool imu_fed,
                 ReplayRecord* r) {
  const config::Config& cfg = in.cfg;
  const recording::Recording& rec = in.rec;
  // Same real-time setup as `agvloc run` (threads get their priorities in run_threads).
  if (cfg.loop.lock_memory) {
    const int e = posix::lock_all_memory();
    if (e) replay_fail(posix::explain_realtime_error("mlockall", e), 0);
  }
  posix::PosixClock mono;
  std::int64_t t_first =
      rec.frames.empty() ? (rec.odom.empty() ? 0 : rec.odom.front().t_ns) : rec.frames.front().t_ns;
  hal::CanFrame first_odometry{};
  std::int64_t mono0 = mono.now_ns();
  if (a.odom_from_can) {
    mono0 = wait_first_odometry(*out.socket_bus, cfg, &first_odometry);
    if (mono0 < 0) return 1;
    if (!rec.odom.empty()) t_first = rec.odom.front().t_ns;
  }
  adapters::ScaledClock clock(mono, t_first, a.speed, mono0);
  recording::ReplayCamera camera(rec, &clock);
  // ranging_camera.enabled: the second stream as a camera of its own, on the same clock.
  recording::ReplayCamera ranging_camera(in.ranging, &clock);
  std::unique_ptr<hal::CanBus> bus;
  if (out.socket_bus) {
    auto mapped = std::make_unique<adapters::TimeMappedBus>(*out.socket_bus, &clock);
    // The anchoring frame is odometry like the rest (the HIL found it missing from fusion).
    if (a.odom_from_can) mapped->unread(first_odometry);
    bus = std::move(mapped);
  } else {
    bus = std::make_unique<can::LogOnlyBus>(out.log, clock, "can0");
  }
  const double duration_s =
      static_cast<double>((rec.odom.empty() ? t_first : rec.odom.back().t_ns) - t_first) / 1e9;
  // A real-time run can outlast the recording: it ends when the last frame is processed and
  // the odometry has stopped, and a loaded machine (or a VM) delivers frames late. With the
  // record 5 s longer than the recording, a HIL run under load lost 206 ticks' rows (2 s past
  // it). The record is allocated once; a run past it is reported
  // (RunResult::ticks_not_recorded), not silently cut.
  r->ticks.reserve(
      static_cast<size_t>((duration_s + kRealtimeRecordSlackS) * cfg.loop.output_rate_hz) + 16);
  r->fixes.reserve(rec.frames.size() + 16);
  if (a.odom_from_can) {
    const double rec_hz =
        duration_s > 0.0 ? static_cast<double>(rec.odom.size()) / duration_s : 0.0;
    r->odom_received.reserve(
        static_cast<size_t>((duration_s + kRealtimeRecordSlackS) *
                            std::max(2.0 * rec_hz, kMinReceivedOdometryRecordHz)));
  }
  app::PipelineIo io;
  io.camera = &camera;
  io.bus = bus.get();
  io.clock = &clock;
  io.odometry = a.odom_from_can ? nullptr : &rec.odom;
  io.imu = imu_fed ? &rec.imu : nullptr;
  io.ticks = &r->ticks;
  io.fixes = &r->fixes;
  io.odometry_received = a.odom_from_can ? &r->odom_received : nullptr;
  if (a.odom_from_can && !rec.odom.empty()) io.can_odometry_end_ns = rec.odom.back().t_ns;
  io.stop = &stop_requested();
  io.quiet = a.quiet;
  if (in.rack) {
    io.ranging_camera = &ranging_camera;
    io.rack_observer = in.rack.get();
    io.ranging_counts = &in.ranging_counts;
  }
  out.attach(&io);
  const std::int64_t w0 = posix::monotonic_now_ns();
  app::run_threads(cfg, in.map_ptr, io, &r->result);
  r->result.wall_ns = posix::monotonic_now_ns() - w0;
  return -1;
}

// --fast (the default): one thread on a stepped clock, deterministic.
void run_fast_replay(const ReplayArgs& a, ReplayInputs& in, ReplayOutputs& out, ReplayRecord* r) {
  const recording::Recording& rec = in.rec;
  // The span is bounded above, so this is at most kMaxReplayTicks records, allocated once.
  const std::int64_t t0 = std::min(rec.frames.empty() ? INT64_MAX : rec.frames.front().t_ns,
                                   rec.odom.empty() ? INT64_MAX : rec.odom.front().t_ns);
  const std::int64_t t1 = std::max(rec.frames.empty() ? 0 : rec.frames.back().t_ns,
                                   rec.odom.empty() ? 0 : rec.odom.back().t_ns);
  if (t1 >= t0) r->ticks.reserve(static_cast<size_t>((t1 - t0) / in.period_ns) + 16);
  r->fixes.reserve(rec.frames.size());  // at most one record per frame
  adapters::SteppedClock clock;
  can::LogOnlyBus bus(out.log, clock, "can0");
  app::PipelineIo io;
  io.bus = &bus;
  io.clock = &clock;
  io.odometry = &rec.odom;
  io.imu = &rec.imu;
  io.ticks = &r->ticks;
  io.fixes = &r->fixes;
  io.stop = &stop_requested();
  if (in.rack) {
    io.ranging_frames = &in.ranging;
    io.rack_observer = in.rack.get();
    io.ranging_counts = &in.ranging_counts;
  }
  out.attach(&io);
  app::run_fast(in.cfg, in.map_ptr, rec, io, &r->result, !a.quiet);
}

// Problems of the run on stderr; 1 when it read no frame at all.
int check_run(const ReplayArgs& a, const ReplayInputs& in, const app::RunResult& result) {
  int rc = 0;
  // Say what happened to unreadable frames; a replay that could read no frame at all failed.
  if (result.camera.errors > 0) {
    std::fprintf(stderr, "replay: %llu of %zu frames could not be read (last: %s)\n",
                 static_cast<unsigned long long>(result.camera.errors), in.rec.frames.size(),
                 result.camera_error.c_str());
  }
  if (!in.rec.frames.empty() && result.camera.frames_delivered == 0 && !stop_requested().load()) {
    std::fprintf(stderr, "replay: no frame of %s could be read: the run used odometry only\n",
                 a.rec_dir.c_str());
    rc = 1;
  }
  if (result.ticks_not_recorded > 0 || result.fixes_not_recorded > 0 ||
      result.odometry_not_recorded > 0) {
    std::fprintf(stderr,
                 "replay: the record was full: %llu output ticks, %llu vision results and %llu "
                 "received odometry samples are not in %s\n",
                 static_cast<unsigned long long>(result.ticks_not_recorded),
                 static_cast<unsigned long long>(result.fixes_not_recorded),
                 static_cast<unsigned long long>(result.odometry_not_recorded), a.out_dir.c_str());
  }
  return rc;
}

// Frames but no fix at all: the likely cause, beside the other diagnostics (exit code unchanged:
// an odometry-only replay is still a replay).
void print_no_fix_hint(const ReplayInputs& in, const ReplayRecord& r) {
  app::NoFixContext why;
  why.family = in.cfg.vision.family;
  if (std::find(in.config_keys.begin(), in.config_keys.end(), "landmark.family") !=
      in.config_keys.end()) {
    why.family_source = "--config";
  } else if (!in.rec.meta.landmark_family.empty()) {
    why.family_source = "meta.yaml";
  }
  why.have_map = in.map_ptr != nullptr;
  why.height_mm = in.cfg.camera_model.mount.height_mm;
  why.size_mm = in.cfg.landmark_size_mm;
  std::fputs(app::no_fix_hint(r.result, r.fixes, why).c_str(), stderr);
}

std::string summary_text(const ReplayArgs& a, const ReplayInputs& in, const ReplayRecord& r,
                         bool imu_fed, const std::string& mqtt_line,
                         const std::vector<std::string>& outputs) {
  std::string summary;
  char buf[256];
  std::snprintf(
      buf, sizeof buf,
      "replay summary: %zu frames, %llu landmark fixes fused, %zu output ticks, wall %.1f s\n",
      in.rec.frames.size(), static_cast<unsigned long long>(r.result.output.fixes_fused),
      r.ticks.size(), static_cast<double>(r.result.wall_ns) / 1e9);
  summary += buf;
  summary += gyro_summary(r.result.output, in.rec, imu_fed);
  if (in.rack) summary += app::ranging_summary(in.ranging_counts, r.result.output);
  for (const auto& d : in.differ) summary += "camera from --config over meta.yaml: " + d + "\n";
  summary += app::format_statistics(r.result);
  summary += mqtt_line;
  // Accuracy against truth and the plot are desk tools, not in the vehicle binary.
  if (in.rec.has_truth) {
    summary += "truth.csv present: accuracy and trajectory.svg with `agvloc-desk report " +
               a.out_dir + " --recording " + a.rec_dir + "`\n";
  }
  summary += "outputs: ";
  for (std::size_t i = 0; i < outputs.size(); ++i) summary += (i ? ", " : "") + outputs[i];
  return summary + "\n";
}

// poses.csv, fixes.csv, odom_received.csv, overlays and summary.txt. Returns 1 when a file could
// not be written, else rc.
int write_outputs(const ReplayArgs& a, const ReplayInputs& in, const ReplayRecord& r, bool imu_fed,
                  const std::string& mqtt_line, int rc) {
  const std::filesystem::path dir(a.out_dir);
  const std::string poses = (dir / "poses.csv").string();
  const std::string fixes_csv = (dir / "fixes.csv").string();
  const std::string odom_csv = (dir / "odom_received.csv").string();
  std::string err;
  if (!app::write_poses_csv(poses, r.ticks, &err) ||
      !app::write_fixes_csv(fixes_csv, r.fixes, &err) ||
      (a.odom_from_can && !app::write_odometry_csv(odom_csv, r.odom_received, &err))) {
    rc = replay_fail(err, 1);
  }
  if (!a.overlay_frames.empty()) {
    write_overlays(in.cfg, in.map_ptr, in.rec, a.overlay_frames, a.out_dir);
  }
  print_no_fix_hint(in, r);
  std::vector<std::string> outputs{poses, fixes_csv};
  if (a.can_iface.empty()) outputs.push_back(a.can_log);
  if (a.odom_from_can) outputs.push_back(odom_csv);
  const std::string summary = summary_text(a, in, r, imu_fed, mqtt_line, outputs);
  std::fputs(summary.c_str(), stdout);
  std::ofstream(dir / "summary.txt") << summary;
  return rc;
}

// The page keeps the replay's final state (pose, statistics, trajectory, newest frame) until the
// user is done with it.
void serve_until_stopped(app::DiagServer& diag) {
  std::printf(
      "diag: replay finished; serving its final state on port %d until SIGINT / "
      "SIGTERM\n",
      diag.port());
  std::fflush(stdout);
  while (!stop_requested().load()) std::this_thread::sleep_for(std::chrono::milliseconds(100));
  diag.stop();
  std::fputs(app::format_diag_counters(diag.stats()).c_str(), stdout);
}

}  // namespace

int replay(int argc, char** argv) {
  ReplayArgs a;
  if (const int rc = parse_args(argc, argv, &a); rc >= 0) return rc;
  ReplayInputs in;
  if (const int rc = load_inputs(a, &in); rc >= 0) return rc;
  install_stop_signals();
  const recording::Recording& rec = in.rec;
  // With --odom-from-can the vehicle's inputs come from the bus, gyro included (a replay of
  // odom_received.csv with the frames must reproduce the run), so imu.csv is not fed then.
  const bool imu_fed = rec.has_imu && !a.odom_from_can;
  std::printf("replay: %s: %zu frames, %zu odometry samples%s%s, map %s, mode %s\n",
              a.rec_dir.c_str(), rec.frames.size(), rec.odom.size(),
              rec.has_imu ? (", " + std::to_string(rec.imu.size()) + " gyro samples").c_str() : "",
              rec.has_truth ? ", truth" : "",
              in.map_ptr ? in.map_file.c_str() : "(payload poses only)",
              a.realtime ? "realtime" : "fast");
  ReplayOutputs out;
  if (const int rc = out.open(a, in); rc >= 0) return rc;
  ReplayRecord r;
  if (a.realtime) {
    if (const int rc = run_realtime(a, in, out, imu_fed, &r); rc >= 0) return rc;
  } else {
    run_fast_replay(a, in, out, &r);
  }
  if (a.can_iface.empty() && !out.log.close()) {
    std::fprintf(stderr, "replay: writing %s failed\n", a.can_log.c_str());
  }
  std::string mqtt_line;
  if (out.mqtt) {
    out.mqtt->stop();
    mqtt_line = app::format_mqtt_counters(out.mqtt->counters(), out.mqtt_handoff);
  }
  const int rc = write_outputs(a, in, r, imu_fed, mqtt_line, check_run(a, in, r.result));
  if (out.diag) serve_until_stopped(*out.diag);
  return rc;
}

}  // namespace agv::cmd
