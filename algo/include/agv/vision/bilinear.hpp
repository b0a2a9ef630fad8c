// Bilinear grey-level samples of an 8-bit image at subpixel positions (pixel centres at integer
// coordinates): the logo and QR module samples, thousands per landmark frame.
#pragma once

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <opencv2/core.hpp>

namespace agv::vision {

// Bilinear sample of an 8-bit image; false outside.
inline bool sample(const cv::Mat& img, double x, double y, double* v) {
  if (!(x >= 0.0 && y >= 0.0 && x <= img.cols - 1.0 && y <= img.rows - 1.0)) return false;
  const int x0 = std::min(static_cast<int>(x), img.cols - 2 < 0 ? 0 : img.cols - 2);
  const int y0 = std::min(static_cast<int>(y), img.rows - 2 < 0 ? 0 : img.rows - 2);
  const double fx = x - x0, fy = y - y0;
  const std::uint8_t* r0 = img.ptr<std::uint8_t>(y0);
  const std::uint8_t* r1 = img.ptr<std::uint8_t>(std::min(y0 + 1, img.rows - 1));
  const int x1 = std::min(x0 + 1, img.cols - 1);
  *v = (1 - fy) * ((1 - fx) * r0[x0] + fx * r0[x1]) + fy * ((1 - fx) * r1[x0] + fx * r1[x1]);
  return true;
}

// sample() for many points of one image (logo and QR module samples): the image's geometry is
// read once, and on an image of at least 2 x 2 pixels the clamps of the second row and column
// fall away (the first ones are at most size - 2). The same arithmetic, so the same values to the
// last bit, with fewer instructions per sample.
class GreySampler {
 public:
  explicit GreySampler(const cv::Mat& img)
      : img_(img),
        data_(img.data),
        step_(static_cast<std::ptrdiff_t>(img.step[0])),
        x_max_(img.cols - 1.0),
        y_max_(img.rows - 1.0),
        x0_max_(img.cols - 2),
        y0_max_(img.rows - 2),
        fast_(img.cols >= 2 && img.rows >= 2) {}
  bool operator()(double x, double y, double* v) const {
    if (!fast_) return sample(img_, x, y, v);
    if (!(x >= 0.0 && y >= 0.0 && x <= x_max_ && y <= y_max_)) return false;
    const int x0 = std::min(static_cast<int>(x), x0_max_);
    const int y0 = std::min(static_cast<int>(y), y0_max_);
    const double fx = x - x0, fy = y - y0;
    const std::uint8_t* r0 = data_ + static_cast<std::ptrdiff_t>(y0) * step_;
    const std::uint8_t* r1 = r0 + step_;
    *v = (1 - fy) * ((1 - fx) * r0[x0] + fx * r0[x0 + 1]) +
         fy * ((1 - fx) * r1[x0] + fx * r1[x0 + 1]);
    return true;
  }

 private:
  const cv::Mat& img_;
  const std::uint8_t* data_;
  std::ptrdiff_t step_;
  double x_max_, y_max_;
  int x0_max_, y0_max_;
  bool fast_;
};

}  // namespace agv::vision
