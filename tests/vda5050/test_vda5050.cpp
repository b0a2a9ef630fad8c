// The VDA 5050 encoder and the health / sigma mapping (docs/guide/vda5050.md "Field mapping").
#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <nlohmann/json.hpp>

#include "agv/localizer/localizer.hpp"
#include "agv/vda5050/vda5050.hpp"
#include "vda_test_util.hpp"

namespace agv::vda5050 {
namespace {

using nlohmann::json;

constexpr double kNan = std::numeric_limits<double>::quiet_NaN();
constexpr double kInf = std::numeric_limits<double>::infinity();

localizer::TickRecord tick(fusion::HealthState h, protocol::Health s, double sigma_mm) {
  localizer::TickRecord t;
  t.t_ns = 1'795'810'219'123'456'789;
  t.estimate.valid = h != fusion::HealthState::kUninitialized;
  t.estimate.health = h;
  t.estimate.pose = {1234.5, -678.9, 3.0};
  t.estimate.v_mps = 0.75;
  t.estimate.omega_radps = -0.125;
  t.estimate.position_sigma_mm = sigma_mm;
  t.status.health = s;
  return t;
}

using test::ident;

TEST(Vda5050Mapping, LocalizedMapsSigmaToDeviationAndScore) {
  const Position p = map_tick(tick(fusion::HealthState::kLocalized, protocol::Health::kOk, 2.0));
  EXPECT_TRUE(p.initialized);
  EXPECT_DOUBLE_EQ(p.x_m, 1.2345);
  EXPECT_DOUBLE_EQ(p.y_m, -0.6789);
  EXPECT_DOUBLE_EQ(p.deviation_range_m, 0.006);  // 3 sigma in m
  EXPECT_NEAR(p.localization_score, 1.0 - 6.0 / kScoreZeroAtDeviationMm, 1e-12);
  EXPECT_DOUBLE_EQ(p.vx_mps, 0.75);
  EXPECT_DOUBLE_EQ(p.vy_mps, 0.0);
  EXPECT_DOUBLE_EQ(p.omega_radps, -0.125);
}

TEST(Vda5050Mapping, ScoreFallsToZeroAtTheLimitAndIsCappedWhenDeadReckoning) {
  EXPECT_DOUBLE_EQ(map_tick(tick(fusion::HealthState::kLocalized, protocol::Health::kOk, 40.0))
                       .localization_score,
                   0.0);
  const Position dr =
      map_tick(tick(fusion::HealthState::kDeadReckoning, protocol::Health::kDegraded, 1.0));
  EXPECT_TRUE(dr.initialized);
  EXPECT_DOUBLE_EQ(dr.localization_score, kDeadReckoningScoreCap);
}

TEST(Vda5050Mapping, LostUninitialisedOrFaultIsNotInitialized) {
  for (const auto& t : {tick(fusion::HealthState::kLost, protocol::Health::kLost, 5.0),
                        tick(fusion::HealthState::kUninitialized, protocol::Health::kLost, 0.0),
                        tick(fusion::HealthState::kLocalized, protocol::Health::kFault, 1.0),
                        tick(fusion::HealthState::kLocalized, protocol::Health::kOk, kNan)}) {
    const Position p = map_tick(t);
    EXPECT_FALSE(p.initialized);
    EXPECT_EQ(p.localization_score, 0.0);
    EXPECT_LT(p.deviation_range_m, 0.0);  // omitted
  }
}

TEST(Vda5050Mapping, ThetaWrappedIntoTheSchemaRange) {
  auto t = tick(fusion::HealthState::kLocalized, protocol::Health::kOk, 1.0);
  t.estimate.pose.theta_rad = 3.0 * M_PI / 2.0;
  EXPECT_NEAR(map_tick(t).theta_rad, -M_PI / 2.0, 1e-12);
}

// initPosition's sigma comes from the configured lost limits (half of them), not a constant.
TEST(Vda5050InitPosition, SigmaIsHalfTheConfiguredLostLimits) {
  fusion::EkfConfig f;
  const localizer::InitPositionSigma d = localizer::init_position_sigma(f);
  EXPECT_DOUBLE_EQ(d.position_mm, 0.5 * f.health.lost_position_sigma_mm);
  EXPECT_DOUBLE_EQ(d.heading_rad, 0.5 * f.health.lost_heading_sigma_rad);
  f.health.lost_position_sigma_mm = 80.0;
  f.health.lost_heading_sigma_rad = 0.1;
  const localizer::InitPositionSigma c = localizer::init_position_sigma(f);
  EXPECT_DOUBLE_EQ(c.position_mm, 40.0);
  EXPECT_DOUBLE_EQ(c.heading_rad, 0.05);
}

// Drives 1 m/s straight with odometry at 100 Hz after placing the pose at t = 0; returns the
// number of 10 ms ticks with PoseValid before the first LOST one (n_ticks if none).
int valid_ticks_after_placing(bool init_position, double sigma_mm, double sigma_rad, int n_ticks) {
  constexpr std::int64_t kMs = 1'000'000;
  localizer::LocalizerConfig c;
  localizer::Localizer loc(c);
  localizer::TickRecord rec;
  std::int64_t t = 1000 * kMs;
  for (int i = 0; i < 20; ++i) {
    loc.on_odometry(t, 1.0, 0.0);
    rec = loc.tick(t += 10 * kMs);
  }
  const Pose2 placed{1000.0, 2000.0, 0.5};
  const bool ok =
      init_position ? loc.init_position(t, placed) : loc.set_pose(t, placed, sigma_mm, sigma_rad);
  EXPECT_TRUE(ok);
  for (int i = 0; i < n_ticks; ++i) {
    loc.on_odometry(t, 1.0, 0.0);
    rec = loc.tick(t += 10 * kMs);
    if (!rec.pose_valid) {
      EXPECT_EQ(rec.status.health, protocol::Health::kLost);
      return i;
    }
  }
  return n_ticks;
}

TEST(Vda5050InitPosition, PoseStaysValidWhileDrivingUntilSigmaGrowsPastTheLimit) {
  const fusion::EkfConfig f;
  // The old constant, the default limit itself: LOST on the first ticks of driving.
  EXPECT_LT(valid_ticks_after_placing(false, f.health.lost_position_sigma_mm,
                                      f.health.lost_heading_sigma_rad, 100),
            5);
  // initPosition: valid for at least 1 s of driving at 1 m/s without a landmark.
  EXPECT_EQ(valid_ticks_after_placing(true, 0.0, 0.0, 100), 100);
}

TEST(Vda5050Time, Iso8601UtcWithMilliseconds) {
  EXPECT_EQ(iso8601_utc_ms(0), "1970-01-01T00:00:00.000Z");
  EXPECT_EQ(iso8601_utc_ms(1'795'810'219'123'456'789), "2026-11-27T20:10:19.123Z");
  EXPECT_EQ(iso8601_utc_ms(951'782'400'999'999'999), "2000-02-29T00:00:00.999Z");  // leap day
  EXPECT_EQ(iso8601_utc_ms(-5), "1970-01-01T00:00:00.000Z");
}

TEST(Vda5050Topic, LayoutOfTheSpecification) {
  EXPECT_EQ(topic(ident(Version::k2_1_0), "visualization"), "uagv/v2/acme/agv-7/visualization");
  EXPECT_EQ(topic(ident(Version::k3_0_0), "connection"), "uagv/v3/acme/agv-7/connection");
}

TEST(Vda5050Encode, Visualization21) {
  const Identity id = ident(Version::k2_1_0);
  const Position p = map_tick(tick(fusion::HealthState::kLocalized, protocol::Health::kOk, 2.0));
  const json m = json::parse(encode_visualization(id, 41, 1'795'810'219'123'456'789, p, 0));
  EXPECT_EQ(m["headerId"], 41);
  EXPECT_EQ(m["timestamp"], "2026-11-27T20:10:19.123Z");
  EXPECT_EQ(m["version"], "2.1.0");
  EXPECT_EQ(m["manufacturer"], "acme");
  EXPECT_EQ(m["serialNumber"], "agv-7");
  EXPECT_FALSE(m.contains("referenceStateHeaderId"));
  const json& a = m["agvPosition"];
  EXPECT_EQ(a["mapId"], "hall-1");
  EXPECT_EQ(a["positionInitialized"], true);
  EXPECT_DOUBLE_EQ(a["x"].get<double>(), 1.2345);
  EXPECT_DOUBLE_EQ(a["deviationRange"].get<double>(), 0.006);
  EXPECT_DOUBLE_EQ(m["velocity"]["vx"].get<double>(), 0.75);
}

TEST(Vda5050Encode, Visualization30RenamesAndReferencesState) {
  const Identity id = ident(Version::k3_0_0);
  const Position p = map_tick(tick(fusion::HealthState::kLost, protocol::Health::kLost, 2.0));
  const json m = json::parse(encode_visualization(id, 0, 0, p, 7));
  EXPECT_EQ(m["version"], "3.0.0");
  EXPECT_EQ(m["referenceStateHeaderId"], 7);
  EXPECT_FALSE(m.contains("agvPosition"));
  EXPECT_EQ(m["mobileRobotPosition"]["localized"], false);
  EXPECT_FALSE(m["mobileRobotPosition"].contains("deviationRange"));
}

TEST(Vda5050Encode, NonFiniteNumbersNeverReachTheJson) {
  Position p;
  p.x_m = kNan;
  p.y_m = kInf;
  p.theta_rad = kNan;
  p.vx_mps = kNan;
  p.localization_score = kNan;
  p.deviation_range_m = kNan;
  const json m = json::parse(encode_visualization(ident(Version::k2_1_0), 0, 0, p, 0));
  EXPECT_EQ(m["agvPosition"]["x"], 0.0);
  EXPECT_EQ(m["agvPosition"]["y"], 0.0);
  EXPECT_EQ(m["velocity"]["vx"], 0.0);
  EXPECT_FALSE(m["agvPosition"].contains("deviationRange"));
}

TEST(Vda5050Encode, ConnectionStatesPerVersion) {
  EXPECT_EQ(json::parse(encode_connection(ident(Version::k2_1_0), 3, 0,
                                          ConnectionState::kConnectionBroken))["connectionState"],
            "CONNECTIONBROKEN");
  EXPECT_EQ(json::parse(encode_connection(ident(Version::k3_0_0), 3, 0,
                                          ConnectionState::kConnectionBroken))["connectionState"],
            "CONNECTION_BROKEN");
  EXPECT_EQ(json::parse(encode_connection(ident(Version::k2_1_0), 3, 0,
                                          ConnectionState::kOnline))["connectionState"],
            "ONLINE");
  EXPECT_EQ(json::parse(encode_connection(ident(Version::k2_1_0), 3, 0,
                                          ConnectionState::kOffline))["connectionState"],
            "OFFLINE");
}

TEST(Vda5050Encode, StateAnswersInstantActionsWhereEachVersionWantsThem) {
  const std::vector<ActionResult> r = {
      {"a1", "initPosition", ActionStatus::kFinished, ""},
      {"a2", "initPosition", ActionStatus::kFailed, "unknown_map"}};
  const json s21 = json::parse(encode_state(ident(Version::k2_1_0), 0, 0, Position{}, r));
  ASSERT_EQ(s21["actionStates"].size(), 2u);
  EXPECT_EQ(s21["actionStates"][0]["actionStatus"], "FINISHED");
  EXPECT_EQ(s21["actionStates"][1]["resultDescription"], "unknown_map");
  const json s30 = json::parse(encode_state(ident(Version::k3_0_0), 0, 0, Position{}, r));
  EXPECT_TRUE(s30["actionStates"].empty());
  EXPECT_EQ(s30["instantActionStates"][1]["actionStatus"], "FAILED");
}

// errors[]: none by default; each entry with its type, level, description and references.
TEST(Vda5050Encode, StateCarriesErrors) {
  EXPECT_TRUE(
      json::parse(encode_state(ident(Version::k2_1_0), 0, 0, Position{}, {}))["errors"].empty());
  const std::vector<StateError> e = {
      {"cameraFault", "WARNING", "camera cam-1: disconnected", {{"cameraId", "cam-1"}}}};
  const json s = json::parse(encode_state(ident(Version::k2_1_0), 3, 0, Position{}, {}, e));
  ASSERT_EQ(s["errors"].size(), 1u);
  EXPECT_EQ(s["errors"][0]["errorType"], "cameraFault");
  EXPECT_EQ(s["errors"][0]["errorLevel"], "WARNING");
  EXPECT_EQ(s["errors"][0]["errorDescription"], "camera cam-1: disconnected");
  EXPECT_EQ(s["errors"][0]["errorReferences"][0]["referenceKey"], "cameraId");
  EXPECT_EQ(s["errors"][0]["errorReferences"][0]["referenceValue"], "cam-1");
  EXPECT_EQ(s["headerId"], 3);
}

TEST(Vda5050Version, OnlyTheThreeReleases) {
  Version v;
  EXPECT_TRUE(parse_version("3.0.0", &v));
  EXPECT_EQ(v, Version::k3_0_0);
  EXPECT_TRUE(parse_version("2.0.0", &v));
  EXPECT_EQ(v, Version::k2_0_0);
  EXPECT_FALSE(parse_version("2.0", &v));
  EXPECT_FALSE(parse_version("1.1.0", &v));
  EXPECT_FALSE(parse_version("2.2.0", &v));
  EXPECT_STREQ(version_string(Version::k2_1_0), "2.1.0");
  EXPECT_STREQ(version_string(Version::k2_0_0), "2.0.0");
}

// 2.0.0's schemas have every field agvloc sends (the 2.0 / 2.1 differences are in fields it does
// not send), so the messages are 2.1.0's with the other version and the same v2 topics.
TEST(Vda5050Encode, Version2_0_0IsVersion2_1_0WithItsVersionString) {
  Position p;
  p.x_m = 1.5;
  p.initialized = true;
  const std::vector<ActionResult> r = {{"a1", "initPosition", ActionStatus::kFinished, ""}};
  const Identity a = ident(Version::k2_0_0), b = ident(Version::k2_1_0);
  const json pairs[][2] = {
      {json::parse(encode_visualization(a, 4, 0, p, 0)),
       json::parse(encode_visualization(b, 4, 0, p, 0))},
      {json::parse(encode_connection(a, 4, 0, ConnectionState::kConnectionBroken)),
       json::parse(encode_connection(b, 4, 0, ConnectionState::kConnectionBroken))},
      {json::parse(encode_state(a, 4, 0, p, r)), json::parse(encode_state(b, 4, 0, p, r))}};
  for (const auto& pair : pairs) {
    EXPECT_EQ(pair[0]["version"], "2.0.0");
    json same = pair[0];
    same["version"] = "2.1.0";
    EXPECT_EQ(same, pair[1]);
  }
  EXPECT_EQ(topic(a, "state"), "uagv/v2/acme/agv-7/state");
}

}  // namespace
}  // namespace agv::vda5050
