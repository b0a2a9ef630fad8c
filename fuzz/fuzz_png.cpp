// PNG frames (drivers/replay png_io), read as replay reads them. Properties: an accepted image is
// 8-bit grey with sides in 1..16384; with an expected size it is accepted only at exactly that
// size, and then gives the same pixels as without one; a rejected one says why. Small accepted
// images survive a write/read round trip exactly.
#include <sys/mman.h>
#include <unistd.h>

#include <string>

#include "agv/recording/png_io.hpp"
#include "fuzz_check.hpp"

namespace {

// The input as a file, without touching the disk.
std::string as_file(const unsigned char* data, std::size_t size, const char* name) {
  static int fd = -1;
  static std::string path;
  if (fd < 0) {
    fd = memfd_create(name, 0);
    FUZZ_CHECK(fd >= 0, "memfd_create");
    path = "/proc/self/fd/" + std::to_string(fd);
  }
  FUZZ_CHECK(ftruncate(fd, 0) == 0 && pwrite(fd, data, size, 0) == static_cast<ssize_t>(size),
             "write");
  return path;
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const unsigned char* data, std::size_t size) {
  const std::string path = as_file(data, size, "agv_fuzz_png");
  cv::Mat img;
  std::string error;
  const bool ok = agv::png::read_gray(path, &img, &error);
  if (!ok) {
    FUZZ_CHECK(!error.empty(), "a rejected PNG says why");
    return 0;
  }
  FUZZ_CHECK(img.type() == CV_8UC1 && img.cols >= 1 && img.rows >= 1 && img.cols <= 16384 &&
                 img.rows <= 16384,
             "image %dx%d type %d", img.cols, img.rows, img.type());
  cv::Mat same, other;
  FUZZ_CHECK(agv::png::read_gray(path, &same, &error, img.cols, img.rows), "%s", error.c_str());
  FUZZ_CHECK(cv::norm(img, same, cv::NORM_INF) == 0.0, "pixels differ with the size check");
  FUZZ_CHECK(!agv::png::read_gray(path, &other, &error, img.cols + 1, img.rows) && other.empty(),
             "wrong width accepted or decoded");
  if (img.total() <= 4096) {
    static int out_fd = memfd_create("agv_fuzz_png_out", 0);
    const std::string out = "/proc/self/fd/" + std::to_string(out_fd);
    FUZZ_CHECK(ftruncate(out_fd, 0) == 0, "truncate");
    FUZZ_CHECK(agv::png::write(out, img, &error, 1), "%s", error.c_str());
    cv::Mat back;
    FUZZ_CHECK(agv::png::read_gray(out, &back, &error), "%s", error.c_str());
    FUZZ_CHECK(cv::norm(img, back, cv::NORM_INF) == 0.0, "round trip");
  }
  return 0;
}
