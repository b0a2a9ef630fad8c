// imu.source and imu.iio_* (algo/src/config/keys_vehicle.cpp, relations in parse.cpp): what
// `agvloc run --check-config` accepts and refuses for the IIO gyro.
#include <gtest/gtest.h>

#include <string>
#include <vector>

#include "agv/config/config.hpp"

namespace {

using agv::config::Config;

const char* kIntrinsics = "intrinsics: {fx: 769.23, fy: 769.23, cx: 319.5, cy: 239.5}\n";

bool parse(const std::string& yaml, Config* cfg, std::vector<std::string>* errors) {
  return agv::config::parse_config(std::string(kIntrinsics) + yaml, "", cfg, errors);
}

bool mentions(const std::vector<std::string>& errors, const std::string& what) {
  for (const auto& e : errors) {
    if (e.find(what) != std::string::npos) return true;
  }
  return false;
}

TEST(ImuConfig, DefaultKeepsTheCanGyro) {
  Config cfg;
  std::vector<std::string> errors;
  ASSERT_TRUE(parse("", &cfg, &errors));
  EXPECT_EQ(cfg.imu.source, agv::config::ImuSource::kCan);
  EXPECT_EQ(cfg.imu.iio_rate_hz, 200.0);
  ASSERT_TRUE(parse("can: {gyro: {enabled: true}}\n", &cfg, &errors));
}

TEST(ImuConfig, IioWithDeviceIsAccepted) {
  Config cfg;
  std::vector<std::string> errors;
  ASSERT_TRUE(
      parse("imu: {source: iio, iio_device: bmi160, iio_trigger: bmi160-dev0, "
            "iio_rate_hz: 400}\n",
            &cfg, &errors))
      << (errors.empty() ? "" : errors.front());
  EXPECT_EQ(cfg.imu.source, agv::config::ImuSource::kIio);
  EXPECT_EQ(cfg.imu.iio_device, "bmi160");
  EXPECT_EQ(cfg.imu.iio_trigger, "bmi160-dev0");
  EXPECT_EQ(cfg.imu.iio_rate_hz, 400.0);
}

TEST(ImuConfig, NonsenseIsRefused) {
  Config cfg;
  std::vector<std::string> errors;
  EXPECT_FALSE(parse("imu: {source: spi}\n", &cfg, &errors));
  EXPECT_TRUE(mentions(errors, "imu.source")) << errors.front();
  errors.clear();
  EXPECT_FALSE(parse("imu: {source: iio}\n", &cfg, &errors));
  EXPECT_TRUE(mentions(errors, "imu.iio_device"));
  errors.clear();
  EXPECT_FALSE(parse("imu: {source: iio, iio_device: bmi160, iio_rate_hz: -5}\n", &cfg, &errors));
  EXPECT_TRUE(mentions(errors, "imu.iio_rate_hz"));
  errors.clear();
  EXPECT_FALSE(parse("imu: {source: iio, iio_device: bmi160, iio_rate_hz: 1e6}\n", &cfg, &errors));
  EXPECT_TRUE(mentions(errors, "imu.iio_rate_hz"));
  errors.clear();
  // Two gyro sources (or "none" with the CAN gyro on) is a contradiction, not a preference.
  EXPECT_FALSE(parse("imu: {source: iio, iio_device: bmi160}\ncan: {gyro: {enabled: true}}\n", &cfg,
                     &errors));
  EXPECT_TRUE(mentions(errors, "imu.source"));
  errors.clear();
  EXPECT_FALSE(parse("imu: {source: none}\ncan: {gyro: {enabled: true}}\n", &cfg, &errors));
  EXPECT_TRUE(mentions(errors, "imu.source"));
}

}  // namespace
