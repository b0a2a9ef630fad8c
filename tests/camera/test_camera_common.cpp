#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <string>
#include <vector>

#include "agv/camera/common.hpp"

namespace {

using agv::camera::ClockDomain;
using agv::camera::TimestampRef;
using agv::hal::CameraConfig;
using agv::hal::PixelFormatPreference;

TEST(CameraStatus, EveryStatusHasAName) {
  using agv::hal::CameraStatus;
  EXPECT_STREQ(agv::hal::to_string(CameraStatus::kOk), "ok");
  EXPECT_STREQ(agv::hal::to_string(CameraStatus::kDisconnected), "disconnected");
  EXPECT_STREQ(agv::hal::to_string(CameraStatus::kTimeout), "timeout");
  EXPECT_STREQ(agv::hal::to_string(static_cast<CameraStatus>(99)), "unknown camera status");
}

TEST(CameraConfig, DefaultIsValid) { EXPECT_EQ(agv::camera::validate_config(CameraConfig{}), ""); }

TEST(CameraConfig, RejectsEachBadFieldWithItsName) {
  struct Case {
    void (*mutate)(CameraConfig&);
    const char* field;
  };
  const Case cases[] = {
      {[](CameraConfig& c) { c.width_px = 0; }, "size"},
      {[](CameraConfig& c) { c.height_px = 100000; }, "size"},
      {[](CameraConfig& c) { c.width_px = 641; }, "even"},
      {[](CameraConfig& c) { c.fps = 0.0; }, "fps"},
      {[](CameraConfig& c) { c.fps = 1e9; }, "fps"},
      {[](CameraConfig& c) { c.exposure_us = 0; }, "exposure_us"},
      // 40 ms exposure does not fit into a 33 ms frame period.
      {[](CameraConfig& c) { c.exposure_us = 40000; }, "frame period"},
      {[](CameraConfig& c) { c.analogue_gain = 0.5; }, "analogue_gain"},
      {[](CameraConfig& c) { c.analogue_gain = std::nan(""); }, "analogue_gain"},
      {[](CameraConfig& c) { c.buffer_count = 1; }, "buffer_count"},
      {[](CameraConfig& c) { c.readout_us = -1; }, "readout_us"},
      {[](CameraConfig& c) { c.pixel_format = static_cast<PixelFormatPreference>(7); },
       "pixel_format"},
  };
  for (const Case& k : cases) {
    CameraConfig c;
    k.mutate(c);
    const std::string e = agv::camera::validate_config(c);
    EXPECT_NE(e.find(k.field), std::string::npos) << "message: '" << e << "'";
  }
}

TEST(PixelFormat, FourccNames) {
  EXPECT_EQ(agv::camera::fourcc_to_string(agv::camera::kFourccNv12), "NV12");
  EXPECT_EQ(agv::camera::fourcc_to_string(agv::camera::kFourccR8), "R8");
  EXPECT_EQ(agv::camera::kFourccGrey, 0x59455247u);  // V4L2_PIX_FMT_GREY
}

TEST(PixelFormat, ChoiceFollowsPreferenceAndAvoidsCopies) {
  using namespace agv::camera;
  const std::vector<std::uint32_t> colour = {make_fourcc('M', 'J', 'P', 'G'), kFourccYuyv,
                                             kFourccNv12};
  EXPECT_EQ(choose_format(PixelFormatPreference::kAuto, colour), kFourccNv12);  // in place
  EXPECT_EQ(choose_format(PixelFormatPreference::kAuto, {kFourccYuyv, kFourccGrey}), kFourccGrey);
  EXPECT_EQ(choose_format(PixelFormatPreference::kYuv, {kFourccYuyv, kFourccGrey}), kFourccYuyv);
  // A forced format: exactly that one when offered and usable, else none (no fallback).
  EXPECT_EQ(choose_format(PixelFormatPreference::kAuto, {kFourccYuyv, kFourccGrey}, kFourccYuyv),
            kFourccYuyv);
  EXPECT_EQ(choose_format(PixelFormatPreference::kAuto, {kFourccGrey}, kFourccYuyv), 0u);
  const std::uint32_t mjpg = make_fourcc('M', 'J', 'P', 'G');  // offered but not usable
  EXPECT_EQ(choose_format(PixelFormatPreference::kAuto, {mjpg, kFourccGrey}, mjpg), 0u);
  EXPECT_EQ(choose_format(PixelFormatPreference::kGray, colour), 0u);
  EXPECT_EQ(choose_format(PixelFormatPreference::kAuto, {make_fourcc('M', 'J', 'P', 'G')}), 0u);
}

TEST(PixelFormat, LayoutSizesAndStrides) {
  using namespace agv::camera;
  GrayLayout l;
  std::string err;
  ASSERT_TRUE(gray_layout(kFourccNv12, 640, 480, 704, &l, &err)) << err;
  EXPECT_TRUE(l.in_place);
  EXPECT_EQ(l.stride_bytes, 704);
  EXPECT_EQ(l.min_bytes, 704u * 480u * 3u / 2u);
  ASSERT_TRUE(gray_layout(kFourccGrey, 640, 480, 640, &l, &err));
  EXPECT_EQ(l.min_bytes, 640u * 480u);
  ASSERT_TRUE(gray_layout(kFourccYuyv, 640, 480, 1280, &l, &err));
  EXPECT_FALSE(l.in_place);
  EXPECT_EQ(l.min_bytes, 1280u * 480u);
  EXPECT_FALSE(gray_layout(kFourccYuyv, 640, 480, 640, &l, &err));
  EXPECT_NE(err.find("stride"), std::string::npos);
  EXPECT_FALSE(gray_layout(kFourccGrey, 640, 480, 600, &l, &err));
  EXPECT_FALSE(gray_layout(kFourccNv12, 641, 480, 704, &l, &err));
  EXPECT_FALSE(gray_layout(make_fourcc('M', 'J', 'P', 'G'), 640, 480, 640, &l, &err));
  EXPECT_NE(err.find("MJPG"), std::string::npos);
}

TEST(PixelFormat, YuyvToGrayTakesLumaAndHonoursStrides) {
  const int w = 4, h = 2, src_stride = 12, dst_stride = 6;  // padded rows on both sides
  std::vector<std::uint8_t> src(static_cast<std::size_t>(src_stride * h), 0xEE);
  for (int r = 0; r < h; ++r) {
    for (int c = 0; c < w; ++c) {
      src[static_cast<std::size_t>(r * src_stride + 2 * c)] = static_cast<std::uint8_t>(10 * r + c);
      src[static_cast<std::size_t>(r * src_stride + 2 * c + 1)] = 200;  // chroma, must be skipped
    }
  }
  std::vector<std::uint8_t> dst(static_cast<std::size_t>(dst_stride * h), 0x55);
  agv::camera::yuyv_to_gray(src.data(), src_stride, w, h, dst.data(), dst_stride);
  for (int r = 0; r < h; ++r) {
    for (int c = 0; c < w; ++c)
      EXPECT_EQ(dst[static_cast<std::size_t>(r * dst_stride + c)], 10 * r + c);
    EXPECT_EQ(dst[static_cast<std::size_t>(r * dst_stride + w)], 0x55) << "padding overwritten";
  }
}

TEST(PixelFormat, Rgb24ToGrayWeightsAndByteOrder) {
  using namespace agv::camera;
  // One row: pure red, pure green, pure blue, white, in memory order R G B.
  const std::uint8_t rgb[12] = {255, 0, 0, 0, 255, 0, 0, 0, 255, 255, 255, 255};
  std::uint8_t gray[4] = {};
  ASSERT_TRUE(convert_to_gray(kFourccBgr888, rgb, 12, 4, 1, gray, 4));  // libcamera BGR888 = R G B
  EXPECT_EQ(gray[0], 77);                                               // (77*255+128)>>8
  EXPECT_EQ(gray[1], 149);                                              // (150*255+128)>>8
  EXPECT_EQ(gray[2], 29);
  EXPECT_EQ(gray[3], 255);
  // Same bytes read as B G R: red and blue swap.
  ASSERT_TRUE(convert_to_gray(kFourccRgb888, rgb, 12, 4, 1, gray, 4));
  EXPECT_EQ(gray[0], 29);
  EXPECT_EQ(gray[2], 77);
  EXPECT_FALSE(convert_to_gray(kFourccNv12, rgb, 12, 4, 1, gray, 4));  // in place, no copy
  GrayLayout l;
  std::string err;
  ASSERT_TRUE(gray_layout(kFourccRgb888, 648, 480, 1944, &l, &err)) << err;
  EXPECT_FALSE(l.in_place);
  EXPECT_FALSE(gray_layout(kFourccRgb888, 648, 480, 1000, &l, &err));
  // RGB only as the last resort under kAuto, never under kYuv.
  EXPECT_EQ(choose_format(PixelFormatPreference::kAuto, {kFourccRgb888, kFourccYuyv}), kFourccYuyv);
  EXPECT_EQ(choose_format(PixelFormatPreference::kAuto, {kFourccRgb888, kFourccBgr888}),
            kFourccRgb888);
  EXPECT_EQ(choose_format(PixelFormatPreference::kYuv, {kFourccRgb888}), 0u);
}

TEST(Timestamp, MidExposureFromStartOfExposure) {
  // Global shutter, 1 ms exposure starting at t=10 ms -> mid at 10.5 ms.
  EXPECT_EQ(agv::camera::exposure_mid_ns(10'000'000, TimestampRef::kStartOfExposure, 1'000'000, 0),
            10'500'000);
  // Rolling shutter with 20 ms readout: centre row starts 10 ms after the first.
  EXPECT_EQ(agv::camera::exposure_mid_ns(10'000'000, TimestampRef::kStartOfExposure, 1'000'000,
                                         20'000'000),
            20'500'000);
}

TEST(Timestamp, MidExposureFromEndOfFrame) {
  EXPECT_EQ(agv::camera::exposure_mid_ns(50'000'000, TimestampRef::kEndOfFrame, 2'000'000, 0),
            49'000'000);
  EXPECT_EQ(
      agv::camera::exposure_mid_ns(50'000'000, TimestampRef::kEndOfFrame, 2'000'000, 30'000'000),
      34'000'000);
}

TEST(Timestamp, ClockDomainEqualClocksIsMonotonic) {
  EXPECT_EQ(agv::camera::guess_clock_domain(900, 1000, 1000), ClockDomain::kMonotonic);
}

TEST(Timestamp, ClockDomainAfterSuspend) {
  const std::int64_t mono = 100'000'000'000, boot = mono + 3'600'000'000'000;  // 1 h suspended
  const std::int64_t age = 20'000'000;
  EXPECT_EQ(agv::camera::guess_clock_domain(boot - age, mono, boot), ClockDomain::kBoottime);
  EXPECT_EQ(agv::camera::guess_clock_domain(mono - age, mono, boot), ClockDomain::kMonotonic);
  EXPECT_EQ(agv::camera::to_monotonic_ns(boot - age, ClockDomain::kBoottime, mono, boot),
            mono - age);
  EXPECT_EQ(agv::camera::to_monotonic_ns(mono - age, ClockDomain::kMonotonic, mono, boot),
            mono - age);
}

TEST(Timestamp, SystemClocksAreConsistent) {
  const std::int64_t m1 = agv::camera::monotonic_now_ns();
  const std::int64_t b = agv::camera::boottime_now_ns();
  const std::int64_t m2 = agv::camera::monotonic_now_ns();
  EXPECT_GT(m1, 0);
  EXPECT_LE(m1, m2);
  EXPECT_GE(b, m1);  // boottime = monotonic + suspend time
}

}  // namespace
