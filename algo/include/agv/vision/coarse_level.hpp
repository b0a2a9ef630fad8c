// Image operations of the detection stage's coarse level (detect.cpp), own loops instead of the
// OpenCV calls they replace because those dominated a landmark-free frame on aarch64; each is
// tested against its reference (tests/vision/test_coarse_level.cpp, also under qemu-aarch64).
//
// Box downsampling of an 8-bit image by an integer factor: each output pixel is the rounded mean of
// an f x f block, what cv::resize with INTER_AREA computes for an integer factor. Two
// implementations that must agree bit for bit: the scalar reference and the vector path, which the
// detection uses for f = 2, 4, 8 and 16 (NEON pairwise adds on aarch64, GCC/Clang vector
// extensions elsewhere; tests/vision compares them, also under qemu-aarch64).
#pragma once

#include <cstdint>
#include <opencv2/core/mat.hpp>
#include <vector>

namespace agv::vision {

// out (CV_8UC1, size cs) = mean of each f x f block of img (CV_8UC1, at least cs * f), rounded
// half up. row_sums is scratch.
void box_downsample_scalar(const cv::Mat& img, int f, cv::Size cs, cv::Mat* out,
                           std::vector<std::uint32_t>* row_sums);
// Same result; the vector path for f in {2, 4, 8, 16}, the scalar one otherwise.
void box_downsample(const cv::Mat& img, int f, cv::Size cs, cv::Mat* out,
                    std::vector<std::uint32_t>* row_sums);

// Largest block for which adaptive_threshold_mean_inv equals OpenCV (whose 8-bit box filter
// rounds through float and 16-bit sums up to 256 pixels); larger blocks call OpenCV.
constexpr int kMaxOwnAdaptiveBlock = 15;

// dst = cv::adaptiveThreshold(src, 255, ADAPTIVE_THRESH_MEAN_C, THRESH_BINARY_INV, block,
// offset) for an 8-bit src, bit for bit: 255 where src - round(mean of the block x block window,
// border replicated) <= -floor(offset), else 0. block odd >= 3. scratch: row sums.
void adaptive_threshold_mean_inv(const cv::Mat& src, int block, double offset, cv::Mat* dst,
                                 std::vector<std::uint16_t>* scratch);

// Integral images of an 8-bit src: sum (CV_32SC1, (h + 1) x (w + 1)) as cv::integral gives it, and
// sq, the integral of the squares, as 32-bit unsigned integers (stored in a CV_32SC1 Mat) that
// wrap modulo 2^32. Read them only through window_sum_sq: a window's sum of squares is below 2^32
// for any window under 66051 pixels, so its modular difference is exact however large the image,
// and the results equal cv::integral(src, sum, sq, CV_32S, CV_64F)'s differences bit for bit.
// Half the memory of 64-bit doubles (aarch64 cost of the loop: coarse_level.cpp).
void integral_sum_sq(const cv::Mat& src, cv::Mat* sum, cv::Mat* sq);

// Sum and sum of squares of the n x n window whose top-left pixel is (x, y), from
// integral_sum_sq's images; the window must lie inside the image and n * n < 66051.
// Inline: the corner search calls it once per candidate pixel.
inline void window_sum_sq(const cv::Mat& sum, const cv::Mat& sq, int x, int y, int n,
                          double* window_sum, double* window_sq) {
  const std::int32_t* s0 = sum.ptr<std::int32_t>(y);
  const std::int32_t* s1 = sum.ptr<std::int32_t>(y + n);
  const std::uint32_t* q0 = sq.ptr<std::uint32_t>(y);
  const std::uint32_t* q1 = sq.ptr<std::uint32_t>(y + n);
  *window_sum = s1[x + n] - s0[x + n] - s1[x] + s0[x];
  *window_sq = static_cast<std::uint32_t>(q1[x + n] - q0[x + n] - q1[x] + q0[x]);
}

}  // namespace agv::vision
