// Bounded file access for the recording reader: files that are not regular files or exceed their
// cap are refused by name before anything is read (docs/design/security.md).
#include <fstream>

#include "agv/recording/recording.hpp"
#include "recording_internal.hpp"

namespace agv::recording {

namespace fs = std::filesystem;

namespace {

// False with *why ("missing", "cannot be read (Too many levels of symbolic links)", "not a
// regular file", "larger than N bytes") unless `p` is a regular file of at most max_bytes.
bool check_regular_file(const fs::path& p, std::uintmax_t max_bytes, std::uintmax_t* size,
                        std::string* why) {
  std::error_code ec;
  const fs::file_status st = fs::status(p, ec);
  if (ec && ec != std::errc::no_such_file_or_directory) {
    *why = "cannot be read (" + ec.message() + ")";
    return false;
  }
  if (!fs::exists(st)) {
    *why = "missing";
    return false;
  }
  if (!fs::is_regular_file(st)) {
    *why = "not a regular file";
    return false;
  }
  *size = fs::file_size(p, ec);
  if (ec) {
    *why = "cannot be read (" + ec.message() + ")";
    return false;
  }
  if (*size > max_bytes) {
    *why = "larger than " + std::to_string(max_bytes) + " bytes";
    return false;
  }
  return true;
}

// `who` names the file in messages: the recording's files by name, others by path.
bool read_bounded(const fs::path& path, std::uintmax_t max_bytes, const std::string& who,
                  std::string* text, std::string* error) {
  std::uintmax_t size = 0;
  std::string why;
  if (!check_regular_file(path, max_bytes, &size, &why)) {
    if (why == "missing") {
      why = who == path.string() ? "cannot open (no such file)"
                                 : "missing (expected at " + path.string() + ")";
    }
    *error = who + ": " + why;
    return false;
  }
  std::ifstream f(path, std::ios::binary);
  if (!f) {
    *error = who + ": cannot open";
    return false;
  }
  // Never more than the cap, even if the file grows while it is read.
  text->assign(static_cast<size_t>(size) + 1, '\0');
  f.read(text->data(), static_cast<std::streamsize>(text->size()));
  const auto got = static_cast<std::uintmax_t>(f.gcount());
  if (got > max_bytes) {
    *error = who + ": larger than " + std::to_string(max_bytes) + " bytes";
    return false;
  }
  text->resize(static_cast<size_t>(got));
  return true;
}

}  // namespace

bool read_text(const fs::path& path, std::uintmax_t max_bytes, std::string* text,
               std::string* error) {
  return read_bounded(path, max_bytes, path.filename().string(), text, error);
}

// Says why `p` cannot be a frame: not a readable regular file of at most kMaxPngBytes (with
// the system's reason, e.g. a symlink loop), or without the PNG signature.
bool check_png_file(const fs::path& p, std::string* why) {
  std::uintmax_t size = 0;
  if (!check_regular_file(p, kMaxPngBytes, &size, why)) return false;
  std::ifstream in(p, std::ios::binary);
  if (!in.is_open()) {
    *why = "cannot be opened";
    return false;
  }
  unsigned char sig[8] = {0};
  in.read(reinterpret_cast<char*>(sig), 8);
  static constexpr unsigned char kPng[8] = {0x89, 'P', 'N', 'G', 0x0d, 0x0a, 0x1a, 0x0a};
  if (in.gcount() != 8 || !std::equal(sig, sig + 8, kPng)) {
    *why = "not a PNG file";
    return false;
  }
  return true;
}

bool safe_relative_path(std::string_view f) {
  if (f.empty() || f.front() == '/' || f.find('\\') != std::string_view::npos) return false;
  for (char c : f) {
    if (static_cast<unsigned char>(c) < 0x20 || c == '"') return false;
  }
  // A file below the directory: no "..", and no "." or trailing "/" that names a directory
  // ("." alone is the recording directory itself; found by fuzz_recording_frames).
  if (f.back() == '/') return false;
  const fs::path p{std::string(f)};
  for (const auto& part : p) {
    if (part == ".." || part == ".") return false;
  }
  return true;
}

bool read_file_bounded(const std::string& path, std::uintmax_t max_bytes, std::string* text,
                       std::string* error) {
  return read_bounded(fs::path(path), max_bytes, path, text, error);
}

}  // namespace agv::recording
