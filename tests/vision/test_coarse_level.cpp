// The coarse level's own loops against their references, bit for bit: the vector box downsample
// against the scalar one (every factor with a vector path, widths with and without a partial last
// chunk, extreme values), the adaptive threshold and the integral images against OpenCV.
#include <gtest/gtest.h>

#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>
#include <random>
#include <vector>

#include "../support/one_landmark_frame.hpp"
#include "agv/sim/render.hpp"
#include "agv/vision/coarse_level.hpp"
#include "agv/vision/landmark_localizer.hpp"

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

// The tracked detection downsamples a window of the frame: a region whose rows start at any
// column and whose step is the frame's, so the vector loads are unaligned.
TEST(BoxDownsample, VectorEqualsScalarOnARegionOfTheFrame) {
  std::mt19937 rng(23);
  std::uniform_int_distribution<int> grey(0, 255);
  cv::Mat frame(480, 640, CV_8UC1);
  for (int y = 0; y < frame.rows; ++y) {
    for (int x = 0; x < frame.cols; ++x)
      frame.at<std::uint8_t>(y, x) = static_cast<std::uint8_t>(grey(rng));
  }
  for (int f : {8, 16}) {
    for (cv::Rect r : {cv::Rect(8, 16, 560, 400), cv::Rect(3, 5, 37 * f + 3, 9 * f),
                       cv::Rect(640 - 17 * f, 480 - 2 * f, 17 * f, 2 * f)}) {
      expect_same(frame(r), f);
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

// Random grey levels, or a smooth ramp plus a little noise (means close to the pixel values, so
// the comparison and the rounding of the mean decide).
cv::Mat test_image(cv::Size sz, bool smooth, std::mt19937* rng) {
  std::uniform_int_distribution<int> grey(0, 255), noise(-3, 3);
  cv::Mat img(sz, CV_8UC1);
  for (int y = 0; y < sz.height; ++y) {
    for (int x = 0; x < sz.width; ++x) {
      const int v = smooth ? 40 + (x * 150) / std::max(1, sz.width) + y + noise(*rng) : grey(*rng);
      img.at<std::uint8_t>(y, x) = static_cast<std::uint8_t>(std::clamp(v, 0, 255));
    }
  }
  return img;
}

TEST(CoarseLevel, AdaptiveThresholdEqualsOpenCv) {
  std::mt19937 rng(5);
  std::vector<std::uint16_t> scratch;
  int compared = 0;
  for (cv::Size sz :
       {cv::Size(80, 60), cv::Size(160, 120), cv::Size(37, 23), cv::Size(7, 5), cv::Size(1, 9)}) {
    for (bool smooth : {false, true}) {
      const cv::Mat img = test_image(sz, smooth, &rng);
      for (int block = 3; block <= 17; block += 2) {
        for (double offset : {6.0, 0.0, 2.5, -3.2, 20.0, -255.0, -300.5, 254.0, 400.0, 1e6}) {
          cv::Mat ref, own;
          cv::adaptiveThreshold(img, ref, 255, cv::ADAPTIVE_THRESH_MEAN_C, cv::THRESH_BINARY_INV,
                                block, offset);
          adaptive_threshold_mean_inv(img, block, offset, &own, &scratch);
          ASSERT_EQ(own.size(), ref.size());
          ASSERT_EQ(own.type(), CV_8UC1);
          EXPECT_EQ(cv::countNonZero(own != ref), 0)
              << sz.width << "x" << sz.height << " block " << block << " offset " << offset;
          compared +=
              cv::countNonZero(ref) > 0 && static_cast<size_t>(cv::countNonZero(ref)) < ref.total()
                  ? 1
                  : 0;
        }
      }
    }
  }
  // Saturated images: the largest window sums, and offsets at the clamps of the 16-bit lanes.
  for (int v : {0, 1, 254, 255}) {
    const cv::Mat flat(cv::Size(45, 21), CV_8UC1, cv::Scalar(v));
    for (int block : {3, 13, 15}) {
      for (double offset : {0.0, -1.0, 1.0, -255.0, 255.0, -256.0, 256.0, 291.0, 292.0}) {
        cv::Mat ref, own;
        cv::adaptiveThreshold(flat, ref, 255, cv::ADAPTIVE_THRESH_MEAN_C, cv::THRESH_BINARY_INV,
                              block, offset);
        adaptive_threshold_mean_inv(flat, block, offset, &own, &scratch);
        EXPECT_EQ(cv::countNonZero(own != ref), 0)
            << "flat " << v << " block " << block << " offset " << offset;
      }
    }
  }
  // Most cases have both classes, so the comparison is not between two all-equal images.
  EXPECT_GT(compared, 100);
}

// Every window's sum and sum of squares equals cv::integral's (64-bit doubles), including on an
// image whose total sum of squares passes 2^32 (the 32-bit integral wraps; window differences must
// not).
TEST(CoarseLevel, IntegralWindowsEqualOpenCv) {
  std::mt19937 rng(9);
  for (cv::Size sz : {cv::Size(80, 60), cv::Size(160, 120), cv::Size(1, 1), cv::Size(33, 2),
                      cv::Size(7, 5), cv::Size(420, 400)}) {
    cv::Mat img = test_image(sz, false, &rng);
    img.at<std::uint8_t>(0, 0) = 255;
    if (sz.width == 420) img.rowRange(0, 300).setTo(255);
    cv::Mat ref_sum, ref_sq, sum, sq;
    cv::integral(img, ref_sum, ref_sq, CV_32S, CV_64F);
    integral_sum_sq(img, &sum, &sq);
    ASSERT_EQ(sum.type(), CV_32SC1);
    EXPECT_EQ(cv::countNonZero(sum != ref_sum), 0);
    if (sz.width == 420) {
      ASSERT_GT(ref_sq.at<double>(sz.height, sz.width), 4294967296.0);
    }
    int windows = 0;
    for (int n : {1, 2, 5, 9, 16}) {
      const int step = sz.width > 100 ? 7 : 1;
      for (int y = 0; y + n <= sz.height; y += step) {
        for (int x = 0; x + n <= sz.width; x += step) {
          double s = 0.0, q = 0.0;
          window_sum_sq(sum, sq, x, y, n, &s, &q);
          const double rs = ref_sum.at<int>(y + n, x + n) - ref_sum.at<int>(y, x + n) -
                            ref_sum.at<int>(y + n, x) + ref_sum.at<int>(y, x);
          const double rq = ref_sq.at<double>(y + n, x + n) - ref_sq.at<double>(y, x + n) -
                            ref_sq.at<double>(y + n, x) + ref_sq.at<double>(y, x);
          ASSERT_EQ(s, rs) << sz << " n " << n << " at " << x << "," << y;
          ASSERT_EQ(q, rq) << sz << " n " << n << " at " << x << "," << y;
          ++windows;
        }
      }
    }
    EXPECT_GT(windows, 0) << sz;
  }
}

// The corner NCC packs the templates into 12, 16 or 32 lanes by their number (8 and 12 rotations:
// 12 lanes, 14: 16, 24 and 32: 32): every packing finds the landmark where it is. That the default
// 12 rotations in 12 lanes give the fixes they gave in 16 is the golden replay's check.
TEST(CoarseLevel, EveryCornerTemplatePackingFindsTheLandmark) {
  const Pose2 landmark{1000.0, -2000.0, deg_to_rad(90.0)};
  const Pose2 e{4.0, -3.0, deg_to_rad(23.0)};
  testsupport::OneLandmarkFrame f;
  std::string err;
  ASSERT_TRUE(testsupport::render_one_landmark(landmark, e, {}, &f, &err)) << err;
  const LandmarkMap& map = f.map;
  const CameraModel& cam = f.cam;
  const cv::Mat& img = f.img;
  LandmarkFix ref;
  {
    LandmarkLocalizer loc(VisionConfig{}, cam, LandmarkGeometry{}, &map);
    ASSERT_EQ(loc.process(img, &ref), FixStatus::kOk) << to_string(ref.status);
  }
  for (int rotations : {8, 14, 24, 32}) {
    VisionConfig cfg;
    cfg.corner_rotations = rotations;
    LandmarkLocalizer loc(cfg, cam, LandmarkGeometry{}, &map);
    LandmarkFix fix;
    ASSERT_EQ(loc.process(img, &fix), FixStatus::kOk) << rotations << ": " << to_string(fix.status);
    EXPECT_NEAR(fix.e_x_mm, e.x_mm, 0.05) << rotations;
    EXPECT_NEAR(fix.e_y_mm, e.y_mm, 0.05) << rotations;
  }
  EXPECT_NEAR(ref.e_x_mm, e.x_mm, 0.05);
}

}  // namespace
}  // namespace agv::vision
