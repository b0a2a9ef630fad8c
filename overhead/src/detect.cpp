#include "detect.hpp"

#include <chrono>
#include <cstdio>
#include <opencv2/core.hpp>
#include <thread>

#include "agv/overhead/camera_frame.hpp"
#include "agv/overhead/detection_msg.hpp"
#include "inputs.hpp"
#include "visualization.hpp"

namespace agv::overhead_app {
namespace {

constexpr int kDetectConnectTimeoutMs = 5000;
constexpr int kDetectFlushTimeoutMs = 10000;

std::vector<overhead::MsgTag> tags_of(const std::vector<overhead::Detection>& dets) {
  std::vector<overhead::MsgTag> tags;
  tags.reserve(dets.size());
  for (const overhead::Detection& d : dets) tags.push_back({d.tag, d.level});
  return tags;
}

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

int run_detect(const DetectArgs& a) {
  OverheadConfig cfg;
  site::Site site;
  if (!load_config_and_site("detect", a.config_path, a.site_path, &cfg, &site)) return 2;
  std::string err;
  CameraRecording cam;
  const std::string bad_camera = topic_error("--camera", a.camera, topic_level_problem(a.camera));
  if (!bad_camera.empty()) return command_fail("detect", 2, bad_camera);
  if (!check_site_topic_ids(cfg, site, true, &err)) return command_fail("detect", 2, err);
  if (!open_camera(a, site, cfg, &cam, &err)) return command_fail("detect", 2, err);
  // The camera's own tracks steer its search windows (predicted reads, areas); the fixes that
  // count are made again by the tracker from the published corners.
  overhead::CameraFrameProcessor processor(site.cameras, site.fleet, cfg.detect, cfg.search);
  processor.set_tray_fit(cfg.tray_fit, cfg.tray);
  overhead::FleetTracker local(site.fleet.size(), cfg.tracker);
  MqttOut out;
  if (!out.start(cfg.mqtt, kDetectConnectTimeoutMs, &err)) return command_fail("detect", 1, err);
  const std::string topic = detections_topic(cfg, a.camera);
  const auto wall0 = std::chrono::steady_clock::now();
  const std::int64_t t0 = cam.rec.frames.empty() ? 0 : cam.rec.frames.front().t_ns;
  std::vector<overhead::Detection> dets;
  overhead::DetectionMsg msg;
  msg.camera_id = a.camera;
  cv::Mat gray;
  std::uint64_t tags = 0, unreadable = 0;
  for (std::size_t i = 0; i < cam.rec.frames.size(); ++i) {
    const std::int64_t t_ns = cam.rec.frames[i].t_ns;
    if (!a.fast) std::this_thread::sleep_until(wall0 + std::chrono::nanoseconds(t_ns - t0));
    if (!recording::load_frame(cam.rec, i, &gray, &err)) {
      if (++unreadable <= 5) command_fail("detect", 0, "frame skipped: " + err);
      continue;
    }
    dets.clear();
    processor.process(cam.site_camera, t_ns, gray, &local, &dets);
    msg.t_ns = t_ns;
    msg.tags = tags_of(dets);
    tags += msg.tags.size();
    out.publish(topic, overhead::encode_detections(msg));
    ++msg.seq;
  }
  out.stop(kDetectFlushTimeoutMs);
  std::printf(
      "agvloc-overhead detect: camera %s: %llu frames (%llu unreadable), %llu tags; mqtt %s: %llu "
      "messages sent, %llu dropped\n",
      a.camera.c_str(), static_cast<unsigned long long>(msg.seq),
      static_cast<unsigned long long>(unreadable), static_cast<unsigned long long>(tags),
      topic.c_str(), static_cast<unsigned long long>(out.sent()),
      static_cast<unsigned long long>(out.dropped()));
  return out.dropped() == 0 ? 0 : 1;
}

}  // namespace agv::overhead_app
