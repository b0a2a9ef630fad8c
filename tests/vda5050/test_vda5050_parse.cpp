// The instantActions parser: initPosition accepted, every malformed or hostile case refused with
// its named reason (docs/guide/vda5050.md "initPosition"; fuzzed by fuzz/fuzz_vda_action.cpp).
#include <gtest/gtest.h>

#include <string>

#include "agv/vda5050/vda5050.hpp"
#include "vda_test_util.hpp"

namespace agv::vda5050 {
namespace {

using test::ident;

std::string header(const std::string& version = "2.1.0", const std::string& serial = "agv-7") {
  return R"("headerId": 5, "timestamp": "2026-01-01T00:00:00.000Z", "version": ")" + version +
         R"(", "manufacturer": "acme", "serialNumber": ")" + serial + "\"";
}

std::string init(const std::string& params, const std::string& type = "initPosition") {
  return R"({"actionId": "a1", "actionType": ")" + type +
         R"(", "blockingType": "NONE", "actionParameters": [)" + params + "]}";
}

const std::string kGood =
    R"({"key": "x", "value": 5.0}, {"key": "y", "value": -3}, {"key": "theta", "value": 1.5},
       {"key": "mapId", "value": "hall-1"}, {"key": "lastNodeId", "value": "n7"})";

std::string message(const std::string& actions, const std::string& hdr = header()) {
  return "{" + hdr + R"(, "actions": [)" + actions + "]}";
}

TEST(Vda5050Parse, AcceptsInitPosition) {
  const ParsedActions p = parse_instant_actions(ident(), message(init(kGood)));
  ASSERT_EQ(p.message_reason, Reason::kNone);
  ASSERT_EQ(p.accepted.size(), 1u);
  EXPECT_EQ(p.accepted[0].action_id, "a1");
  EXPECT_DOUBLE_EQ(p.accepted[0].x_m, 5.0);
  EXPECT_DOUBLE_EQ(p.accepted[0].y_m, -3.0);
  EXPECT_DOUBLE_EQ(p.accepted[0].theta_rad, 1.5);
  EXPECT_EQ(p.accepted[0].last_node_id, "n7");
  EXPECT_TRUE(p.refused.empty());
}

TEST(Vda5050Parse, Version3UsesInitializePosition) {
  const ParsedActions p = parse_instant_actions(
      ident(Version::k3_0_0), message(init(kGood, "initializePosition"), header("3.0.0")));
  ASSERT_EQ(p.accepted.size(), 1u);
  // 2.1.0's name in a 3.0.0 message is not ours: left to the vehicle controller.
  const ParsedActions q =
      parse_instant_actions(ident(Version::k3_0_0), message(init(kGood), header("3.0.0")));
  EXPECT_TRUE(q.accepted.empty());
  EXPECT_EQ(q.not_ours, 1u);
}

// vda-5050-lib 1.4.0's master control sends 2.0.0 instant actions under `instantActions`.
TEST(Vda5050Parse, Version2_0_0AlsoReadsTheInstantActionsKey) {
  const std::string lib = "{" + header("2.0.0") + R"(, "instantActions": [)" + init(kGood) + "]}";
  const ParsedActions p = parse_instant_actions(ident(Version::k2_0_0), lib);
  ASSERT_EQ(p.message_reason, Reason::kNone);
  ASSERT_EQ(p.accepted.size(), 1u);
  EXPECT_DOUBLE_EQ(p.accepted[0].x_m, 5.0);
  EXPECT_EQ(parse_instant_actions(ident(Version::k2_0_0), message(init(kGood), header("2.0.0")))
                .accepted.size(),
            1u);
  // The key of the document wins where both are there; other versions read only `actions`.
  const std::string both =
      "{" + header("2.0.0") + R"(, "actions": [], "instantActions": [)" + init(kGood) + "]}";
  EXPECT_TRUE(parse_instant_actions(ident(Version::k2_0_0), both).accepted.empty());
  EXPECT_EQ(parse_instant_actions(ident(), lib).message_reason, Reason::kMissingField);
}

TEST(Vda5050Parse, OtherActionsAreTheVehicleControllers) {
  const ParsedActions p = parse_instant_actions(
      ident(), message(R"({"actionId": "p", "actionType": "startPause", "blockingType": "HARD"},)" +
                       init(kGood)));
  EXPECT_EQ(p.not_ours, 1u);
  EXPECT_EQ(p.accepted.size(), 1u);
}

struct MessageCase {
  const char* name;
  std::string text;
  Reason reason;
};

TEST(Vda5050Parse, RefusesMalformedMessagesWithTheirReason) {
  const std::vector<MessageCase> cases = {
      {"not json", "{\"headerId\": ", Reason::kNotJson},
      {"empty", "", Reason::kNotJson},
      {"array", "[1, 2]", Reason::kNotObject},
      {"no header", R"({"actions": []})", Reason::kMissingField},
      {"headerId string", R"({"headerId": "5", "timestamp": "t", "version": "2.1.0",
        "manufacturer": "acme", "serialNumber": "agv-7", "actions": []})",
       Reason::kWrongType},
      {"other major", message(init(kGood), header("3.0.0")), Reason::kWrongVersion},
      {"other vehicle", message(init(kGood), header("2.1.0", "agv-8")), Reason::kWrongTarget},
      {"no actions", "{" + header() + "}", Reason::kMissingField},
      {"actions object", "{" + header() + R"(, "actions": {}})", Reason::kWrongType},
      {"action not object", message("42"), Reason::kWrongType},
      // The JSON parser refuses a number beyond double (kNonFinite stays as a second guard).
      {"overflow", message(init(R"({"key": "x", "value": 1e999})")), Reason::kNotJson},
      {"deep", std::string(100, '[') + std::string(100, ']'), Reason::kTooDeep},
      {"huge", "\"" + std::string(kMaxMessageBytes, 'a') + "\"", Reason::kTooLarge},
  };
  for (const MessageCase& c : cases) {
    const ParsedActions p = parse_instant_actions(ident(), c.text);
    EXPECT_EQ(p.message_reason, c.reason) << c.name << ": got " << reason_name(p.message_reason);
    EXPECT_TRUE(p.accepted.empty()) << c.name;
  }
  std::string many;
  for (std::size_t i = 0; i <= kMaxActions; ++i) many += (i ? "," : "") + init(kGood);
  EXPECT_EQ(parse_instant_actions(ident(), message(many)).message_reason, Reason::kTooManyActions);
}

TEST(Vda5050Parse, RefusesBadInitPositionWithTheirReason) {
  const std::string m = R"({"key": "mapId", "value": "hall-1"})";
  const std::vector<MessageCase> cases = {
      {"no parameters",
       R"({"actionId": "a1", "actionType": "initPosition", "blockingType": "NONE"})",
       Reason::kMissingParameter},
      {"no theta", init(R"({"key": "x", "value": 1}, {"key": "y", "value": 1},)" + m),
       Reason::kMissingParameter},
      {"x string",
       init(R"({"key": "x", "value": "1"}, {"key": "y", "value": 1},
                           {"key": "theta", "value": 0},)" +
            m),
       Reason::kWrongType},
      {"x twice",
       init(R"({"key": "x", "value": 1}, {"key": "x", "value": 2},
                          {"key": "y", "value": 1}, {"key": "theta", "value": 0},)" +
            m),
       Reason::kDuplicateParameter},
      {"far",
       init(R"({"key": "x", "value": 1e9}, {"key": "y", "value": 1},
                      {"key": "theta", "value": 0},)" +
            m),
       Reason::kOutOfRange},
      {"theta 4",
       init(R"({"key": "x", "value": 1}, {"key": "y", "value": 1},
                          {"key": "theta", "value": 4},)" +
            m),
       Reason::kOutOfRange},
      {"other map", init(R"({"key": "x", "value": 1}, {"key": "y", "value": 1},
                            {"key": "theta", "value": 0}, {"key": "mapId", "value": "hall-2"})"),
       Reason::kUnknownMap},
      {"parameter not object", init("7"), Reason::kWrongType},
      {"parameter without value", init(R"({"key": "x"})"), Reason::kMissingField},
      {"long id",
       init(R"({"key": "x", "value": 1}, {"key": "y", "value": 1},
                          {"key": "theta", "value": 0}, {"key": "mapId", "value": ")" +
            std::string(kMaxIdChars + 1, 'm') + "\"}"),
       Reason::kStringTooLong},
  };
  for (const MessageCase& c : cases) {
    const ParsedActions p = parse_instant_actions(ident(), message(c.text));
    ASSERT_EQ(p.message_reason, Reason::kNone) << c.name;
    EXPECT_TRUE(p.accepted.empty()) << c.name;
    ASSERT_EQ(p.refused.size(), 1u) << c.name;
    EXPECT_EQ(p.refused[0].status, ActionStatus::kFailed);
    EXPECT_EQ(p.refused[0].result_description, reason_name(c.reason)) << c.name;
  }
}

TEST(Vda5050Parse, EveryReasonHasAName) {
  for (int r = 0; r <= static_cast<int>(Reason::kStringTooLong); ++r) {
    EXPECT_STRNE(reason_name(static_cast<Reason>(r)), "unknown") << r;
  }
}

}  // namespace
}  // namespace agv::vda5050
