// The recording format (docs/recording.md): a directory with meta.yaml, frames.csv + PNGs,
// odom.csv and an optional truth.csv. Used by replay, the simulator and the live recorder.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "agv/common/camera_model.hpp"

namespace agv::recording {

inline constexpr int kFormatVersion = 1;

struct Meta {
  int format_version = kFormatVersion;
  CameraModel camera;              // image size, intrinsics, distortion, height, mounting
  double landmark_size_mm = 60.0;  // outer border side
};

struct FrameRow {
  std::int64_t t_ns = 0;  // exposure mid-time, monotonic clock
  std::string file;       // PNG path relative to the recording directory
};

struct OdomRow {
  std::int64_t t_ns = 0;
  double v_mps = 0.0;        // body-frame forward speed
  double omega_radps = 0.0;  // yaw rate, counter-clockwise positive
};

struct TruthRow {
  std::int64_t t_ns = 0;
  double x_mm = 0.0;  // world pose of the vehicle reference point
  double y_mm = 0.0;
  double theta_deg = 0.0;
};

struct Recording {
  std::string dir;
  Meta meta;
  std::vector<FrameRow> frames;
  std::vector<OdomRow> odom;
  std::vector<TruthRow> truth;  // empty when truth.csv is absent
  bool has_truth = false;
};

// Reads meta.yaml, frames.csv, odom.csv and truth.csv (if present). Images are not loaded.
// On malformed input returns false with *error naming the file and line ("frames.csv:12: ...").
// Timestamps must be strictly increasing within each file; referenced PNGs must exist.
bool read_recording(const std::string& dir, Recording* out, std::string* error);

// Writers create the directory if needed and overwrite the files.
bool write_meta(const std::string& dir, const Meta& meta, std::string* error);
bool write_frames_csv(const std::string& dir, const std::vector<FrameRow>& rows, std::string* error);
bool write_odom_csv(const std::string& dir, const std::vector<OdomRow>& rows, std::string* error);
bool write_truth_csv(const std::string& dir, const std::vector<TruthRow>& rows, std::string* error);

}  // namespace agv::recording
