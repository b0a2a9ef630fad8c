// Reading the desk tools' inputs (image folders, check frames) defensively: only regular files
// under a size cap (a FIFO or device would block or never end), PNGs refused by their header
// before any pixel is decoded (a small file can declare a 16384^2 image), and folder entries that
// are not regular files (symlink loops, sockets) skipped and counted instead of thrown on.
#pragma once

#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

namespace cv {
class Mat;
}

namespace agv::desk::input {

// A desk image above this is refused: 25 Mpx covers any machine-vision camera a floor
// localizer would use (640x480 and 1280x800 here), and bounds a decoded frame to 25 MB.
inline constexpr std::int64_t kMaxImagePixels = 25'000'000;
// A PNG file above this is refused before it is opened for decoding.
inline constexpr std::uintmax_t kMaxImageBytes = 64u << 20;

// True when path names a regular file (symlinks followed) of at most max_bytes; else false with
// *error naming the path and what it is (directory, FIFO, symlink loop, too large, missing).
bool regular_file(const std::string& path, std::uintmax_t max_bytes, std::string* error);

// Width and height from the PNG header (signature and IHDR); reads 24 bytes only.
bool png_size(const std::string& path, int* width_px, int* height_px, std::string* error);

// Reads a PNG as 8-bit gray after the checks above: a regular file of at most kMaxImageBytes
// whose header declares at most max_pixels; the header's size is then enforced while decoding.
bool read_gray(const std::string& path, cv::Mat* out, std::string* error,
               std::int64_t max_pixels = kMaxImagePixels);

// The *.png (any case) regular files of dir, sorted by name. Entries that are not regular files
// (or whose type cannot be read: a symlink loop) are skipped, one line each in *skipped.
// False with *error when dir cannot be listed.
bool list_pngs(const std::string& dir, std::vector<std::filesystem::path>* files,
               std::vector<std::string>* skipped, std::string* error);

}  // namespace agv::desk::input
