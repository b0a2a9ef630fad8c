// Recording format writers (docs/guide/recording.md): meta.yaml, the CSV files and frame PNGs, as
// the simulator and `agvloc record` write them. The strict readers: recording.cpp and
// the files it names.
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <sstream>

#include "agv/recording/png_io.hpp"
#include "agv/recording/recording.hpp"
#include "recording_internal.hpp"

namespace agv::recording {

namespace fs = std::filesystem;

namespace {

bool write_text(const fs::path& path, const std::string& text, std::string* error) {
  std::error_code ec;
  fs::create_directories(path.parent_path(), ec);
  std::ofstream f(path, std::ios::binary | std::ios::trunc);
  if (f) f << text;
  if (!f) {
    if (error) *error = path.string() + ": cannot write";
    return false;
  }
  return true;
}

std::string fmt_g17(double v) {
  char buf[40];
  std::snprintf(buf, sizeof buf, "%.17g", v);
  return buf;
}

}  // namespace

std::string format_meta_yaml(const Meta& m) {
  const auto& k = m.camera.intrinsics;
  const auto& mt = m.camera.mount;
  std::ostringstream os;
  os << "# agvloc recording metadata, docs/guide/recording.md\n"
     << "format_version: " << m.format_version << "\n";
  if (!m.source.empty()) {
    // Double-quoted YAML scalar with escapes, so any text round-trips.
    std::string q;
    for (char c : m.source) {
      if (c == '"' || c == '\\') q += '\\';
      if (c == '\n') {
        q += "\\n";
        continue;
      }
      q += c;
    }
    os << "source: \"" << q << "\"\n";
  }
  os << "image:\n  width_px: " << k.width_px << "\n  height_px: " << k.height_px << "\n"
     << "intrinsics:\n  fx: " << fmt_g17(k.fx) << "\n  fy: " << fmt_g17(k.fy)
     << "\n  cx: " << fmt_g17(k.cx) << "\n  cy: " << fmt_g17(k.cy) << "\n"
     << "distortion:\n  k1: " << fmt_g17(k.k1) << "\n  k2: " << fmt_g17(k.k2)
     << "\n  p1: " << fmt_g17(k.p1) << "\n  p2: " << fmt_g17(k.p2) << "\n  k3: " << fmt_g17(k.k3)
     << "\n"
     << "mount:\n  height_mm: " << fmt_g17(mt.height_mm)
     << "\n  offset_x_mm: " << fmt_g17(mt.offset_x_mm)
     << "\n  offset_y_mm: " << fmt_g17(mt.offset_y_mm)
     << "\n  yaw_deg: " << fmt_g17(rad_to_deg(wrap_angle_rad(mt.yaw_rad))) << "\n";
  // Tilt only when there is one: untilted recordings stay byte-identical to older ones.
  if (mt.tilted()) {
    os << "  roll_deg: " << fmt_g17(rad_to_deg(mt.roll_rad))
       << "\n  pitch_deg: " << fmt_g17(rad_to_deg(mt.pitch_rad)) << "\n";
  }
  os << "landmark:\n  size_mm: " << fmt_g17(m.landmark_size_mm) << "\n";
  if (!m.landmark_family.empty()) os << "  family: " << m.landmark_family << "\n";
  return os.str();
}

bool write_meta(const std::string& dir, const Meta& m, std::string* error) {
  const std::string text = format_meta_yaml(m);
  // Refuse to write what the reader would reject.
  Meta check;
  std::string err;
  if (!parse_meta_yaml(text, &check, &err)) {
    if (error) *error = "refusing to write invalid meta: " + err;
    return false;
  }
  return write_text(fs::path(dir) / "meta.yaml", text, error);
}

bool format_frames_csv(const std::vector<FrameRow>& rows, std::string* text, std::string* error) {
  std::string s = "t_ns,file\n";
  for (const FrameRow& r : rows) {
    if (!safe_relative_path(r.file) || r.file.find(',') != std::string::npos) {
      if (error) *error = "frames.csv: file name '" + r.file + "' cannot be written";
      return false;
    }
    s += std::to_string(r.t_ns) + "," + r.file + "\n";
  }
  *text = std::move(s);
  return true;
}

bool write_frames_csv(const std::string& dir, const std::vector<FrameRow>& rows,
                      std::string* error) {
  std::string s;
  return format_frames_csv(rows, &s, error) && write_text(fs::path(dir) / "frames.csv", s, error);
}

std::string format_odom_csv(const std::vector<OdomRow>& rows) {
  std::string s = "t_ns,v_mps,omega_radps\n";
  char buf[96];
  for (const OdomRow& r : rows) {
    std::snprintf(buf, sizeof buf, "%lld,%.9g,%.9g\n", static_cast<long long>(r.t_ns), r.v_mps,
                  r.omega_radps);
    s += buf;
  }
  return s;
}

bool write_odom_csv(const std::string& dir, const std::vector<OdomRow>& rows, std::string* error) {
  return write_text(fs::path(dir) / "odom.csv", format_odom_csv(rows), error);
}

std::string format_truth_csv(const std::vector<TruthRow>& rows) {
  std::string s = "t_ns,x_mm,y_mm,theta_deg\n";
  char buf[128];
  for (const TruthRow& r : rows) {
    // Round first, then wrap, so -179.9999999 never prints as the out-of-range -180.000000.
    double th = std::round(wrap_angle_deg(r.theta_deg) * 1e6) / 1e6;
    if (th <= -180.0) th += 360.0;
    std::snprintf(buf, sizeof buf, "%lld,%.4f,%.4f,%.6f\n", static_cast<long long>(r.t_ns), r.x_mm,
                  r.y_mm, th);
    s += buf;
  }
  return s;
}

bool write_truth_csv(const std::string& dir, const std::vector<TruthRow>& rows,
                     std::string* error) {
  return write_text(fs::path(dir) / "truth.csv", format_truth_csv(rows), error);
}

std::string format_imu_csv(const std::vector<ImuRow>& rows) {
  std::string s = "t_ns,gyro_z_radps\n";
  char buf[64];
  for (const ImuRow& r : rows) {
    // 9 significant digits: 1e-9 of the rate, far below any gyro's noise.
    std::snprintf(buf, sizeof buf, "%lld,%.9g\n", static_cast<long long>(r.t_ns), r.gyro_z_radps);
    s += buf;
  }
  return s;
}

bool write_imu_csv(const std::string& dir, const std::vector<ImuRow>& rows, std::string* error) {
  return write_text(fs::path(dir) / "imu.csv", format_imu_csv(rows), error);
}

bool write_frame_png(const std::string& dir, const std::string& relative_file, const cv::Mat& image,
                     std::string* error) {
  if (image.empty() || image.type() != CV_8UC1 || !safe_relative_path(relative_file)) {
    if (error) *error = relative_file + ": need an 8-bit grey image and a relative path";
    return false;
  }
  const fs::path p = fs::path(dir) / relative_file;
  std::error_code ec;
  fs::create_directories(p.parent_path(), ec);
  // Fast zlib level: frames are written at 30 fps by the simulator and the recorder.
  std::string e;
  const bool ok = png::write(p.string(), image, &e, 1);
  if (!ok && error) *error = e;
  return ok;
}

}  // namespace agv::recording
