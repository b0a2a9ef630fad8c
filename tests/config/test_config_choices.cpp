// The choice keys are read once, by the key table, into enums; their names come back from the
// same tables. The CAN protocol configuration carries the gyro input.
#include <gtest/gtest.h>

#include <string>
#include <vector>

#include "agv/common/landmark.hpp"
#include "agv/config/config.hpp"
#include "agv/config/keys.hpp"

namespace agv::config {
namespace {

const char* kIntrinsics = "intrinsics: {fx: 769.23, fy: 769.23, cx: 319.5, cy: 239.5}\n";

Config parsed(const std::string& yaml) {
  Config cfg;
  std::vector<std::string> errors;
  EXPECT_TRUE(parse_config(kIntrinsics + yaml, "", &cfg, &errors))
      << (errors.empty() ? "" : errors.front());
  return cfg;
}

TEST(ConfigChoices, ReadIntoEnumsAndNamedBack) {
  const Config cfg = parsed(
      "camera:\n  driver: v4l2\ncan:\n  odometry:\n    mode: wheels\n"
      "imu:\n  source: iio\n  iio_device: bmi160\n");
  EXPECT_EQ(cfg.camera.driver, CameraDriver::kV4l2);
  EXPECT_EQ(cfg.can.odometry_mode, protocol::OdometryMode::kWheels);
  EXPECT_EQ(cfg.imu.source, ImuSource::kIio);
  EXPECT_STREQ(camera_driver_name(cfg.camera.driver), "v4l2");
  EXPECT_STREQ(odometry_mode_name(cfg.can.odometry_mode), "wheels");
  EXPECT_STREQ(imu_source_name(cfg.imu.source), "iio");
  // The key table reads and writes the same names.
  for (const char* key : {"camera.driver", "can.odometry.mode", "imu.source"}) {
    const Key* k = find_key(key);
    ASSERT_NE(k, nullptr) << key;
    Config copy;
    k->set(copy, k->get(cfg));
    EXPECT_EQ(format_value(*k, k->get(copy)), format_value(*k, k->get(cfg))) << key;
  }
  EXPECT_EQ(format_value(*find_key("imu.source"), find_key("imu.source")->get(cfg)), "iio");
  const Config defaults = parsed("");
  EXPECT_EQ(defaults.camera.driver, CameraDriver::kLibcamera);
  EXPECT_EQ(defaults.can.odometry_mode, protocol::OdometryMode::kTwist);
  EXPECT_EQ(defaults.imu.source, ImuSource::kCan);
}

TEST(ConfigChoices, UnknownNameIsRefusedByTheTable) {
  Config cfg;
  std::vector<std::string> errors;
  EXPECT_FALSE(parse_config(std::string(kIntrinsics) + "imu:\n  source: spi\n", "", &cfg, &errors));
  ASSERT_FALSE(errors.empty());
  EXPECT_NE(errors.front().find("imu.source"), std::string::npos) << errors.front();
}

TEST(LandmarkFamilyNames, RoundTripAndRefuseUnknown) {
  for (const auto& [name, family] : kLandmarkFamilyNames) {
    LandmarkFamily f = family == LandmarkFamily::kQr ? LandmarkFamily::kTag36h11
                                                      : LandmarkFamily::kQr;
    ASSERT_TRUE(parse_landmark_family(name, &f));
    EXPECT_EQ(f, family);
    EXPECT_EQ(std::string(landmark_family_name(f)), name);
  }
  LandmarkFamily f = LandmarkFamily::kTag36h11;
  EXPECT_FALSE(parse_landmark_family("aruco", &f));
  EXPECT_EQ(f, LandmarkFamily::kTag36h11);  // unchanged
}

TEST(ProtocolConfig, CarriesTheGyroInput) {
  const Config cfg = parsed("can:\n  gyro:\n    enabled: true\n    id: 0x2A0\n    protected: false\n");
  const protocol::ProtocolConfig pc = protocol_config(cfg);
  EXPECT_TRUE(pc.gyro.enabled);
  EXPECT_EQ(pc.gyro.can_id, 0x2A0u);
  EXPECT_FALSE(pc.gyro.protected_e2e);
  EXPECT_FALSE(protocol_config(parsed("")).gyro.enabled);
}

TEST(ProtocolConfig, AGyroIdOnTheOdometryIdIsAConfigurationError) {
  Config cfg;
  std::vector<std::string> errors;
  // 0x311 is the v_omega odometry ID of the default base_id 0x300.
  EXPECT_FALSE(parse_config(std::string(kIntrinsics) + "can:\n  gyro:\n    enabled: true\n    id: 0x311\n",
                            "", &cfg, &errors));
  ASSERT_FALSE(errors.empty());
  EXPECT_NE(errors.front().find("gyro CAN ID collides"), std::string::npos) << errors.front();
}

TEST(LandmarkGeometry, FromTheOneSizeKey) {
  const Config cfg = parsed("landmark:\n  size_mm: 80\n");
  EXPECT_DOUBLE_EQ(landmark_geometry(cfg).size_mm, 80.0);
  LandmarkGeometry defaults;
  EXPECT_DOUBLE_EQ(landmark_geometry(cfg).outer_half_mm(), 40.0);
  EXPECT_NE(landmark_geometry(cfg).inner_half_mm(), defaults.inner_half_mm());
}

}  // namespace
}  // namespace agv::config
