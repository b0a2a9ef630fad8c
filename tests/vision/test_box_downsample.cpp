// The vector box downsample against its scalar reference: bit-exact on random images, for every
// factor with a vector path, widths with and without a partial last chunk, and extreme values.
#include <gtest/gtest.h>

#include <opencv2/core.hpp>
#include <random>
#include <vector>

#include "agv/vision/box_downsample.hpp"

namespace agv::vision {
namespace {

void expect_same(const cv::Mat& img, int f) {
  const cv::Size cs(img.cols / f, img.rows / f);
  cv::Mat ref, vec;
  std::vector<std::uint32_t> s1, s2;
  box_downsample_scalar(img, f, cs, &ref, &s1);
  box_downsample(img, f, cs, &vec, &s2);
  ASSERT_EQ(ref.size(), vec.size());
  ASSERT_EQ(vec.type(), CV_8UC1);
  EXPECT_EQ(cv::countNonZero(ref != vec), 0)
      << "f " << f << " size " << img.cols << "x" << img.rows;
}

TEST(BoxDownsample, VectorEqualsScalarOnRandomImages) {
  std::mt19937 rng(17);
  std::uniform_int_distribution<int> grey(0, 255);
  for (int f : {2, 3, 4, 8, 16}) {
    for (cv::Size sz : {cv::Size(640, 480), cv::Size(1280, 960), cv::Size(100, 37),
                        cv::Size(17 * f + 5, 3 * f + 1), cv::Size(f, f)}) {
      cv::Mat img(sz, CV_8UC1);
      for (int y = 0; y < img.rows; ++y) {
        for (int x = 0; x < img.cols; ++x)
          img.at<std::uint8_t>(y, x) = static_cast<std::uint8_t>(grey(rng));
      }
      expect_same(img, f);
    }
  }
}

TEST(BoxDownsample, ExtremesAndRounding) {
  for (int f : {2, 4, 8, 16}) {
    cv::Mat white(6 * f, 40 * f, CV_8UC1, cv::Scalar(255));
    expect_same(white, f);
    cv::Mat out;
    std::vector<std::uint32_t> s;
    box_downsample(white, f, cv::Size(40, 6), &out, &s);
    EXPECT_EQ(cv::countNonZero(out != 255), 0);
    // Half-way means round up: a block with area / 2 pixels of 1 and the rest 0 has mean 0.5.
    cv::Mat half(f, 16 * f, CV_8UC1, cv::Scalar(0));
    half.rowRange(0, f / 2).setTo(1);
    box_downsample(half, f, cv::Size(16, 1), &out, &s);
    EXPECT_EQ(cv::countNonZero(out != 1), 0) << f;
    expect_same(half, f);
  }
}

}  // namespace
}  // namespace agv::vision
