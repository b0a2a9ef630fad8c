// 8-bit PNG reading and writing with libpng directly. OpenCV's imgcodecs would do, but Debian
// builds it against GDAL and a dozen image libraries: linking it loads ~140 shared libraries and
// ~25 MB of resident memory into the vehicle binary for the one format recordings use.
#pragma once

#include <opencv2/core.hpp>
#include <string>

namespace agv::png {

// Reads a PNG as 8-bit gray (CV_8UC1). Gray+alpha drops alpha; RGB(A) is converted with the
// ITU-R BT.601 luma weights; 16-bit is reduced to 8. False with *error on a missing, truncated or
// corrupt file (libpng errors are caught, never fatal; *error carries libpng's message). With
// expect_width/expect_height > 0 the header must declare exactly that size; it is checked before
// any pixel is decoded or allocated. Sides above 16384 are always rejected.
bool read_gray(const std::string& path, cv::Mat* out, std::string* error, int expect_width = 0,
               int expect_height = 0);

// Writes CV_8UC1 (gray) or CV_8UC3 (BGR, as OpenCV stores colour) as PNG. compression 0..9.
bool write(const std::string& path, const cv::Mat& image, std::string* error, int compression = 3);

}  // namespace agv::png
