#include "detect.hpp"

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <opencv2/core.hpp>
#include <thread>

#include "agv/overhead/camera_frame.hpp"
#include "agv/overhead/detection_msg.hpp"
#include "inputs.hpp"
#include "live.hpp"
#include "visualization.hpp"

namespace agv::overhead_app {
namespace {

constexpr int kDetectConnectTimeoutMs = 5000;
constexpr int kDetectFlushTimeoutMs = 10000;

// The recording of --replay, checked to be --camera's.
bool open_camera(const DetectArgs& a, const site::Site& site, const OverheadConfig& cfg,
                 CameraRecording* out, std::string* error) {
  std::vector<CameraRecording> cams;
  std::vector<std::string> warnings;
  if (!open_recordings({a.replay_dir}, site, cfg, &cams, &warnings, error)) return false;
  for (const std::string& w : warnings) command_fail("detect", 0, "warning: " + w);
  if (cams[0].id != a.camera) {
    *error = a.replay_dir + ": a recording of camera '" + cams[0].id + "', not of --camera '" +
             a.camera + "'";
    return false;
  }
  *out = std::move(cams[0]);
  return true;
}

}  // namespace

std::string detections_topic(const OverheadConfig& cfg, const std::string& camera) {
  return cfg.detections.topic_prefix + "/detections/" + camera;
}

std::string detections_subscription(const OverheadConfig& cfg) {
  return detections_topic(cfg, "+");
}

std::string orders_subscription(const OverheadConfig& cfg) {
  return cfg.orders.interface_name + "/+/+/+/order";
}

bool is_order_topic(const OverheadConfig& cfg, const std::string& topic) {
  const std::string detections = detections_topic(cfg, "");
  return topic.compare(0, detections.size(), detections) != 0;
}

namespace {

std::atomic<bool> g_stop{false};

extern "C" void on_detect_stop_signal(int) { g_stop.store(true); }

void print_summary(const std::string& camera, const CameraDetector& det, std::uint64_t refused,
                   const std::string& topic, const MqttOut& out) {
  std::printf(
      "agvloc-overhead detect: camera %s: %llu frames (%llu refused or unreadable), %llu tags; "
      "mqtt %s: %llu messages sent, %llu dropped\n",
      camera.c_str(), static_cast<unsigned long long>(det.frames()),
      static_cast<unsigned long long>(refused), static_cast<unsigned long long>(det.tags()),
      topic.c_str(), static_cast<unsigned long long>(out.sent()),
      static_cast<unsigned long long>(out.dropped()));
}

// The recording's frames at its pace (or --fast); the number of frames not detected.
std::uint64_t detect_replay(const DetectArgs& a, const CameraRecording& cam, CameraDetector* det,
                            MqttOut* out, const std::string& topic) {
  const auto wall0 = std::chrono::steady_clock::now();
  const std::int64_t t0 = cam.rec.frames.empty() ? 0 : cam.rec.frames.front().t_ns;
  cv::Mat gray;
  std::string err;
  std::uint64_t skipped = 0;
  for (std::size_t i = 0; i < cam.rec.frames.size(); ++i) {
    const std::int64_t t_ns = cam.rec.frames[i].t_ns;
    if (!a.fast) std::this_thread::sleep_until(wall0 + std::chrono::nanoseconds(t_ns - t0));
    const overhead::DetectionMsg* m =
        recording::load_frame(cam.rec, i, &gray, &err) ? det->detect(t_ns, gray, &err) : nullptr;
    if (m == nullptr) {
      if (++skipped <= 5) command_fail("detect", 0, "frame skipped: " + err);
      continue;
    }
    out->publish(topic, overhead::encode_detections(*m));
  }
  return skipped;
}

// The live camera cameras.<--camera>.device until SIGINT / SIGTERM or --duration-s.
int detect_live(const DetectArgs& a) {
  LiveInputs in;
  if (!start_live("detect", a.config_path, a.site_path, on_detect_stop_signal, &in)) return 2;
  auto it = std::find_if(in.cams.begin(), in.cams.end(),
                         [&a](const LiveCamera& c) { return c.id == a.camera; });
  if (it == in.cams.end()) {
    return command_fail("detect", 2,
                        "--camera " + a.camera + ": not a site camera with cameras." + a.camera +
                            ".device in " + a.config_path + " (or give --replay)");
  }
  std::string err;
  if (!check_site_topic_ids(in.cfg, in.site, true, &err)) return command_fail("detect", 2, err);
  CameraDetector det(in.site, in.cfg, it->site_camera);
  MqttOut out;
  if (!out.start(in.cfg.mqtt, kDetectConnectTimeoutMs, &err)) return command_fail("detect", 1, err);
  const std::string topic = detections_topic(in.cfg, a.camera);
  const LiveDetectCounters n = run_detect_live(
      &*it, &det,
      [&](const overhead::DetectionMsg& m) { out.publish(topic, overhead::encode_detections(m)); },
      g_stop, static_cast<std::int64_t>(std::llround(a.duration_s * 1e9)));
  out.stop(kDetectFlushTimeoutMs);
  print_summary(a.camera, det, n.frames_refused, topic, out);
  std::printf("agvloc-overhead detect: %llu frames replaced by newer ones before detection\n",
              static_cast<unsigned long long>(n.frames_replaced));
  std::printf("agvloc-overhead detect: camera %s\n", describe(a.camera, n.health).c_str());
  return out.dropped() == 0 ? 0 : 1;
}

}  // namespace

int run_detect(const DetectArgs& a) {
  const std::string bad_camera = topic_error("--camera", a.camera, topic_level_problem(a.camera));
  if (!bad_camera.empty()) return command_fail("detect", 2, bad_camera);
  if (a.replay_dir.empty()) return detect_live(a);
  OverheadConfig cfg;
  site::Site site;
  if (!load_config_and_site("detect", a.config_path, a.site_path, &cfg, &site)) return 2;
  std::string err;
  CameraRecording cam;
  if (!check_site_topic_ids(cfg, site, true, &err)) return command_fail("detect", 2, err);
  if (!open_camera(a, site, cfg, &cam, &err)) return command_fail("detect", 2, err);
  CameraDetector det(site, cfg, cam.site_camera);
  MqttOut out;
  if (!out.start(cfg.mqtt, kDetectConnectTimeoutMs, &err)) return command_fail("detect", 1, err);
  const std::string topic = detections_topic(cfg, a.camera);
  const std::uint64_t skipped = detect_replay(a, cam, &det, &out, topic);
  out.stop(kDetectFlushTimeoutMs);
  print_summary(a.camera, det, skipped, topic, out);
  return out.dropped() == 0 ? 0 : 1;
}

}  // namespace agv::overhead_app
