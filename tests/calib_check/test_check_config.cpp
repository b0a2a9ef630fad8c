// --check-config refuses configurations that can never localize (issue 36, item 9), naming the
// key, and names fusion's relations by their configuration keys (not the struct's _ns fields).
#include <gtest/gtest.h>

#include <string>

#include "agv/config/config.hpp"
#include "config.hpp"

namespace {

using agv::config::Config;

const std::string kIntrinsics = "intrinsics: {fx: 769.23, fy: 769.23, cx: 319.5, cy: 239.5}\n";

std::string errors_of(const std::string& yaml) {
  Config cfg;
  std::vector<std::string> errors;
  if (agv::config::parse_config(kIntrinsics + yaml, "", &cfg, &errors)) return "accepted";
  std::string all;
  for (const auto& e : errors) all += e + "\n";
  return all;
}

TEST(CheckConfig, CanInterfaceMustBeALinuxInterfaceName) {
  EXPECT_EQ(errors_of("can: {interface: vcan0}\n"), "accepted");
  EXPECT_EQ(errors_of("can: {interface: abcdefghijklmno}\n"), "accepted");  // 15
  EXPECT_NE(errors_of("can: {interface: abcdefghijklmnop}\n").find("can.interface: 16 characters"),
            std::string::npos);
  EXPECT_NE(errors_of("can: {interface: " + std::string(100000, 'x') + "}\n")
                .find("can.interface: 100000 characters"),
            std::string::npos);
  EXPECT_NE(errors_of("can: {interface: \"can\\0x\"}\n").find("can.interface: contains"),
            std::string::npos);
  EXPECT_NE(errors_of("can: {interface: \"a/b\"}\n").find("can.interface: contains"),
            std::string::npos);
  EXPECT_NE(errors_of("can: {interface: \"\"}\n").find("can.interface: 0 characters"),
            std::string::npos);
}

TEST(CheckConfig, ReplayFixDelayBeyondTheFusionLimitIsRefused) {
  EXPECT_EQ(errors_of("replay: {fix_delay_ms: 500}\n"), "accepted");
  const std::string e = errors_of("replay: {fix_delay_ms: 600}\nfusion: {max_fix_delay_ms: 500}\n");
  EXPECT_NE(e.find("replay.fix_delay_ms: value 600 exceeds fusion.max_fix_delay_ms (500)"),
            std::string::npos)
      << e;
}

TEST(CheckConfig, OdomGapNamedByItsKey) {
  const std::string e = errors_of("fusion: {odom_period_ms: 20, odom_gap_ms: 10}\n");
  EXPECT_NE(e.find("fusion.odom_gap_ms: value 10 must be at least fusion.odom_period_ms (20)"),
            std::string::npos)
      << e;
  EXPECT_EQ(e.find("_ns"), std::string::npos) << e;
}

TEST(CheckConfig, TagFamilyNeedsAMapWithTagIds) {
  Config cfg;
  cfg.vision.family = agv::LandmarkFamily::kTag36h11;
  std::vector<std::string> errors;
  EXPECT_FALSE(agv::config::check_can_localize(cfg, nullptr, &errors));
  ASSERT_EQ(errors.size(), 1u);
  EXPECT_NE(errors[0].find("tag36h11 needs landmark.map"), std::string::npos) << errors[0];

  agv::LandmarkMap map;
  map.entries[5] = {5, {}};
  map.entries[586] = {586, {}};
  errors.clear();
  EXPECT_TRUE(agv::config::check_can_localize(cfg, &map, &errors));
  map.entries[587] = {587, {}};
  map.entries[1000] = {1000, {}};
  EXPECT_FALSE(agv::config::check_can_localize(cfg, &map, &errors));
  ASSERT_EQ(errors.size(), 1u);
  EXPECT_NE(errors[0].find("2 id(s) above 586 (587, 1000)"), std::string::npos) << errors[0];

  // The QR family carries its pose: no map needed, any map id.
  cfg.vision.family = agv::LandmarkFamily::kQr;
  errors.clear();
  EXPECT_TRUE(agv::config::check_can_localize(cfg, nullptr, &errors));
  EXPECT_TRUE(agv::config::check_can_localize(cfg, &map, &errors));
}

}  // namespace
