// Scaling out (docs/guide/overhead.md "Scaling out: detector processes"): `detect` runs one
// camera's tag detection and publishes each frame's tags (agv/overhead/detection_msg.hpp) on
// <detections.topic_prefix>/detections/<camera id> of the output.mqtt broker, QoS 0; `run
// --detections-from-broker` subscribes to every camera's topic and feeds the tags to the tracker
// by their exposure stamps, publishing the tracks as `run` does.
#pragma once

#include <atomic>
#include <cstdint>
#include <functional>
#include <opencv2/core.hpp>
#include <string>

#include "agv/overhead/camera_frame.hpp"
#include "agv/overhead/detection_msg.hpp"
#include "agv/overhead/tracker.hpp"
#include "agv/site/site.hpp"
#include "config.hpp"
#include "live_feed.hpp"
#include "run.hpp"

namespace agv::overhead_app {

struct DetectArgs {
  std::string config_path;  // empty: the defaults
  std::string site_path;
  std::string camera;       // the site camera's id
  std::string replay_dir;   // one camera's recording; empty: the live camera (cameras.<id>.device)
  bool fast = false;        // as fast as possible instead of at the recording's pace
  double duration_s = 0.0;  // live: 0 until SIGINT / SIGTERM
};

// One camera's tag detection, frame by frame, for the replay and the live camera alike. The
// camera's own tracks steer its search windows (predicted reads, areas); the fixes that count
// are made again by the tracker from the published corners.
class CameraDetector {
 public:
  CameraDetector(const site::Site& site, const OverheadConfig& cfg, std::size_t site_camera);
  // The frame's tags, stamped t_ns, with the next sequence number; null with *error for a frame
  // that is not 8-bit gray of the camera's size (nothing to publish, no number used).
  const overhead::DetectionMsg* detect(std::int64_t t_ns, const cv::Mat& gray, std::string* error);
  std::uint64_t frames() const { return msg_.seq; }
  std::uint64_t tags() const { return tags_; }

 private:
  std::size_t camera_;
  overhead::CameraFrameProcessor processor_;
  overhead::FleetTracker local_;
  std::vector<overhead::Detection> dets_;
  overhead::DetectionMsg msg_;
  std::uint64_t tags_ = 0;
};

struct LiveDetectCounters {
  std::uint64_t frames_detected = 0;
  std::uint64_t frames_refused = 0;  // not the camera's size or format (the first few logged)
  // Frames the camera delivered while the previous one was still being detected, replaced by a
  // newer one before their turn: the detector always works on the newest frame.
  std::uint64_t frames_replaced = 0;
  CameraHealth health;
};

// The live camera's frames through `det` until `stop` is set, duration_ns has passed (0: no
// limit) or its stream ended; every message to `publish` (on the calling thread). A camera that
// fails or disconnects is reopened (live_feed.hpp).
LiveDetectCounters run_detect_live(
    LiveCamera* cam, CameraDetector* det,
    const std::function<void(const overhead::DetectionMsg&)>& publish,
    const std::atomic<bool>& stop, std::int64_t duration_ns);

// <detections.topic_prefix>/detections/<camera>.
std::string detections_topic(const OverheadConfig& cfg, const std::string& camera);
// What the tracker subscribes to: every camera's detections topic, <prefix>/detections/+ (the
// one wildcard; the prefix holds none, config.cpp refuses it).
std::string detections_subscription(const OverheadConfig& cfg);

// What `run` subscribes to with orders.subscribe: <orders.interface_name>/+/+/+/order.
std::string orders_subscription(const OverheadConfig& cfg);
// A topic of that subscription (a detections topic otherwise).
bool is_order_topic(const OverheadConfig& cfg, const std::string& topic);

// Exit code: 0 done, 2 bad input, 1 the broker refused or went away.
int run_detect(const DetectArgs& args);
// `run --detections-from-broker`: until SIGINT / SIGTERM or args.duration_s.
int run_broker_tracker(const RunArgs& args);

}  // namespace agv::overhead_app
