#include "agv/recording/csv_stream.hpp"

#include <fcntl.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>

namespace agv::recording {

namespace {

// The single-row text of a whole-file formatter, without its header: one formatter per file,
// so the streamed rows cannot drift from what write_*_csv writes.
std::string without_header(const std::string& text) { return text.substr(text.find('\n') + 1); }

}  // namespace

bool format_frame_row(const FrameRow& row, std::string* text, std::string* error) {
  std::string s;
  if (!format_frames_csv({row}, &s, error)) return false;
  *text = without_header(s);
  return true;
}
std::string format_odom_row(const OdomRow& row) { return without_header(format_odom_csv({row})); }
std::string format_imu_row(const ImuRow& row) { return without_header(format_imu_csv({row})); }

std::string frames_csv_header() {
  std::string s;
  format_frames_csv({}, &s, nullptr);
  return s;
}
std::string odom_csv_header() { return format_odom_csv({}); }
std::string imu_csv_header() { return format_imu_csv({}); }

CsvStream::~CsvStream() { close(nullptr); }

bool CsvStream::open(const std::string& path, const std::string& header, std::string* error) {
  close(nullptr);
  path_ = path;
  fd_ = ::open(path.c_str(), O_WRONLY | O_CREAT | O_EXCL | O_CLOEXEC, 0644);
  if (fd_ < 0) {
    if (error) *error = path + ": cannot create: " + std::strerror(errno);
    return false;
  }
  size_bytes_ = 0;
  rows_written_ = rows_pending_ = rows_lost_ = 0;
  buffer_ = header;
  if (!flush(error)) {
    ::close(fd_);
    fd_ = -1;
    return false;
  }
  return true;
}

void CsvStream::add(const std::string& row) {
  buffer_ += row;
  ++rows_pending_;
}

bool CsvStream::flush(std::string* error) {
  if (buffer_.empty()) return true;
  if (fd_ < 0) {
    if (error) *error = path_ + ": not open";
    rows_lost_ += rows_pending_;
    rows_pending_ = 0;
    buffer_.clear();
    return false;
  }
  std::size_t done = 0;
  while (done < buffer_.size()) {
    const ssize_t n = ::write(fd_, buffer_.data() + done, buffer_.size() - done);
    if (n > 0) {
      done += static_cast<std::size_t>(n);
      continue;
    }
    if (n < 0 && errno == EINTR) continue;
    const int e = n < 0 ? errno : ENOSPC;
    // A partial row would make the reader reject the whole file ("truncated"); the rows before
    // it are whole, so cut back to them.
    if (done > 0 && ::ftruncate(fd_, static_cast<off_t>(size_bytes_)) == 0) {
      ::lseek(fd_, static_cast<off_t>(size_bytes_), SEEK_SET);
    }
    if (error) *error = path_ + ": write failed: " + std::strerror(e);
    rows_lost_ += rows_pending_;
    rows_pending_ = 0;
    buffer_.clear();
    return false;
  }
  size_bytes_ += buffer_.size();
  rows_written_ += rows_pending_;
  rows_pending_ = 0;
  buffer_.clear();
  return true;
}

bool CsvStream::sync(std::string* error) {
  if (fd_ < 0) return true;
  if (::fdatasync(fd_) != 0) {
    if (error) *error = path_ + ": fdatasync failed: " + std::strerror(errno);
    return false;
  }
  return true;
}

bool CsvStream::close(std::string* error) {
  if (fd_ < 0) return true;
  bool ok = flush(error);
  ok = sync(ok ? error : nullptr) && ok;
  if (::close(fd_) != 0 && ok) {
    if (error) *error = path_ + ": close failed: " + std::strerror(errno);
    ok = false;
  }
  fd_ = -1;
  return ok;
}

}  // namespace agv::recording
