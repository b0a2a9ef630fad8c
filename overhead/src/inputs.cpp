#include "inputs.hpp"

#include <yaml-cpp/yaml.h>

#include <cmath>
#include <cstdio>
#include <filesystem>

#include "agv/overhead/detection_msg.hpp"
#include "agv/overhead/tag_code.hpp"
#include "agv/recording/site_file.hpp"

namespace agv::overhead_app {

namespace {

namespace fs = std::filesystem;
constexpr std::uintmax_t kMaxCameraYamlBytes = 64u << 10;

std::string camera_ids(const site::Site& site) {
  std::string ids;
  for (const site::CeilingCamera& c : site.cameras) ids += (ids.empty() ? "" : ", ") + c.id;
  return ids.empty() ? "none" : ids;
}

}  // namespace

bool check_fleet_tag_distance(const site::Site& site, int min_bits, std::string* error) {
  const auto& f = site.fleet;
  std::size_t close = 0;
  std::string first;
  for (std::size_t i = 0; i < f.size(); ++i) {
    for (std::size_t j = i + 1; j < f.size(); ++j) {
      const int d = overhead::tag_distance(f[i].tag_id, f[j].tag_id);
      if (d >= min_bits || f[i].tag_id == f[j].tag_id) continue;  // one tag twice: the site's
      if (close++ == 0) {
        first = "fleet[" + std::to_string(i) + "] '" + f[i].id + "' (tag " +
                std::to_string(f[i].tag_id) + ") and fleet[" + std::to_string(j) + "] '" + f[j].id +
                "' (tag " + std::to_string(f[j].tag_id) + "): codes " + std::to_string(d) +
                " bits apart";
      }
    }
  }
  if (close == 0) return true;
  *error = "identity.min_tag_distance: tags too close: " + first +
           (close > 1 ? " (and " + std::to_string(close - 1) + " more pairs)" : "") +
           ", at least " + std::to_string(min_bits) +
           " required (give one of them another tag id, or lower identity.min_tag_distance)";
  return false;
}

bool load_site_file(const std::string& path, site::Site* out, std::vector<std::string>* errors) {
  if (!recording::read_site_file(path, out, errors)) return false;
  if (out->cameras.empty()) errors->push_back(path + ": cameras: the site has no ceiling camera");
  if (out->fleet.empty()) errors->push_back(path + ": fleet: the site has no vehicle");
  return errors->empty();
}

bool read_camera_id(const std::string& dir, std::string* id, std::string* error) {
  const std::string path = (fs::path(dir) / "camera.yaml").string();
  std::string text;
  if (!recording::read_file_bounded(path, kMaxCameraYamlBytes, &text, error)) return false;
  try {
    const YAML::Node root = YAML::Load(text);
    if (!root.IsMap() || !root["id"] || !root["id"].IsScalar() || root["id"].Scalar().empty()) {
      *error = path + ": no camera id (id: ...)";
      return false;
    }
    if (root["vehicle"]) {
      *error = path + ": a camera on vehicle '" + root["vehicle"].as<std::string>("?") +
               "', not a ceiling camera";
      return false;
    }
    *id = root["id"].Scalar();
    return true;
  } catch (const YAML::Exception& e) {
    *error = path + ": line " + std::to_string(e.mark.line + 1) + ": " + e.msg;
    return false;
  }
}

bool open_recordings(const std::vector<std::string>& dirs, const site::Site& site,
                     const OverheadConfig& cfg, std::vector<CameraRecording>* out,
                     std::vector<std::string>* warnings, std::string* error) {
  out->clear();
  for (const std::string& dir : dirs) {
    CameraRecording c;
    std::error_code ec;
    if (!fs::is_directory(dir, ec)) {
      return (*error = dir + ": no such recording folder", false);
    }
    if (!read_camera_id(dir, &c.id, error)) return false;
    bool found = false;
    for (std::size_t i = 0; i < site.cameras.size(); ++i) {
      if (site.cameras[i].id == c.id) c.site_camera = i, found = true;
    }
    if (!found) {
      *error = dir + ": camera '" + c.id +
               "' is not in the site (its cameras: " + camera_ids(site) + ")";
      return false;
    }
    for (const CameraRecording& o : *out) {
      if (o.id == c.id) return (*error = dir + ": camera '" + c.id + "' given twice", false);
    }
    std::string err;
    if (!recording::read_recording(dir, &c.rec, &err)) return (*error = dir + ": " + err, false);
    const CameraIntrinsics& k = site.cameras[c.site_camera].intrinsics;
    const CameraIntrinsics& m = c.rec.meta.camera.intrinsics;
    if (m.width_px != k.width_px || m.height_px != k.height_px) {
      *error = dir + ": frames are " + std::to_string(m.width_px) + "x" +
               std::to_string(m.height_px) + " but the site's camera '" + c.id + "' is " +
               std::to_string(k.width_px) + "x" + std::to_string(k.height_px) +
               " (a recording rendered with --scale needs a site with the scaled intrinsics)";
      return false;
    }
    if (c.rec.frames.empty()) return (*error = dir + ": frames.csv has no frame", false);
    const auto cam = cfg.cameras.find(c.id);
    if (cam != cfg.cameras.end()) c.latency_ns = std::llround(cam->second.latency_ms * 1e6);
    for (const std::string& w : c.rec.warnings) warnings->push_back(dir + ": " + w);
    out->push_back(std::move(c));
  }
  return true;
}

bool check_site_topic_ids(const OverheadConfig& cfg, const site::Site& site, bool bus,
                          std::string* error) {
  if (cfg.mqtt.enabled) {
    for (std::size_t i = 0; i < site.fleet.size(); ++i) {
      *error = topic_error("site fleet[" + std::to_string(i) + "].id", site.fleet[i].id,
                           topic_level_problem(site.fleet[i].id));
      if (!error->empty()) return false;
    }
  }
  if (!cfg.mqtt.enabled && !bus) return true;
  for (std::size_t i = 0; i < site.cameras.size(); ++i) {
    const std::string& id = site.cameras[i].id;
    std::string why = topic_level_problem(id);
    if (why.empty() && bus && id.size() > overhead::kMaxCameraIdChars) {
      why = std::to_string(id.size()) + " bytes, more than the " +
            std::to_string(overhead::kMaxCameraIdChars) + " a detections message carries";
    }
    *error = topic_error("site cameras[" + std::to_string(i) + "].id", id, why);
    if (!error->empty()) return false;
  }
  return true;
}

bool check_config_against_site(const OverheadConfig& cfg, const site::Site& site,
                               std::string* error) {
  if (!check_fleet_tag_distance(site, cfg.min_tag_distance, error)) return false;
  if (!check_site_topic_ids(cfg, site, false, error)) return false;
  for (const auto& entry : cfg.cameras) {
    const std::string& id = entry.first;
    bool found = false;
    for (const site::CeilingCamera& c : site.cameras) found = found || c.id == id;
    if (!found) {
      *error = "cameras." + id + ": no camera '" + id +
               "' in the site (its cameras: " + camera_ids(site) + ")";
      return false;
    }
  }
  return true;
}

int command_fail(const char* command, int code, const std::string& msg) {
  std::fprintf(stderr, "agvloc-overhead %s: %s\n", command, msg.c_str());
  return code;
}

bool load_config_and_site(const char* command, const std::string& config_path,
                          const std::string& site_path, OverheadConfig* cfg, site::Site* site) {
  std::vector<std::string> errors;
  bool ok = (config_path.empty() || load_config(config_path, cfg, &errors)) &&
            load_site_file(site_path, site, &errors);
  std::string err;
  if (ok && !check_config_against_site(*cfg, *site, &err)) {
    errors.push_back(config_path + ": " + err);
    ok = false;
  }
  if (!ok) {
    for (const std::string& e : errors) command_fail(command, 2, e);
  }
  return ok;
}

}  // namespace agv::overhead_app
