#include "desk_input.hpp"

#include <algorithm>
#include <array>
#include <cctype>
#include <fstream>

#include "agv/config/keys.hpp"
#include "agv/recording/png_io.hpp"

namespace agv::desk::input {

namespace fs = std::filesystem;

namespace {

const char* type_name(fs::file_type t) {
  switch (t) {
    case fs::file_type::directory:
      return "a directory";
    case fs::file_type::fifo:
      return "a FIFO";
    case fs::file_type::socket:
      return "a socket";
    case fs::file_type::block:
    case fs::file_type::character:
      return "a device";
    case fs::file_type::not_found:
      return "not found";
    default:
      return "not a regular file";
  }
}

std::uint32_t be32(const unsigned char* p) {
  return (std::uint32_t{p[0]} << 24) | (std::uint32_t{p[1]} << 16) | (std::uint32_t{p[2]} << 8) |
         std::uint32_t{p[3]};
}

}  // namespace

bool regular_file(const std::string& path, std::uintmax_t max_bytes, std::string* error) {
  std::error_code ec;
  const fs::file_status st = fs::status(path, ec);
  if (ec && st.type() != fs::file_type::not_found) {
    *error = path + ": " + ec.message();
    return false;
  }
  if (st.type() != fs::file_type::regular) {
    *error = path + ": " + type_name(st.type()) + " (a regular file is needed)";
    return false;
  }
  const std::uintmax_t size = fs::file_size(path, ec);
  if (ec) {
    *error = path + ": " + ec.message();
    return false;
  }
  if (size > max_bytes) {
    *error = path + ": " + std::to_string(size) + " bytes, more than the " +
             std::to_string(max_bytes) + " accepted";
    return false;
  }
  return true;
}

bool png_size(const std::string& path, int* width_px, int* height_px, std::string* error) {
  std::ifstream f(path, std::ios::binary);
  std::array<unsigned char, 24> h{};
  if (!f.read(reinterpret_cast<char*>(h.data()), static_cast<std::streamsize>(h.size()))) {
    *error = path + ": too short for a PNG header";
    return false;
  }
  static const unsigned char kSig[8] = {0x89, 'P', 'N', 'G', '\r', '\n', 0x1a, '\n'};
  if (!std::equal(kSig, kSig + 8, h.begin()) ||
      !std::equal(h.begin() + 12, h.begin() + 16, reinterpret_cast<const unsigned char*>("IHDR"))) {
    *error = path + ": not a PNG file (no PNG signature and IHDR header)";
    return false;
  }
  const std::uint32_t w = be32(&h[16]), hh = be32(&h[20]);
  if (w == 0 || hh == 0 || w > 0x7fffffffu || hh > 0x7fffffffu) {
    *error =
        path + ": PNG header declares a " + std::to_string(w) + "x" + std::to_string(hh) + " image";
    return false;
  }
  *width_px = static_cast<int>(w);
  *height_px = static_cast<int>(hh);
  return true;
}

bool read_gray(const std::string& path, cv::Mat* out, std::string* error, std::int64_t max_pixels) {
  if (!regular_file(path, kMaxImageBytes, error)) return false;
  int w = 0, h = 0;
  if (!png_size(path, &w, &h, error)) return false;
  // No camera the configuration accepts (camera.width/height, keys.hpp) is larger.
  const config::Key* kw = config::find_key("camera.width");
  const config::Key* kh = config::find_key("camera.height");
  if (w > kw->hi || h > kh->hi) {
    *error = path + ": " + std::to_string(w) + "x" + std::to_string(h) +
             " pixels, larger than any camera the configuration accepts (camera.width " +
             config::format_range(*kw) + ", camera.height " + config::format_range(*kh) +
             "); not decoded";
    return false;
  }
  if (static_cast<std::int64_t>(w) * h > max_pixels) {
    *error = path + ": " + std::to_string(w) + "x" + std::to_string(h) + " pixels, more than the " +
             std::to_string(max_pixels) + " accepted (not decoded; is this a camera frame?)";
    return false;
  }
  // The expected size makes the decoder refuse a file whose header changed since png_size.
  return png::read_gray(path, out, error, w, h);
}

bool list_pngs(const std::string& dir, std::vector<fs::path>* files,
               std::vector<std::string>* skipped, std::string* error) {
  std::error_code ec;
  fs::directory_iterator it(dir, ec), end;
  if (ec) {
    *error = dir + ": " + ec.message();
    return false;
  }
  for (; it != end; it.increment(ec)) {
    if (ec) {
      *error = dir + ": " + ec.message();
      return false;
    }
    const fs::path& p = it->path();
    std::string ext = p.extension().string();
    std::transform(ext.begin(), ext.end(), ext.begin(),
                   [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
    if (ext != ".png") continue;
    std::error_code sec;
    const fs::file_status st = fs::status(p, sec);
    if (sec && st.type() != fs::file_type::not_found) {
      skipped->push_back(p.filename().string() + ": " + sec.message());
    } else if (st.type() != fs::file_type::regular) {
      skipped->push_back(p.filename().string() + ": " + type_name(st.type()));
    } else {
      files->push_back(p);
    }
  }
  std::sort(files->begin(), files->end());
  std::sort(skipped->begin(), skipped->end());
  return true;
}

}  // namespace agv::desk::input
