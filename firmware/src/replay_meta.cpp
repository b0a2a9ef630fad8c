#include "replay_meta.hpp"

#include <algorithm>
#include <cstdio>

#include "agv/config/keys.hpp"

namespace agv::app {

namespace {

// Nine digits: a value that went through degrees -> radians -> degrees compares equal to itself,
// a calibration's 4th decimal does not.
std::string text(const config::Value& v) {
  if (const auto* d = std::get_if<double>(&v)) {
    char b[32];
    std::snprintf(b, sizeof b, "%.9g", *d);
    return b;
  }
  if (const auto* i = std::get_if<std::int64_t>(&v)) return std::to_string(*i);
  if (const auto* b = std::get_if<bool>(&v)) return *b ? "true" : "false";
  return std::get<std::string>(v);
}

}  // namespace

const std::vector<std::string>& meta_keys() {
  static const std::vector<std::string> keys = {
      "camera.width",         "camera.height",    "intrinsics.fx",      "intrinsics.fy",
      "intrinsics.cx",        "intrinsics.cy",    "intrinsics.k1",      "intrinsics.k2",
      "intrinsics.p1",        "intrinsics.p2",    "intrinsics.k3",      "mounting.offset_x_mm",
      "mounting.offset_y_mm", "mounting.yaw_deg", "mounting.height_mm", "mounting.roll_deg",
      "mounting.pitch_deg",   "landmark.size_mm", "landmark.family"};
  return keys;
}

bool apply_recording_meta(const recording::Meta& meta, const std::vector<std::string>& config_keys,
                          const std::string& config_name, config::Config* cfg,
                          std::vector<std::string>* lines, std::string* error) {
  config::Config from_meta = *cfg;
  from_meta.camera_model = meta.camera;
  from_meta.camera.camera.width_px = meta.camera.intrinsics.width_px;
  from_meta.camera.camera.height_px = meta.camera.intrinsics.height_px;
  from_meta.landmark_size_mm = meta.landmark_size_mm;
  // read_recording accepts only the families' names; empty (an older recording) is skipped below.
  from_meta.vision.family = LandmarkFamily::kQr;
  parse_landmark_family(meta.landmark_family, &from_meta.vision.family);
  for (const std::string& name : meta_keys()) {
    const config::Key* k = config::find_key(name);
    if (!k) continue;  // the list above names table keys only (test_replay_command checks it)
    // A recording older than the family key says nothing about it: the configuration's stands.
    if (name == "landmark.family" && meta.landmark_family.empty()) continue;
    const config::Value mv = k->get(from_meta);
    const bool given = std::find(config_keys.begin(), config_keys.end(), name) != config_keys.end();
    if (!given) {
      k->set(*cfg, mv);
      continue;
    }
    const std::string m = text(mv), c = text(k->get(*cfg));
    if (m == c) continue;
    if (name == "camera.width" || name == "camera.height") {
      *error = name + ": " + config_name + " sets " + c + ", the recording's meta.yaml " + m +
               ": the frames are " + std::to_string(meta.camera.intrinsics.width_px) + "x" +
               std::to_string(meta.camera.intrinsics.height_px) +
               " px, so a camera calibrated at another resolution does not apply";
      return false;
    }
    lines->push_back(name + ": --config " + c + " (used), meta.yaml " + m);
  }
  cfg->camera_model.intrinsics.width_px = meta.camera.intrinsics.width_px;
  cfg->camera_model.intrinsics.height_px = meta.camera.intrinsics.height_px;
  return true;
}

}  // namespace agv::app
