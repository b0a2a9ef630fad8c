#include <gtest/gtest.h>

#include <cstdio>
#include <filesystem>
#include <fstream>

#include "agv/recording/png_io.hpp"

namespace {
std::string tmp(const char* name) {
  return (std::filesystem::temp_directory_path() / (std::string("agv_png_") + name)).string();
}
}  // namespace

TEST(PngIo, GrayRoundTripIsExact) {
  cv::Mat img(37, 53, CV_8UC1);
  cv::randu(img, 0, 256);
  std::string err;
  const std::string p = tmp("gray.png");
  ASSERT_TRUE(agv::png::write(p, img, &err)) << err;
  cv::Mat back;
  ASSERT_TRUE(agv::png::read_gray(p, &back, &err)) << err;
  ASSERT_EQ(back.type(), CV_8UC1);
  EXPECT_EQ(cv::norm(img, back, cv::NORM_INF), 0.0);
}

TEST(PngIo, ColourIsReadAsLuma) {
  cv::Mat bgr(4, 4, CV_8UC3, cv::Scalar(0, 0, 255));  // pure red
  std::string err;
  const std::string p = tmp("red.png");
  ASSERT_TRUE(agv::png::write(p, bgr, &err)) << err;
  cv::Mat g;
  ASSERT_TRUE(agv::png::read_gray(p, &g, &err)) << err;
  EXPECT_NEAR(g.at<unsigned char>(0, 0), 76, 1);  // 0.299 * 255
}

TEST(PngIo, CorruptTruncatedAndMissingFilesAreErrors) {
  cv::Mat img(64, 64, CV_8UC1, cv::Scalar(9));
  std::string err;
  const std::string p = tmp("trunc.png");
  ASSERT_TRUE(agv::png::write(p, img, &err));
  std::filesystem::resize_file(p, std::filesystem::file_size(p) / 2);
  cv::Mat out;
  EXPECT_FALSE(agv::png::read_gray(p, &out, &err));
  EXPECT_NE(err.find("corrupt"), std::string::npos) << err;
  std::ofstream(tmp("text.png")) << "not a png at all";
  EXPECT_FALSE(agv::png::read_gray(tmp("text.png"), &out, &err));
  EXPECT_NE(err.find("not a PNG"), std::string::npos);
  EXPECT_FALSE(agv::png::read_gray("/nonexistent/x.png", &out, &err));
  EXPECT_FALSE(agv::png::write("/nonexistent/dir/x.png", img, &err));
  EXPECT_FALSE(agv::png::write(tmp("f.png"), cv::Mat(3, 3, CV_32F), &err));
}
