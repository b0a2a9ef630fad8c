// Image operations of the detection stage's coarse level (detect.cpp), own loops instead of the
// OpenCV calls they replace because those dominated a landmark-free frame on aarch64; each is
// tested against its reference (tests/vision/test_coarse_level.cpp, also under qemu-aarch64).
//
// Box downsampling of an 8-bit image by an integer factor: each output pixel is the rounded mean of
// an f x f block, what cv::resize with INTER_AREA computes for an integer factor. Two
// implementations that must agree bit for bit: the scalar reference and the vector path (GCC/Clang
// vector extensions, 16 pixels a step: NEON on aarch64, SSE2 on x86-64), which the detection uses
// for f = 2, 4, 8 and 16 (tests/vision compares them, also under qemu-aarch64).
#pragma once

#include <cstdint>
#include <vector>

namespace cv {
class Mat;
template <typename T>
class Size_;
using Size = Size_<int>;
}  // namespace cv

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
                                 std::vector<int>* scratch);

// Integral images of an 8-bit src as cv::integral(src, sum, sq, CV_32S, CV_64F) gives them (the
// squares summed exactly in 64-bit integers, so the doubles are the same).
void integral_sum_sq(const cv::Mat& src, cv::Mat* sum, cv::Mat* sq);

}  // namespace agv::vision
