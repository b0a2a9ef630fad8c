// What agvloc-overhead refuses before it would publish to or subscribe to an MQTT topic built from
// it: wildcards, separators, NUL and control characters, text that is not UTF-8, empty and
// overlong parts, the broker's '$' topics (overhead/src/topics.hpp, docs/guide/overhead.md).
#include <gtest/gtest.h>

#include <string>
#include <vector>

#include "config.hpp"
#include "detect.hpp"
#include "inputs.hpp"

namespace agv::overhead_app {
namespace {

std::vector<std::string> errors_of(const std::string& text) {
  OverheadConfig cfg;
  std::vector<std::string> errors;
  parse_config(text, &cfg, &errors);
  return errors;
}

std::string mqtt_key(const std::string& leaf, const std::string& value) {
  return "output:\n  mqtt:\n    " + leaf + ": " + value + "\n";
}

std::string prefix_key(const std::string& value) {
  return "detections:\n  topic_prefix: " + value + "\n";
}

// One error, naming the key and saying why.
void expect_refused(const std::string& text, const std::string& key, const std::string& why) {
  const std::vector<std::string> e = errors_of(text);
  ASSERT_EQ(e.size(), 1u) << text;
  EXPECT_NE(e[0].find(key), std::string::npos) << e[0];
  EXPECT_NE(e[0].find(why), std::string::npos) << e[0];
}

// Values no part of a topic may have, as YAML scalars, and the word of the error.
const std::vector<std::pair<std::string, std::string>> kBadParts = {
    {"\"+\"", "wildcard '+'"},
    {"\"#\"", "wildcard '#'"},
    {"\"site+7\"", "wildcard '+'"},
    {"\"\"", "empty"},
    {"\"a\\0b\"", "NUL"},
    {"\"a\\nb\"", "control"},
    {"\"a\\x85b\"", "control"},  // U+0085, a C1 control
    {std::string(257, 'a'), "257 bytes, more than 256"},
};

TEST(OverheadTopics, TopicLevelKeysRefuseWhatATopicLevelCannotCarry) {
  for (const char* leaf : {"interface_name", "manufacturer"}) {
    const std::string key = std::string("output.mqtt.") + leaf;
    for (const auto& [value, why] : kBadParts) expect_refused(mqtt_key(leaf, value), key, why);
    expect_refused(mqtt_key(leaf, "a/b"), key, "'/'");
    expect_refused(mqtt_key(leaf,
                            "Halle-S\xfc"
                            "d"),
                   key, "UTF-8");
    EXPECT_TRUE(errors_of(mqtt_key(leaf, std::string(256, 'a'))).empty()) << leaf;
    EXPECT_TRUE(errors_of(mqtt_key(leaf,
                                   "Halle-S\xc3\xbc"
                                   "d"))
                    .empty());
  }
  expect_refused(mqtt_key("interface_name", "\"$SYS\""), "output.mqtt.interface_name", "'$'");
  EXPECT_TRUE(errors_of(mqtt_key("manufacturer", "\"$acme\"")).empty());  // not the first level
}

TEST(OverheadTopics, DetectionsPrefixRefusesWildcardsEmptyLevelsAndBrokerTopics) {
  const std::string key = "detections.topic_prefix";
  for (const auto& [value, why] : kBadParts) expect_refused(prefix_key(value), key, why);
  for (const char* value : {"site/+/x", "site/#", "\"+/x\""})
    expect_refused(prefix_key(value), key, "wildcard");
  for (const char* value : {"a//b", "/a", "a/", "\"/\""})
    expect_refused(prefix_key(value), key, "empty topic level");
  expect_refused(prefix_key("\"$SYS/x\""), key, "'$'");
  // 4 levels of 255 bytes and 3 separators: 1023 bytes, accepted; one more byte is refused.
  const std::string level(255, 'p');
  const std::string longest = level + "/" + level + "/" + level + "/" + level;
  EXPECT_TRUE(errors_of(prefix_key(longest)).empty());
  expect_refused(prefix_key(longest + "pp"), key, "1025 bytes, more than 1024");
  for (const char* value : {"site-7", "plant/hall-2", "a/b/c"})
    EXPECT_TRUE(errors_of(prefix_key(value)).empty()) << value;
}

TEST(OverheadTopics, EveryProblemOfTheFileIsReported) {
  EXPECT_EQ(errors_of("output:\n  mqtt:\n    interface_name: \"#\"\n    manufacturer: a/b\n"
                      "detections:\n  topic_prefix: \"+\"\n")
                .size(),
            3u);
}

TEST(OverheadTopics, TheTrackerSubscribesToOneWildcardOnly) {
  OverheadConfig cfg;
  cfg.detections.topic_prefix = "plant/hall-2";
  EXPECT_EQ(detections_subscription(cfg), "plant/hall-2/detections/+");
  EXPECT_EQ(detections_topic(cfg, "cam-west"), "plant/hall-2/detections/cam-west");
}

site::Site two_ids(const std::string& agv, const std::string& camera) {
  site::Site s;
  s.fleet.resize(1);
  s.fleet[0].id = agv;
  s.cameras.resize(1);
  s.cameras[0].id = camera;
  return s;
}

TEST(OverheadTopics, SiteIdsInTopicsAreTopicLevels) {
  OverheadConfig cfg;
  std::string err;
  // Without MQTT and without the detections bus no id reaches a topic.
  EXPECT_TRUE(check_site_topic_ids(cfg, two_ids("agv+1", "cam/1"), false, &err)) << err;
  cfg.mqtt.enabled = true;
  EXPECT_FALSE(check_site_topic_ids(cfg, two_ids("agv+1", "cam-1"), false, &err));
  EXPECT_NE(err.find("site fleet[0].id: 'agv+1'"), std::string::npos) << err;
  EXPECT_NE(err.find("wildcard '+'"), std::string::npos) << err;
  EXPECT_FALSE(check_site_topic_ids(cfg, two_ids("agv-1", "cam#1"), false, &err));
  EXPECT_NE(err.find("site cameras[0].id"), std::string::npos) << err;
  EXPECT_FALSE(check_config_against_site(cfg, two_ids("agv/1", "cam-1"), &err));
  EXPECT_NE(err.find("site fleet[0].id"), std::string::npos) << err;
  EXPECT_TRUE(check_site_topic_ids(cfg, two_ids("agv-1", std::string(65, 'c')), false, &err))
      << err;
}

TEST(OverheadTopics, DetectionsBusCameraIdsFitTheMessage) {
  OverheadConfig cfg;  // output.mqtt.enabled false: the bus alone
  std::string err;
  EXPECT_FALSE(check_site_topic_ids(cfg, two_ids("agv+1", "cam#1"), true, &err));
  EXPECT_NE(err.find("site cameras[0].id: 'cam#1'"), std::string::npos) << err;
  EXPECT_FALSE(check_site_topic_ids(cfg, two_ids("agv-1", std::string(65, 'c')), true, &err));
  EXPECT_NE(err.find("65 bytes, more than the 64"), std::string::npos) << err;
  EXPECT_TRUE(check_site_topic_ids(cfg, two_ids("agv+1", std::string(64, 'c')), true, &err))
      << err;
}

}  // namespace
}  // namespace agv::overhead_app
