#include <gtest/gtest.h>
#include <linux/videodev2.h>

#include "agv/v4l2/v4l2_camera.hpp"

namespace {

using agv::camera::TimestampRef;

TEST(V4l2Timestamp, FlagsDecoded) {
  auto k =
      agv::v4l2::timestamp_kind(V4L2_BUF_FLAG_TIMESTAMP_MONOTONIC | V4L2_BUF_FLAG_TSTAMP_SRC_SOE);
  EXPECT_TRUE(k.monotonic);
  EXPECT_EQ(k.ref, TimestampRef::kStartOfExposure);
  k = agv::v4l2::timestamp_kind(V4L2_BUF_FLAG_TIMESTAMP_MONOTONIC | V4L2_BUF_FLAG_TSTAMP_SRC_EOF);
  EXPECT_TRUE(k.monotonic);
  EXPECT_EQ(k.ref, TimestampRef::kEndOfFrame);
  k = agv::v4l2::timestamp_kind(V4L2_BUF_FLAG_TIMESTAMP_COPY);
  EXPECT_FALSE(k.monotonic);
}

TEST(V4l2Timestamp, MidExposureForEachSource) {
  const std::int64_t ts = 1'000'000'000, deq = 1'005'000'000, exp = 2'000'000, ro = 10'000'000;
  // Start of exposure (UVC): first row + half readout + half exposure.
  EXPECT_EQ(agv::v4l2::frame_time_ns(
                V4L2_BUF_FLAG_TIMESTAMP_MONOTONIC | V4L2_BUF_FLAG_TSTAMP_SRC_SOE, ts, deq, exp, ro),
            ts + 5'000'000 + 1'000'000);
  // End of frame (most drivers): back by half readout + half exposure.
  EXPECT_EQ(agv::v4l2::frame_time_ns(V4L2_BUF_FLAG_TIMESTAMP_MONOTONIC, ts, deq, exp, ro),
            ts - 6'000'000);
  // Unknown clock: the dequeue time stands in for end of frame.
  EXPECT_EQ(agv::v4l2::frame_time_ns(V4L2_BUF_FLAG_TIMESTAMP_UNKNOWN, ts, deq, exp, ro),
            deq - 6'000'000);
}

TEST(V4l2Camera, MissingDeviceIsDisconnected) {
  agv::hal::CameraConfig c;
  c.id = "/dev/agv-no-such-video-device";
  agv::v4l2::V4l2Camera cam(c);
  EXPECT_EQ(cam.start(), agv::hal::CameraStatus::kDisconnected);
  EXPECT_NE(std::string(cam.last_error()).find("agv-no-such-video-device"), std::string::npos);
  agv::hal::FrameView f;
  EXPECT_EQ(cam.next_frame(0, &f), agv::hal::CameraStatus::kNotStarted);
  cam.stop();  // idempotent
  cam.stop();
}

TEST(V4l2Camera, InvalidConfigRejectedBeforeOpening) {
  agv::hal::CameraConfig c;
  c.id = "/dev/null";
  c.fps = 0;
  agv::v4l2::V4l2Camera cam(c);
  EXPECT_EQ(cam.start(), agv::hal::CameraStatus::kInvalidArgument);
  EXPECT_NE(std::string(cam.last_error()).find("fps"), std::string::npos);
}

TEST(V4l2Camera, NonVideoDeviceRejected) {
  agv::hal::CameraConfig c;
  c.id = "/dev/null";
  agv::v4l2::V4l2Camera cam(c);
  const auto s = cam.start();
  EXPECT_TRUE(s == agv::hal::CameraStatus::kDeviceError ||
              s == agv::hal::CameraStatus::kInvalidArgument)
      << agv::hal::to_string(s);
  EXPECT_STRNE(cam.last_error(), "");
}

}  // namespace
