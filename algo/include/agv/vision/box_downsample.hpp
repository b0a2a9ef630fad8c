// Box downsampling of an 8-bit image by an integer factor, the coarse level of the detection
// stage: each output pixel is the rounded mean of an f x f block, what cv::resize with INTER_AREA
// computes for an integer factor. Two implementations that must agree bit for bit: the scalar
// reference and the vector path (GCC/Clang vector extensions, 16 pixels a step: NEON on aarch64,
// SSE2 on x86-64), which the detection uses for f = 2, 4, 8 and 16 (tests/vision compares them,
// also under qemu-aarch64).
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

}  // namespace agv::vision
