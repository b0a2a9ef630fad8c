// Scaling out (docs/guide/overhead.md "Scaling out: detector processes"): `detect` runs one
// camera's tag detection and publishes each frame's tags (agv/overhead/detection_msg.hpp) on
// <detections.topic_prefix>/detections/<camera id> of the output.mqtt broker, QoS 0; `run
// --detections-from-broker` subscribes to every camera's topic and feeds the tags to the tracker
// by their exposure stamps, publishing the tracks as `run` does.
#pragma once

#include <string>

#include "config.hpp"
#include "run.hpp"

namespace agv::overhead_app {

struct DetectArgs {
  std::string config_path;  // empty: the defaults
  std::string site_path;
  std::string camera;      // the site camera's id
  std::string replay_dir;  // one camera's recording
  bool fast = false;       // as fast as possible instead of at the recording's pace
};

// <detections.topic_prefix>/detections/<camera>.
std::string detections_topic(const OverheadConfig& cfg, const std::string& camera);
// What the tracker subscribes to: every camera's detections topic, <prefix>/detections/+ (the
// one wildcard; the prefix holds none, config.cpp refuses it).
std::string detections_subscription(const OverheadConfig& cfg);

// Exit code: 0 done, 2 bad input, 1 the broker refused or went away.
int run_detect(const DetectArgs& args);
// `run --detections-from-broker`: until SIGINT / SIGTERM or args.duration_s.
int run_broker_tracker(const RunArgs& args);

}  // namespace agv::overhead_app
