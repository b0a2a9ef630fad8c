// agvloc-overhead's inputs: the site file (fleet and ceiling cameras) and one recording folder per
// ceiling camera in the format `agvloc-desk render-site` writes (docs/guide/recording.md, plus
// camera.yaml naming the camera), matched to the site's cameras by id.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "agv/recording/recording.hpp"
#include "agv/site/site.hpp"
#include "config.hpp"

namespace agv::overhead_app {

// Reads and checks a site file and the floor map it names (relative to its folder). False with
// one line per problem ("SITE: key (line N): message").
bool load_site_file(const std::string& path, site::Site* out, std::vector<std::string>* errors);

struct CameraRecording {
  std::size_t site_camera = 0;  // index into site.cameras
  std::string id;
  std::int64_t latency_ns = 0;
  recording::Recording rec;
};

// The id in DIR/camera.yaml; false with *error when the file is missing, malformed, has no id, or
// describes a camera on a vehicle.
bool read_camera_id(const std::string& dir, std::string* id, std::string* error);

// Opens every recording folder, matches it to a site camera (its intrinsics and pose are the
// site's: the recording's image size must equal them) and applies the configured latency. False
// with *error naming the folder and what is wrong; warnings (a cut last line) in *warnings.
bool open_recordings(const std::vector<std::string>& dirs, const site::Site& site,
                     const OverheadConfig& cfg, std::vector<CameraRecording>* out,
                     std::vector<std::string>* warnings, std::string* error);

// Every two fleet vehicles' tags are at least min_bits apart (overhead::tag_distance: a tag read
// with that many wrong bits could decode as the other); else false with *error naming the first
// pair and counting the others.
bool check_fleet_tag_distance(const site::Site& site, int min_bits, std::string* error);

// The site's ids that become MQTT topic levels (topics.hpp): with output.mqtt.enabled every
// vehicle's and camera's (VDA 5050 visualization and camera state topics); with `bus` every
// camera's (PREFIX/detections/CAMERA, its detection messages' camera id: at most
// overhead::kMaxCameraIdChars). False with *error naming the first id refused.
bool check_site_topic_ids(const OverheadConfig& cfg, const site::Site& site, bool bus,
                          std::string* error);

// Every configured cameras.<id> names a camera of the site, the fleet's tags are
// identity.min_tag_distance apart and, with output.mqtt.enabled, the site's ids are topic levels
// (check_site_topic_ids); else false with *error.
bool check_config_against_site(const OverheadConfig& cfg, const site::Site& site,
                               std::string* error);

// What every command that tracks starts from: the configuration (its defaults when config_path is
// empty) and the site, checked against each other. False after printing each problem as
// "agvloc-overhead COMMAND: ..." on stderr.
bool load_config_and_site(const char* command, const std::string& config_path,
                          const std::string& site_path, OverheadConfig* cfg, site::Site* site);

// Prints "agvloc-overhead COMMAND: MSG" on stderr and returns code.
int command_fail(const char* command, int code, const std::string& msg);

}  // namespace agv::overhead_app
