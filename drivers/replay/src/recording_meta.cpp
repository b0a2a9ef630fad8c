// meta.yaml of a recording (docs/guide/recording.md): every key checked, range-checked and named
// in the error with its line.
#include <yaml-cpp/yaml.h>

#include <cmath>
#include <cstdio>
#include <set>

#include "agv/common/geometry.hpp"
#include "agv/common/landmark.hpp"
#include "agv/recording/recording.hpp"
#include "recording_internal.hpp"

namespace agv::recording {

namespace fs = std::filesystem;

namespace {

struct MetaParser {
  const std::string& name;
  std::string* error;

  bool fail(const YAML::Node& n, const std::string& why) {
    const int line = n.Mark().is_null() ? 0 : n.Mark().line + 1;
    if (error) *error = name + ":" + std::to_string(line) + ": " + why;
    return false;
  }

  // The mapping must have exactly these keys (all required).
  bool keys(const YAML::Node& map, const std::string& where, const std::set<std::string>& required,
            const std::set<std::string>& optional = {}) {
    if (!map.IsMap()) return fail(map, where + " must be a mapping");
    std::set<std::string> seen;
    for (const auto& kv : map) {
      std::string k;
      try {
        k = kv.first.as<std::string>();
      } catch (const YAML::Exception&) {
        return fail(kv.first, where + ": keys must be plain strings");
      }
      if (!required.count(k) && !optional.count(k)) {
        return fail(kv.first, "unknown key '" + (where.empty() ? k : where + "." + k) + "'");
      }
      if (!seen.insert(k).second) return fail(kv.first, "duplicate key '" + k + "'");
    }
    for (const auto& k : required) {
      if (!seen.count(k)) {
        return fail(map, "missing key '" + (where.empty() ? k : where + "." + k) + "'");
      }
    }
    return true;
  }

  bool number(const YAML::Node& map, const std::string& where, const std::string& key, double lo,
              double hi, double* out) {
    const YAML::Node n = map[key];
    const std::string full = where.empty() ? key : where + "." + key;
    if (!n.IsScalar()) return fail(n, "'" + full + "' must be a number");
    double v = 0.0;
    if (!YAML::convert<double>::decode(n, v) || !std::isfinite(v)) {
      return fail(n, "'" + full + "' must be a finite number, got '" + n.Scalar() + "'");
    }
    if (v < lo || v > hi) {
      char buf[160];
      std::snprintf(buf, sizeof buf, "'%s' = %g is outside [%g, %g]", full.c_str(), v, lo, hi);
      return fail(n, buf);
    }
    *out = v;
    return true;
  }

  bool integer(const YAML::Node& map, const std::string& where, const std::string& key, int lo,
               int hi, int* out) {
    const YAML::Node n = map[key];
    const std::string full = where.empty() ? key : where + "." + key;
    int v = 0;
    if (!n.IsScalar() || !YAML::convert<int>::decode(n, v)) {
      return fail(n, "'" + full + "' must be an integer");
    }
    if (v < lo || v > hi) {
      return fail(n, "'" + full + "' = " + std::to_string(v) + " is outside [" +
                         std::to_string(lo) + ", " + std::to_string(hi) + "]");
    }
    *out = v;
    return true;
  }
};

}  // namespace

bool parse_meta_yaml(const std::string& text, Meta* out, std::string* error,
                     const std::string& name) {
  YAML::Node root;
  try {
    root = YAML::Load(text);
  } catch (const YAML::ParserException& e) {
    if (error) *error = name + ":" + std::to_string(e.mark.line + 1) + ": YAML syntax: " + e.msg;
    return false;
  } catch (const std::exception& e) {
    if (error) *error = name + ":0: " + e.what();
    return false;
  }
  MetaParser p{name, error};
  try {
    if (!root.IsMap()) return p.fail(root, "top level must be a mapping");
    if (!p.keys(root, "",
                {"format_version", "image", "intrinsics", "distortion", "mount", "landmark"},
                {"source"})) {
      return false;
    }
    Meta m;
    if (!p.integer(root, "", "format_version", 1, 1000000, &m.format_version)) return false;
    if (m.format_version != kFormatVersion) {
      return p.fail(root["format_version"],
                    "unsupported format_version " + std::to_string(m.format_version) +
                        " (this build reads " + std::to_string(kFormatVersion) + ")");
    }
    const YAML::Node img = root["image"], in = root["intrinsics"], di = root["distortion"],
                     mo = root["mount"], lm = root["landmark"];
    auto& k = m.camera.intrinsics;
    auto& mt = m.camera.mount;
    if (!p.keys(img, "image", {"width_px", "height_px"}) ||
        !p.integer(img, "image", "width_px", 1, 16384, &k.width_px) ||
        !p.integer(img, "image", "height_px", 1, 16384, &k.height_px)) {
      return false;
    }
    if (!p.keys(in, "intrinsics", {"fx", "fy", "cx", "cy"}) ||
        !p.number(in, "intrinsics", "fx", 1.0, 1e6, &k.fx) ||
        !p.number(in, "intrinsics", "fy", 1.0, 1e6, &k.fy) ||
        !p.number(in, "intrinsics", "cx", -k.width_px, 2.0 * k.width_px, &k.cx) ||
        !p.number(in, "intrinsics", "cy", -k.height_px, 2.0 * k.height_px, &k.cy)) {
      return false;
    }
    if (!p.keys(di, "distortion", {"k1", "k2", "p1", "p2", "k3"}) ||
        !p.number(di, "distortion", "k1", -100, 100, &k.k1) ||
        !p.number(di, "distortion", "k2", -100, 100, &k.k2) ||
        !p.number(di, "distortion", "p1", -1, 1, &k.p1) ||
        !p.number(di, "distortion", "p2", -1, 1, &k.p2) ||
        !p.number(di, "distortion", "k3", -100, 100, &k.k3)) {
      return false;
    }
    double yaw_deg = 0.0, roll_deg = 0.0, pitch_deg = 0.0;
    if (!p.keys(mo, "mount", {"height_mm", "offset_x_mm", "offset_y_mm", "yaw_deg"},
                {"roll_deg", "pitch_deg"}) ||
        !p.number(mo, "mount", "height_mm", 1.0, 10000.0, &mt.height_mm) ||
        !p.number(mo, "mount", "offset_x_mm", -10000.0, 10000.0, &mt.offset_x_mm) ||
        !p.number(mo, "mount", "offset_y_mm", -10000.0, 10000.0, &mt.offset_y_mm) ||
        !p.number(mo, "mount", "yaw_deg", -180.0, 180.0, &yaw_deg)) {
      return false;
    }
    if (yaw_deg == -180.0) return p.fail(mo["yaw_deg"], "'mount.yaw_deg' must be in (-180, 180]");
    mt.yaw_rad = deg_to_rad(yaw_deg);
    if ((mo["roll_deg"] && !p.number(mo, "mount", "roll_deg", -45.0, 45.0, &roll_deg)) ||
        (mo["pitch_deg"] && !p.number(mo, "mount", "pitch_deg", -45.0, 45.0, &pitch_deg))) {
      return false;
    }
    mt.roll_rad = deg_to_rad(roll_deg);
    mt.pitch_rad = deg_to_rad(pitch_deg);
    if (!p.keys(lm, "landmark", {"size_mm"}, {"family"}) ||
        !p.number(lm, "landmark", "size_mm", 1.0, 1000.0, &m.landmark_size_mm)) {
      return false;
    }
    if (lm["family"]) {
      const YAML::Node f = lm["family"];
      LandmarkFamily family;
      if (!f.IsScalar() || !parse_landmark_family(f.Scalar(), &family)) {
        return p.fail(f, "'landmark.family' must be qr or tag36h11");
      }
      m.landmark_family = f.Scalar();
    }
    if (root["source"]) {
      if (!root["source"].IsScalar()) return p.fail(root["source"], "'source' must be a string");
      m.source = root["source"].Scalar();
    }
    *out = std::move(m);
    return true;
  } catch (const YAML::Exception& e) {
    if (error) *error = name + ":" + std::to_string(e.mark.line + 1) + ": " + e.msg;
    return false;
  }
}

bool read_meta(const std::string& dir, Meta* out, std::string* error) {
  std::string text, err;
  if (!read_text(fs::path(dir) / "meta.yaml", kMaxMetaBytes, &text, &err)) {
    if (error) *error = err;
    return false;
  }
  return parse_meta_yaml(text, out, error);
}

}  // namespace agv::recording
