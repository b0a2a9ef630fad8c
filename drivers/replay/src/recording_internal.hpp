// Shared by the recording reader (recording.cpp: the whole recording; recording_files.cpp: bounded
// file access; recording_meta.cpp: meta.yaml; recording_csv.cpp: the CSV files) and the writers
// (recording_write.cpp).
#pragma once

#include <cstdint>
#include <filesystem>
#include <string>
#include <string_view>

namespace agv::recording {

// Per-file caps (docs/design/security.md): with them a hostile recording cannot make the reader
// hold more than a few hundred MB (the longest legitimate files, odom.csv and truth.csv at 100 Hz,
// are ~3 MB per hour; imu.csv at 200 Hz with only t_ns,gyro_z_radps ~20 MB per hour).
inline constexpr std::uintmax_t kMaxMetaBytes = 64u << 10;  // 64 KiB
// 8 MiB: ~250k frames, 2.3 h at 30 fps
inline constexpr std::uintmax_t kMaxFramesCsvBytes = 8u << 20;
// 32 MiB: ~10 h of 100 Hz odometry
inline constexpr std::uintmax_t kMaxTimedCsvBytes = 32u << 20;
inline constexpr std::uintmax_t kMaxPngBytes = 64u << 20;  // one frame

// A file name below the recording directory: relative, no "." or ".." component, no trailing
// "/", no control characters or '"'.
bool safe_relative_path(std::string_view f);

// Reads the whole file into *text, refusing one that is not a regular file or is larger than
// max_bytes; the message names the file by its file name.
bool read_text(const std::filesystem::path& path, std::uintmax_t max_bytes, std::string* text,
               std::string* error);

// Says why `p` cannot be a frame: not a readable regular file of at most kMaxPngBytes (with
// the system's reason, e.g. a symlink loop), or without the PNG signature.
bool check_png_file(const std::filesystem::path& p, std::string* why);

}  // namespace agv::recording
