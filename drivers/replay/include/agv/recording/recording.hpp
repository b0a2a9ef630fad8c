// The recording format (docs/guide/recording.md): a directory with meta.yaml, frames.csv + PNGs,
// odom.csv and the optional truth.csv and imu.csv. Used by replay, the simulator and the live
// recorder.
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

#include "agv/common/camera_model.hpp"

namespace cv {
class Mat;
}

namespace agv::recording {

inline constexpr int kFormatVersion = 1;
// Largest accepted t_ns (2^62 ns, 146 years): sums of a time and a period or delay never overflow.
inline constexpr std::int64_t kMaxTimeNs = std::int64_t{1} << 62;
// Most frames a recording may have (2.3 h at 30 fps): replay keeps one 408-byte fix record each.
inline constexpr int kMaxFrames = 250'000;

struct Meta {
  int format_version = kFormatVersion;
  CameraModel camera;              // image size, intrinsics, distortion, height, mounting
  double landmark_size_mm = 60.0;  // outer border side
  // The printed landmark family, as landmark.family names it ("qr" or "tag36h11"); empty in a
  // recording made before the key existed (replay then takes the configuration's, by default qr).
  std::string landmark_family;
  std::string source;  // optional free text (e.g. the command that made it)
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

// One gyro sample of imu.csv (further columns of the file are checked, then dropped).
struct ImuRow {
  std::int64_t t_ns = 0;      // the gyro's own stamp (its latency / clock offset included)
  double gyro_z_radps = 0.0;  // yaw rate about the vehicle's z axis, counter-clockwise positive
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
  std::vector<ImuRow> imu;  // empty when imu.csv is absent (no gyro: wheel odometry only)
  bool has_imu = false;
  // What read_recording accepted with a loss, one line each ("odom.csv:1234: last line cut ...").
  std::vector<std::string> warnings;
};

// Reads meta.yaml, frames.csv, odom.csv, truth.csv and imu.csv (the last two if present). Images
// are not loaded. On malformed input returns false with *error naming the file and line
// ("frames.csv:12: ..."). Timestamps must be strictly increasing within each file; referenced PNGs
// must exist. A CSV's last line without its newline (a recording cut by a power loss) is dropped
// and named in out->warnings; every other defect is an error.
bool read_recording(const std::string& dir, Recording* out, std::string* error);

// Parts of read_recording, usable on their own. `name` is the file name used in messages.
bool parse_meta_yaml(const std::string& text, Meta* out, std::string* error,
                     const std::string& name = "meta.yaml");
bool read_meta(const std::string& dir, Meta* out, std::string* error);
bool parse_frames_csv(const std::string& text, std::vector<FrameRow>* out, std::string* error,
                      const std::string& name = "frames.csv");
bool parse_odom_csv(const std::string& text, std::vector<OdomRow>* out, std::string* error,
                    const std::string& name = "odom.csv");
bool parse_truth_csv(const std::string& text, std::vector<TruthRow>* out, std::string* error,
                     const std::string& name = "truth.csv");
// imu.csv: the header starts with t_ns,gyro_z_radps; further columns (gyro_x_radps, accel_*,
// ...) are allowed when the header names them, their values must be finite and are dropped.
bool parse_imu_csv(const std::string& text, std::vector<ImuRow>* out, std::string* error,
                   const std::string& name = "imu.csv");

// Loads frame i as 8-bit grey. False with *error when the file is missing or unreadable (with
// the reason), not decodable (with libpng's message), or not of the size in meta.yaml (checked on
// the PNG header before anything is decoded).
bool load_frame(const Recording& rec, size_t i, cv::Mat* image, std::string* error);

// Reads a whole file that must be a regular file of at most max_bytes (not a device, FIFO or
// directory). False with *error naming the path and the reason.
bool read_file_bounded(const std::string& path, std::uintmax_t max_bytes, std::string* text,
                       std::string* error);

// Replay simulates every output period between the first and last time of frames.csv and
// odom.csv. False with *error naming those rows when that is max_ticks periods or more.
bool check_replay_span(const Recording& rec, std::int64_t period_ns, std::int64_t max_ticks,
                       std::string* error);

// The text the writers below write (docs/guide/recording.md). Meta and frames round-trip exactly;
// odom.csv and imu.csv keep 9 significant digits, truth.csv 0.1 um and 1e-6 degrees.
std::string format_meta_yaml(const Meta& meta);
bool format_frames_csv(const std::vector<FrameRow>& rows, std::string* text, std::string* error);
std::string format_odom_csv(const std::vector<OdomRow>& rows);
std::string format_truth_csv(const std::vector<TruthRow>& rows);
std::string format_imu_csv(const std::vector<ImuRow>& rows);  // t_ns,gyro_z_radps only

// Writers create the directory if needed and overwrite the files.
bool write_meta(const std::string& dir, const Meta& meta, std::string* error);
bool write_frames_csv(const std::string& dir, const std::vector<FrameRow>& rows,
                      std::string* error);
bool write_odom_csv(const std::string& dir, const std::vector<OdomRow>& rows, std::string* error);
bool write_truth_csv(const std::string& dir, const std::vector<TruthRow>& rows, std::string* error);
bool write_imu_csv(const std::string& dir, const std::vector<ImuRow>& rows, std::string* error);
// Writes an 8-bit grey image as PNG at dir/relative_file (creating sub-directories).
bool write_frame_png(const std::string& dir, const std::string& relative_file, const cv::Mat& image,
                     std::string* error);

}  // namespace agv::recording
