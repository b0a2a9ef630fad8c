// Frames of every camera merged in the order they reach the tracker (exposure time plus the
// camera's configured latency; fixes keep their exposure time), and every vehicle's state
// published at output.rate_hz on a clock of its own, extrapolated to the tick.
#include "replay.hpp"

#include <opencv2/core.hpp>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <memory>
#include <thread>

#include "agv/overhead/camera_frame.hpp"
#include "inputs.hpp"
#include "outputs.hpp"
#include "visualization.hpp"

namespace agv::overhead_app {

namespace {

constexpr int kMqttConnectTimeoutMs = 5000;
constexpr int kMqttFlushTimeoutMs = 3000;
constexpr int kFrameWarningsShown = 5;

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

std::int64_t epoch_now_ns() {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(
             std::chrono::system_clock::now().time_since_epoch())
      .count();
}

class Replay {
 public:
  Replay(const OverheadConfig& cfg, const site::Site& site, std::vector<CameraRecording> cams)
      : cfg_(cfg),
        site_(site),
        cams_(std::move(cams)),
        processor_(site.cameras, site.fleet, cfg.detect, cfg.search),
        tracker_(site.fleet.size(), cfg.tracker),
        header_ids_(site.fleet.size(), 0) {}

  bool open_outputs(const std::string& out_dir, std::string* error) {
    if (!out_dir.empty() && !csv_.open(out_dir, error)) return false;
    if (!cfg_.mqtt.enabled) return true;
    const std::string map_id = cfg_.mqtt.map_id.empty() ? site_.name : cfg_.mqtt.map_id;
    for (const site::FleetAgv& a : site_.fleet) {
      if (!topic_level_ok(a.id)) {
        *error = "fleet: AGV id '" + a.id + "' cannot be an MQTT topic level";
        return false;
      }
      ids_.push_back(identity_of(cfg_.mqtt, map_id, a.id));
    }
    mqtt_ = std::make_unique<MqttOut>();
    return mqtt_->start(cfg_.mqtt, kMqttConnectTimeoutMs, error);
  }

  void run(bool fast) {
    const std::vector<FrameEvent> events = merge_frames(cams_);
    const auto period_ns = static_cast<std::int64_t>(std::llround(1e9 / cfg_.output_rate_hz));
    const std::int64_t t0 = events.front().arrival_ns;
    const auto wall0 = std::chrono::steady_clock::now();
    std::int64_t next_tick = t0;
    for (const FrameEvent& e : events) {
      for (; next_tick <= e.arrival_ns; next_tick += period_ns) {
        if (!fast) pace(wall0, next_tick - t0);
        publish(next_tick);
      }
      if (!fast) pace(wall0, e.arrival_ns - t0);
      process(e);
    }
    publish(next_tick);
  }

  bool finish(std::string* error) {
    if (mqtt_) mqtt_->stop(kMqttFlushTimeoutMs);
    print_summary();
    return !csv_.is_open() || csv_.close(error);
  }

 private:
  static void pace(std::chrono::steady_clock::time_point wall0, std::int64_t since_ns) {
    std::this_thread::sleep_until(wall0 + std::chrono::nanoseconds(since_ns));
  }

  void process(const FrameEvent& e) {
    const CameraRecording& cam = cams_[e.input];
    cv::Mat gray;
    std::string err;
    if (!recording::load_frame(cam.rec, e.frame, &gray, &err)) {
      if (++bad_frames_ <= kFrameWarningsShown) {
        std::fprintf(stderr, "agvloc-overhead replay: %s: frame skipped: %s\n", cam.rec.dir.c_str(),
                     err.c_str());
      }
      return;
    }
    detections_.clear();
    processor_.process(cam.site_camera, cam.rec.frames[e.frame].t_ns, gray, &tracker_,
                       &detections_);
    ++frames_;
    for (const overhead::Detection& d : detections_) {
      ++detections_total_;
      if (csv_.is_open()) csv_.detection(detection_row(site_, d));
    }
  }

  void publish(std::int64_t t_ns) {
    tracker_.update_states(t_ns);
    const std::int64_t epoch_ns = mqtt_ ? epoch_now_ns() : 0;
    for (std::size_t i = 0; i < site_.fleet.size(); ++i) {
      const overhead::TrackOutput t = tracker_.output(i, t_ns);
      if (t.state == overhead::TrackState::kNone) continue;
      if (csv_.is_open()) csv_.track(track_row(site_.fleet[i].id, t));
      if (mqtt_) {
        mqtt_->publish(vda5050::topic(ids_[i], "visualization"),
                       visualization_json(ids_[i], header_ids_[i]++, epoch_ns, t));
      }
    }
  }

  void print_summary() const {
    const overhead::FrameCounters& f = processor_.counters();
    const overhead::TrackerCounters& c = tracker_.counters();
    std::printf(
        "agvloc-overhead replay: %zu cameras, %llu frames (%llu unreadable, skipped), %llu "
        "detections (%llu unknown ids, %llu without fix)\n",
        cams_.size(), static_cast<unsigned long long>(frames_),
        static_cast<unsigned long long>(bad_frames_),
        static_cast<unsigned long long>(detections_total_),
        static_cast<unsigned long long>(f.unknown_ids), static_cast<unsigned long long>(f.no_fix));
    std::printf(
        "agvloc-overhead replay: fixes applied %llu, tracks started %llu, gated %llu, too old "
        "%llu, invalid %llu, lost %llu\n",
        static_cast<unsigned long long>(c.applied), static_cast<unsigned long long>(c.started),
        static_cast<unsigned long long>(c.gated), static_cast<unsigned long long>(c.too_old),
        static_cast<unsigned long long>(c.invalid), static_cast<unsigned long long>(c.lost));
    if (mqtt_) {
      std::printf("agvloc-overhead replay: mqtt: %llu messages sent, %llu dropped\n",
                  static_cast<unsigned long long>(mqtt_->sent()),
                  static_cast<unsigned long long>(mqtt_->dropped()));
    }
  }

  const OverheadConfig& cfg_;
  const site::Site& site_;
  std::vector<CameraRecording> cams_;
  overhead::CameraFrameProcessor processor_;
  overhead::FleetTracker tracker_;
  std::vector<overhead::Detection> detections_;
  CsvOut csv_;
  std::unique_ptr<MqttOut> mqtt_;
  std::vector<vda5050::Identity> ids_;
  std::vector<std::uint32_t> header_ids_;
  std::uint64_t frames_ = 0, bad_frames_ = 0, detections_total_ = 0;
};

int fail(int code, const std::string& msg) {
  std::fprintf(stderr, "agvloc-overhead replay: %s\n", msg.c_str());
  return code;
}

}  // namespace

int run_replay(const ReplayArgs& args) {
  OverheadConfig cfg;
  std::vector<std::string> errors;
  if (!args.config_path.empty() && !load_config(args.config_path, &cfg, &errors)) {
    for (const std::string& e : errors) fail(2, e);
    return 2;
  }
  site::Site site;
  if (!load_site_file(args.site_path, &site, &errors)) {
    for (const std::string& e : errors) fail(2, e);
    return 2;
  }
  std::string err;
  if (!check_config_against_site(cfg, site, &err)) return fail(2, args.config_path + ": " + err);
  std::vector<CameraRecording> cams;
  std::vector<std::string> warnings;
  if (!open_recordings(args.recordings, site, cfg, &cams, &warnings, &err)) return fail(2, err);
  for (const std::string& w : warnings) std::fprintf(stderr, "agvloc-overhead replay: warning: %s\n", w.c_str());
  Replay replay(cfg, site, std::move(cams));
  if (!replay.open_outputs(args.out_dir, &err)) return fail(1, err);
  replay.run(args.fast);
  if (!replay.finish(&err)) return fail(1, err);
  return 0;
}

}  // namespace agv::overhead_app
