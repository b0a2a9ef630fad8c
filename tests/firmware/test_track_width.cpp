// The track width is one fact: the key can.odometry.track_width_mm reaches the CAN wheel-speed
// decoding, the unequal-wheels correction and the fusion's slip lever arm alike.
#include <gtest/gtest.h>

#include <string>
#include <vector>

#include "agv/config/config.hpp"
#include "agv/config/keys.hpp"
#include "output_loop.hpp"

namespace {

const char* kIntrinsics = "intrinsics: {fx: 769.23, fy: 769.23, cx: 319.5, cy: 239.5}\n";

bool mentions(const std::vector<std::string>& errors, const std::string& what) {
  for (const auto& e : errors) {
    if (e.find(what) != std::string::npos) return true;
  }
  return false;
}

}  // namespace

TEST(TrackWidth, OneKeyGivesTheDecoderAndTheFusionTheSameLeverArm) {
  agv::config::Config cfg;
  std::vector<std::string> errors;
  ASSERT_TRUE(agv::config::parse_config(std::string(kIntrinsics) +
                                            "can:\n  odometry:\n    mode: wheels\n"
                                            "    track_width_mm: 700\n",
                                        "", &cfg, &errors));
  const agv::localizer::LocalizerConfig lc = agv::app::localizer_config(cfg);
  EXPECT_DOUBLE_EQ(lc.protocol.odometry.track_width_mm, 700.0);  // wheel speeds -> v, omega
  EXPECT_DOUBLE_EQ(lc.fusion.slip.wheel_track_mm, 700.0);             // a slip's speed error
}

TEST(TrackWidth, TheFusionsOwnKeyIsRemovedNamingTheOne) {
  agv::config::Config cfg;
  std::vector<std::string> errors;
  EXPECT_FALSE(agv::config::parse_config(
      std::string(kIntrinsics) + "fusion:\n  wheel_track_mm: 700\n", "", &cfg, &errors));
  EXPECT_TRUE(
      mentions(errors, "fusion.wheel_track_mm: removed key; use can.odometry.track_width_mm"));
  EXPECT_EQ(agv::config::find_key("fusion.wheel_track_mm"), nullptr);
}
