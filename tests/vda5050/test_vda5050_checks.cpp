// What the configuration checker refuses so that the publisher never meets it (a string JSON
// cannot carry, a topic level MQTT cannot publish to, a broker host that can never resolve, a
// non-loopback page without allow_remote), the encoder's defence when a string slips through, and
// the log escaping of bytes from the network (docs/guide/vda5050.md, docs/design/security.md).
#include <gtest/gtest.h>

#include <string>
#include <vector>

#include "agv/common/log_escape.hpp"
#include "agv/config/config.hpp"
#include "agv/vda5050/vda5050.hpp"
#include "vda_test_util.hpp"

namespace agv {
namespace {

// The errors parse_config gives for a configuration with only this vda5050 / diag text.
std::vector<std::string> errors_of(const std::string& yaml) {
  config::Config cfg;
  std::vector<std::string> errors;
  config::parse_config(yaml, "", &cfg, &errors, config::ConfigUse::kReplay);
  return errors;
}

bool names(const std::vector<std::string>& errors, const std::string& key) {
  for (const auto& e : errors) {
    if (e.find(key) != std::string::npos) return true;
  }
  return false;
}

std::string vda(const std::string& key, const std::string& value) {
  return "vda5050:\n  enabled: true\n  " + key + ": " + value + "\n";
}

TEST(Vda5050ConfigCheck, DefaultsPass) {
  EXPECT_TRUE(errors_of("vda5050:\n  enabled: true\n").empty());
}

TEST(Vda5050ConfigCheck, RefusesStringsThatAreNotUtf8) {
  // Latin-1 "Halle-Süd" as a file saved in the wrong encoding has it.
  for (const char* key :
       {"map_id", "manufacturer", "serial_number", "interface_name", "username"}) {
    const auto e = errors_of(vda(key,
                                 "Halle-S\xfc"
                                 "d"));
    EXPECT_TRUE(names(e, std::string("vda5050.") + key)) << key;
  }
  EXPECT_TRUE(errors_of(vda("map_id",
                            "Halle-S\xc3\xbc"
                            "d"))
                  .empty());  // UTF-8: fine
}

TEST(Vda5050ConfigCheck, RefusesMqttWildcardsAndSeparatorsInTopicLevels) {
  for (const char* key : {"serial_number", "manufacturer", "interface_name"}) {
    for (const char* value :
         {"\"+\"", "\"#\"", "a/b", "\"a+b\"", "\"\"", "\"a\\0b\"", "\"a\\nb\""}) {
      EXPECT_TRUE(names(errors_of(vda(key, value)), std::string("vda5050.") + key))
          << key << " " << value;
    }
  }
  EXPECT_TRUE(errors_of(vda("serial_number", "AGV_7.a:b-c")).empty());
}

TEST(Vda5050ConfigCheck, RefusesC1ControlsInTopicLevelsAndABrokerTopicAsFirstLevel) {
  for (const char* key : {"serial_number", "manufacturer", "interface_name"}) {
    EXPECT_TRUE(names(errors_of(vda(key, "\"a\\x85b\"")), std::string("vda5050.") + key)) << key;
  }
  const auto e = errors_of(vda("interface_name", "\"$SYS\""));
  ASSERT_TRUE(names(e, "vda5050.interface_name"));
  EXPECT_TRUE(names(e, "'$'"));
  EXPECT_TRUE(errors_of(vda("serial_number", "\"$agv-1\"")).empty());  // not the first level
}

TEST(Vda5050ConfigCheck, RefusesIdsLongerThanAnInstantActionMayCarry) {
  EXPECT_TRUE(
      names(errors_of(vda("serial_number", std::string(257, 'a'))), "vda5050.serial_number"));
  EXPECT_TRUE(names(errors_of(vda("map_id", std::string(257, 'm'))), "vda5050.map_id"));
  EXPECT_TRUE(errors_of(vda("serial_number", std::string(256, 'a'))).empty());
}

TEST(Vda5050ConfigCheck, RefusesABrokerHostThatCanNeverResolve) {
  EXPECT_TRUE(names(errors_of(vda("broker_host", "\"\"")), "vda5050.broker_host"));
  EXPECT_TRUE(names(errors_of(vda("broker_host", std::string(10000, 'h'))), "vda5050.broker_host"));
  EXPECT_TRUE(names(errors_of(vda("broker_host", "\"a b\"")), "vda5050.broker_host"));
  EXPECT_TRUE(errors_of(vda("broker_host", std::string(255, 'h'))).empty());
  EXPECT_TRUE(errors_of(vda("broker_host", "\"::1\"")).empty());
}

TEST(DiagConfigCheck, NonLoopbackAddressNeedsAllowRemote) {
  const auto e = errors_of("diag:\n  bind_address: 0.0.0.0\n");
  ASSERT_TRUE(names(e, "diag.bind_address"));
  EXPECT_TRUE(names(e, "allow_remote"));
  EXPECT_TRUE(errors_of("diag:\n  bind_address: 0.0.0.0\n  allow_remote: true\n").empty());
  for (const char* a : {"127.0.0.1", "127.1.2.3", "::1", "localhost"}) {
    EXPECT_TRUE(errors_of(std::string("diag:\n  bind_address: \"") + a + "\"\n").empty()) << a;
  }
}

TEST(Vda5050Encode, AStringThatIsNotUtf8NeverThrows) {
  vda5050::Identity id = vda5050::test::ident();
  id.map_id =
      "Halle-S\xfc"
      "d";
  id.serial_number = "\xff\xfe";
  std::string text;
  ASSERT_NO_THROW(text = vda5050::encode_connection(id, 1, 0, vda5050::ConnectionState::kOnline));
  ASSERT_NO_THROW(text = vda5050::encode_visualization(id, 1, 0, {}, 0));
  EXPECT_NE(text.find("Halle-S\xef\xbf\xbd"
                      "d"),
            std::string::npos)
      << text;  // U+FFFD
  ASSERT_NO_THROW(
      text = vda5050::encode_state(
          id, 1, 0, {}, {{"a\xc0", "initPosition", vda5050::ActionStatus::kFinished, ""}}));
  EXPECT_TRUE(is_valid_utf8(text));
}

TEST(LogEscape, ControlCharactersAndMalformedUtf8BecomeHex) {
  // A forged journal line and an ANSI sequence that would recolour the terminal.
  EXPECT_EQ(escape_for_log("id\nagvloc: forged\x1b[31m"), "id\\x0aagvloc: forged\\x1b[31m");
  EXPECT_EQ(escape_for_log("a\\b"), "a\\\\b");
  EXPECT_EQ(escape_for_log(std::string("a\0b\x7f", 4)), "a\\x00b\\x7f");
  EXPECT_EQ(escape_for_log("S\xfc"
                           "d"),
            "S\\xfcd");
  EXPECT_EQ(escape_for_log("S\xc3\xbc"
                           "d \xe2\x82\xac"),
            "S\xc3\xbc"
            "d \xe2\x82\xac");  // kept
  EXPECT_EQ(escape_for_log("\xc2\x9b"
                           "31m"),
            "\\xc2\\x9b31m");                                    // C1 CSI
  EXPECT_EQ(escape_for_log("\xc0\xaf"), "\\xc0\\xaf");           // overlong '/'
  EXPECT_EQ(escape_for_log("\xed\xa0\x80"), "\\xed\\xa0\\x80");  // a surrogate
  EXPECT_EQ(escape_for_log("\xe2\x82"), "\\xe2\\x82");           // truncated
  EXPECT_EQ(escape_for_log(std::string(300, 'a'), 256), std::string(256, 'a') + "...");
}

TEST(LogEscape, Utf8Validation) {
  EXPECT_TRUE(is_valid_utf8(""));
  EXPECT_TRUE(is_valid_utf8("plain \xf0\x9f\x9a\x97"));
  EXPECT_FALSE(is_valid_utf8("\xf4\x90\x80\x80"));  // beyond U+10FFFF
  EXPECT_FALSE(is_valid_utf8("\x80"));
  EXPECT_FALSE(is_valid_utf8("\xf5\x80\x80\x80"));
}

}  // namespace
}  // namespace agv
