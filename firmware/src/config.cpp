#include "config.hpp"

#include <cstdio>
#include <filesystem>

#include "agv/config/keys.hpp"
#include "agv/recording/recording.hpp"

namespace agv::config {

bool load_config(const std::string& path, Config* out, std::vector<std::string>* errors,
                 ConfigUse use) {
  std::string text, read_error;
  if (!recording::read_file_bounded(path, kMaxConfigBytes, &text, &read_error)) {
    errors->push_back(read_error);
    return false;
  }
  out->source = path;
  const std::string dir = std::filesystem::path(path).parent_path().string();
  if (!parse_config(text, dir, out, errors, use)) {
    for (auto& e : *errors) e = path + ": " + e;
    return false;
  }
  return true;
}

bool load_config_or_report(const std::string& path, const char* who, Config* out, ConfigUse use) {
  std::vector<std::string> errors;
  if (load_config(path, out, &errors, use)) return true;
  for (const auto& e : errors) std::fprintf(stderr, "%s: config: %s\n", who, e.c_str());
  return false;
}

bool load_map_file(const std::string& path, LandmarkMap* map, std::string* error) {
  std::string text, e;
  if (!recording::read_file_bounded(path, kMaxMapBytes, &text, &e)) {
    *error = e;
    return false;
  }
  if (!parse_landmark_map(text, map, &e)) {
    *error = path + ": " + e;
    return false;
  }
  return true;
}

bool check_can_localize(const Config& cfg, const LandmarkMap* map,
                        std::vector<std::string>* errors) {
  const size_t before = errors->size();
  if (cfg.vision.family == LandmarkFamily::kTag36h11) {
    if (!map || map->entries.empty()) {
      errors->push_back(
          "landmark.family tag36h11 needs landmark.map: a tag carries only its id, the pose "
          "comes from the map (without one every tag is \"not in the map\")");
    } else {
      std::string ids;
      int n = 0;
      for (const auto& [id, e] : map->entries) {
        if (id <= kTag36h11MaxId) continue;
        if (n++ < 5) ids += (ids.empty() ? "" : ", ") + std::to_string(id);
      }
      if (n > 0) {
        errors->push_back("landmark.map " + cfg.map_file + ": " + std::to_string(n) +
                          " id(s) above " + std::to_string(kTag36h11MaxId) + " (" + ids +
                          (n > 5 ? ", ..." : "") +
                          "), which tag36h11 does not have: those landmarks can never be seen");
      }
    }
  } else if (map && map->entries.count(0) > 0) {
    // The map format takes id 0 for the tag family's first tag; a QR payload's ids start at 1.
    errors->push_back("landmark.map " + cfg.map_file +
                      ": id 0, which no QR landmark carries (payload ids are 1..65535; id 0 is "
                      "for landmark.family tag36h11 only): that entry can never be seen");
  }
  return errors->size() == before;
}

namespace {

// A key's value as the YAML would write it, so the summary reads like the configuration.
std::string val(const Config& cfg, const char* name) {
  const Key* k = find_key(name);
  return k ? format_value(*k, k->get(cfg)) : std::string("?");
}

std::string hex_id(std::uint32_t id) {
  char b[16];
  std::snprintf(b, sizeof b, "0x%X", id);
  return b;
}

}  // namespace

std::string config_summary(const Config& cfg, const LandmarkMap* map) {
  const auto& cam = cfg.camera.camera;
  std::string s;
  s += "  camera: " + val(cfg, "camera.driver") + (cam.id.empty() ? "" : " id \"" + cam.id + "\"") +
       (cam.model.empty() ? "" : " model \"" + cam.model + "\"") + ", " +
       std::to_string(cam.width_px) + "x" + std::to_string(cam.height_px) + " px at " +
       val(cfg, "camera.fps") + " fps, exposure " + val(cfg, "camera.exposure_us") + " us\n";
  s += "  intrinsics: fx " + val(cfg, "intrinsics.fx") + ", fy " + val(cfg, "intrinsics.fy") +
       ", cx " + val(cfg, "intrinsics.cx") + ", cy " + val(cfg, "intrinsics.cy") + " px; k1 " +
       val(cfg, "intrinsics.k1") + ", k2 " + val(cfg, "intrinsics.k2") + ", p1 " +
       val(cfg, "intrinsics.p1") + ", p2 " + val(cfg, "intrinsics.p2") + ", k3 " +
       val(cfg, "intrinsics.k3") + "\n";
  s += "  mounting: offset_x_mm " + val(cfg, "mounting.offset_x_mm") + ", offset_y_mm " +
       val(cfg, "mounting.offset_y_mm") + ", yaw_deg " + val(cfg, "mounting.yaw_deg") +
       ", height_mm " + val(cfg, "mounting.height_mm") + ", roll_deg " +
       val(cfg, "mounting.roll_deg") + ", pitch_deg " + val(cfg, "mounting.pitch_deg") + "\n";
  s += "  landmark: family " + val(cfg, "landmark.family") + ", size_mm " +
       val(cfg, "landmark.size_mm") + "; ";
  if (map) {
    const auto& e = map->entries;
    s += "map " + cfg.map_file + ": " + std::to_string(e.size()) + " landmark" +
         (e.size() == 1 ? "" : "s") +
         (e.empty() ? ""
                    : " (ids " + std::to_string(e.begin()->first) + ".." +
                          std::to_string(e.rbegin()->first) + ")") +
         "\n";
  } else {
    s += "no map (poses from the printed codes)\n";
  }
  const protocol::ProtocolConfig pc = protocol_config(cfg);
  const bool wheels = cfg.can.odometry_mode == protocol::OdometryMode::kWheels;
  // 0 means the DBC's ID: base_id + 0x10 (wheels) / + 0x11 (v_omega).
  const std::uint32_t odom_id =
      cfg.can.odometry_id != 0 ? cfg.can.odometry_id : pc.base_id + (wheels ? 0x10u : 0x11u);
  s += "  CAN: " + cfg.can.interface + ", base_id " + hex_id(pc.base_id) +
       (cfg.can.extended_ids ? " (extended ids)" : " (standard ids)") + ", odometry " +
       val(cfg, "can.odometry.mode") + " on " + hex_id(odom_id) +
       (cfg.can.odometry_protected ? " (E2E protected)" : " (unprotected)") +
       (wheels ? ", track_width_mm " + val(cfg, "can.odometry.track_width_mm") : std::string()) +
       "\n";
  s += "  imu: source " + val(cfg, "imu.source");
  if (cfg.imu.source == ImuSource::kIio) {
    s += ", device " + cfg.imu.iio_device + " at " + val(cfg, "imu.iio_rate_hz") + " Hz";
  } else if (cfg.imu.source == ImuSource::kCan) {
    const std::uint32_t gyro_id = cfg.can.gyro_id != 0 ? cfg.can.gyro_id : pc.base_id + 0x12u;
    s += cfg.can.gyro_enabled ? ", AGV_Gyro on " + hex_id(gyro_id)
                              : " but can.gyro.enabled false: wheel odometry only";
  } else {
    s += ": wheel odometry only";
  }
  s += "\n";
  s += "  odometry: speed_scale " + val(cfg, "odometry.speed_scale") + ", yaw_rate_scale " +
       val(cfg, "odometry.yaw_rate_scale") + ", yaw_rate_bias_degps " +
       val(cfg, "odometry.yaw_rate_bias_degps") + ", yaw_per_metre_deg " +
       val(cfg, "odometry.yaw_per_metre_deg") + "; camera.time_offset_ms " +
       val(cfg, "camera.time_offset_ms") + "\n";
  s +=
      "  output: " + val(cfg, "loop.output_rate_hz") + " Hz; vda5050 " +
      (cfg.vda5050.enabled ? "on (" + cfg.vda5050.broker_host + ")" : std::string("off")) +
      "; diag " +
      (cfg.diag.enabled ? "on (" + cfg.diag.bind_address + ":" + std::to_string(cfg.diag.port) + ")"
                        : std::string("off")) +
      "\n";
  return s;
}

}  // namespace agv::config
