// The diagnostics encoders (algo/src/diag): Prometheus text exposition format and the page's JSON.
#include <gtest/gtest.h>

#include <cmath>
#include <initializer_list>
#include <limits>
#include <map>
#include <nlohmann/json.hpp>
#include <set>
#include <sstream>
#include <string>
#include <vector>

#include "agv/diag/diag.hpp"
#include "agv/localizer/can_output.hpp"
#include "agv/protocol/codec.hpp"

namespace agv::diag {
namespace {

// double, not the float INFINITY / NAN macros (-Wdouble-promotion).
constexpr double kInf = std::numeric_limits<double>::infinity();
constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

Snapshot sample_snapshot() {
  Snapshot s;
  s.has_tick = true;
  s.tick.t_ns = 2'500'000'000;
  s.tick.estimate.valid = true;
  s.tick.pose_valid = true;
  s.tick.estimate.pose = {1234.5, -678.25, 0.5};
  s.tick.estimate.cov(0, 0) = 4.0;
  s.tick.estimate.cov(1, 1) = 9.0;
  s.tick.estimate.cov(2, 2) = 1e-6;
  s.tick.estimate.position_sigma_mm = 3.0;
  s.tick.estimate.time_since_fix_ns = 120'000'000;
  s.tick.status.health = protocol::Health::kDegraded;
  s.tick.status.faults = protocol::fault::kCameraStalled | protocol::fault::kImuTimeout;
  s.tick.status.rejections = protocol::reject::kGate;
  s.stats.ticks = 250;
  s.stats.fixes_fused = 17;
  s.stats.fixes_rejected_gate = 2;
  for (std::int64_t v : {500, 1500, 80'000, 900'000, 2'000'000, 3'000'000, 40'000'000}) {
    s.stats.end_to_end_ns.record_ns(v);
  }
  s.stats.period_jitter_ns.record_ns(-5);  // recorded as 0
  s.can_present = true;
  s.can.tx_errors = 3;
  for (int i = 0; i < 3; ++i) {
    vision::LandmarkFix f;
    f.status = i == 1 ? vision::FixStatus::kQrUnreadable : vision::FixStatus::kOk;
    f.landmark_id = 7 + static_cast<std::uint32_t>(i);
    f.vehicle_in_world = {100.0 * i, 5.0, 0.1};
    f.cov_world(0, 0) = 0.25;
    s.fixes.push(fix_entry(f, 1'000'000'000LL * i, 1'000'000'000LL * i + 30'000'000));
  }
  for (int i = 0; i < 5; ++i) {
    localizer::TickRecord t;
    t.t_ns = 100'000'000LL * i;
    t.estimate.valid = i > 0;
    t.estimate.pose = {10.0 * i, 0.0, 0.0};
    s.track.push(track_point(t));
  }
  return s;
}

struct Family {
  std::string type;
  bool help = false;
};

// A line-by-line check of the text format 0.0.4: every sample's family has HELP and TYPE before
// it, names and labels are well formed, values parse; histograms have cumulative buckets ending
// in +Inf equal to _count, and _sum.
void check_prometheus(const std::string& text, std::map<std::string, double>* samples) {
  std::map<std::string, Family> families;
  std::istringstream in(text);
  std::string line;
  ASSERT_FALSE(text.empty());
  ASSERT_EQ(text.back(), '\n');
  std::map<std::string, std::vector<std::pair<double, double>>> buckets;  // family -> (le, count)
  while (std::getline(in, line)) {
    ASSERT_FALSE(line.empty()) << "empty line";
    if (line.rfind("# HELP ", 0) == 0) {
      const std::string name = line.substr(7, line.find(' ', 7) - 7);
      EXPECT_FALSE(families[name].help) << "second HELP for " << name;
      families[name].help = true;
      continue;
    }
    if (line.rfind("# TYPE ", 0) == 0) {
      std::istringstream l(line.substr(7));
      std::string name, type;
      l >> name >> type;
      EXPECT_TRUE(type == "counter" || type == "gauge" || type == "histogram") << line;
      EXPECT_TRUE(families[name].type.empty()) << "second TYPE for " << name;
      families[name].type = type;
      continue;
    }
    ASSERT_NE(line[0], '#') << line;
    const std::size_t sp = line.rfind(' ');
    const std::string series = line.substr(0, sp), value = line.substr(sp + 1);
    const std::string name = series.substr(0, series.find('{'));
    for (char c : name) {
      ASSERT_TRUE(std::isalnum(static_cast<unsigned char>(c)) || c == '_' || c == ':') << line;
    }
    std::string family = name;
    for (const char* suffix : {"_bucket", "_sum", "_count"}) {
      const std::string sfx = suffix;
      if (name.size() > sfx.size() &&
          name.compare(name.size() - sfx.size(), sfx.size(), sfx) == 0 &&
          families.count(name.substr(0, name.size() - sfx.size())) &&
          families[name.substr(0, name.size() - sfx.size())].type == "histogram") {
        family = name.substr(0, name.size() - sfx.size());
      }
    }
    ASSERT_TRUE(families.count(family)) << "sample before its TYPE: " << line;
    EXPECT_TRUE(families[family].help) << line;
    if (families[family].type == "counter") {
      EXPECT_EQ(family.substr(family.size() - 6), "_total") << family;
    }
    double v = 0.0;
    if (value == "+Inf") {
      v = kInf;
    } else if (value == "NaN") {
      v = kNaN;
    } else {
      std::size_t used = 0;
      v = std::stod(value, &used);
      ASSERT_EQ(used, value.size()) << line;
    }
    if (series.find('{') != std::string::npos) {
      ASSERT_EQ(series.back(), '}') << line;
      const std::string labels = series.substr(series.find('{') + 1);
      EXPECT_NE(labels.find("=\""), std::string::npos) << line;
    }
    (*samples)[series] = v;
    if (name == family + "_bucket") {
      const std::size_t le = series.find("le=\"");
      ASSERT_NE(le, std::string::npos) << line;
      const std::string bound = series.substr(le + 4, series.find('"', le + 4) - le - 4);
      buckets[family].push_back({bound == "+Inf" ? kInf : std::stod(bound), v});
    }
  }
  for (const auto& [family, f] : families) {
    EXPECT_TRUE(f.help && !f.type.empty()) << family;
    if (f.type != "histogram") continue;
    const auto& b = buckets[family];
    ASSERT_GE(b.size(), 2u) << family;
    for (std::size_t i = 1; i < b.size(); ++i) {
      EXPECT_GT(b[i].first, b[i - 1].first) << family << ": bounds not increasing";
      EXPECT_GE(b[i].second, b[i - 1].second) << family << ": buckets not cumulative";
    }
    EXPECT_TRUE(std::isinf(b.back().first)) << family << ": no +Inf bucket";
    ASSERT_TRUE(samples->count(family + "_count")) << family;
    ASSERT_TRUE(samples->count(family + "_sum")) << family;
    EXPECT_EQ(b.back().second, samples->at(family + "_count")) << family;
  }
}

// Each named sample present with exactly its value.
void expect_samples(const std::map<std::string, double>& samples,
                    std::initializer_list<std::pair<const char*, double>> want) {
  for (const auto& [name, value] : want) {
    const auto it = samples.find(name);
    if (it == samples.end()) {
      ADD_FAILURE() << "no sample " << name;
    } else {
      EXPECT_EQ(it->second, value) << name;
    }
  }
}

TEST(DiagMetrics, TextFormatIsValid) {
  const Snapshot s = sample_snapshot();
  ServerStats server;
  server.requests = 5;
  std::map<std::string, double> samples;
  check_prometheus(metrics_text(s, server), &samples);
  expect_samples(samples, {{"agvloc_ticks_total", 250},
                           {"agvloc_fixes_fused_total", 17},
                           {"agvloc_fixes_rejected_total{reason=\"gate\"}", 2},
                           {"agvloc_can_errors_total{kind=\"tx_error\"}", 3},
                           {"agvloc_health{state=\"degraded\"}", 1},
                           {"agvloc_health{state=\"ok\"}", 0},
                           {"agvloc_position_sigma_meters", 0.003},
                           {"agvloc_diag_requests_total", 5}});
}

TEST(DiagMetrics, HistogramMatchesRecordedValues) {
  const Snapshot s = sample_snapshot();
  std::map<std::string, double> samples;
  check_prometheus(metrics_text(s, {}), &samples);
  EXPECT_EQ(samples["agvloc_end_to_end_seconds_count"], 7);
  EXPECT_NEAR(samples["agvloc_end_to_end_seconds_sum"], 45.982e-3, 1e-9);
  // 500 ns, 1.5 us, 80 us < 100 us; 0.9 ms < 1 ms; 2 and 3 ms < 5 ms; 40 ms < 50 ms. A value is
  // counted under a bound once its ~3 % wide bucket lies below it.
  expect_samples(samples, {{"agvloc_end_to_end_seconds_bucket{le=\"0.0001\"}", 3},
                           {"agvloc_end_to_end_seconds_bucket{le=\"0.001\"}", 4},
                           {"agvloc_end_to_end_seconds_bucket{le=\"0.0025\"}", 5},
                           {"agvloc_end_to_end_seconds_bucket{le=\"0.005\"}", 6},
                           {"agvloc_end_to_end_seconds_bucket{le=\"0.025\"}", 6},
                           {"agvloc_end_to_end_seconds_bucket{le=\"0.05\"}", 7},
                           {"agvloc_end_to_end_seconds_bucket{le=\"+Inf\"}", 7},
                           {"agvloc_period_jitter_seconds_bucket{le=\"0.0001\"}", 1},
                           {"agvloc_period_jitter_seconds_sum", 0.0}});
}

TEST(DiagMetrics, EmptySnapshotIsValid) {
  std::map<std::string, double> samples;
  check_prometheus(metrics_text(Snapshot{}, {}), &samples);
  EXPECT_EQ(samples["agvloc_end_to_end_seconds_bucket{le=\"+Inf\"}"], 0);
  EXPECT_EQ(samples.count("agvloc_can_errors_total{kind=\"tx_error\"}"), 0u);  // no bus
}

TEST(DiagMetrics, NonFiniteGaugeIsNaN) {
  Snapshot s = sample_snapshot();
  s.tick.estimate.position_sigma_mm = kNaN;
  std::map<std::string, double> samples;
  check_prometheus(metrics_text(s, {}), &samples);
  EXPECT_TRUE(std::isnan(samples["agvloc_position_sigma_meters"]));
}

TEST(DiagJson, StatusFields) {
  const Snapshot s = sample_snapshot();
  const auto j = nlohmann::json::parse(status_json(s, {}, "replay"));
  EXPECT_EQ(j["mode"], "replay");
  EXPECT_EQ(j["t_ns"], 2'500'000'000LL);
  EXPECT_TRUE(j["pose"]["valid"].get<bool>());
  EXPECT_DOUBLE_EQ(j["pose"]["x_mm"].get<double>(), 1234.5);
  EXPECT_DOUBLE_EQ(j["pose"]["y_mm"].get<double>(), -678.25);
  EXPECT_NEAR(j["pose"]["theta_deg"].get<double>(), 28.6478897565, 1e-9);
  EXPECT_DOUBLE_EQ(j["pose"]["sigma_x_mm"].get<double>(), 2.0);
  EXPECT_DOUBLE_EQ(j["pose"]["sigma_y_mm"].get<double>(), 3.0);
  EXPECT_DOUBLE_EQ(j["pose"]["time_since_fix_ms"].get<double>(), 120.0);
  EXPECT_EQ(j["health"], "DEGRADED");
  EXPECT_EQ(j["faults"], nlohmann::json::parse(R"(["camera_stalled","imu_timeout"])"));
  EXPECT_EQ(j["rejections"], nlohmann::json::parse(R"(["gate"])"));
  EXPECT_EQ(j["counters"]["fixes_fused"], 17);
  EXPECT_EQ(j["counters"]["ticks"], 250);
  EXPECT_EQ(j["latency"]["end_to_end"]["count"], 7);
  for (const char* k : {"end_to_end", "period_jitter", "fusion", "can_send"}) {
    ASSERT_TRUE(j["latency"].contains(k)) << k;
    EXPECT_TRUE(j["latency"][k].contains("p99_ms")) << k;
  }
  ASSERT_EQ(j["fixes"].size(), 3u);
  EXPECT_EQ(j["fixes"][0]["landmark_id"], 9);  // newest first
  EXPECT_EQ(j["fixes"][1]["status"], vision::to_string(vision::FixStatus::kQrUnreadable));
  EXPECT_DOUBLE_EQ(j["fixes"][0]["x_mm"].get<double>(), 200.0);
  EXPECT_DOUBLE_EQ(j["fixes"][0]["sigma_mm"].get<double>(), 0.5);
  EXPECT_DOUBLE_EQ(j["fixes"][0]["latency_ms"].get<double>(), 30.0);
}

// The page's pose.valid and /metrics' agvloc_pose_valid are the PoseValid the CAN pose frames of
// the same tick carry; "initialised" (the filter has a pose) is separate: true while LOST too.
TEST(DiagPoseValid, IsTheCanPoseValid) {
  constexpr std::int64_t kMs = 1'000'000;
  localizer::LocalizerConfig c;
  c.fusion.health.odom_timeout_ns = 50 * kMs;
  c.heartbeat_period_ns = 1000 * kMs;
  localizer::Localizer loc(c);
  localizer::CanOutput can(c.protocol);
  localizer::OutFrames out;
  struct Seen {
    bool can = false, page = false, initialised = false;
    double metric = -1.0, metric_initialised = -1.0;
    protocol::Health health = protocol::Health::kOk;
  };
  auto tick = [&](std::int64_t t) {
    Snapshot s;
    s.has_tick = true;
    can.tick(loc, t, &out, &s.tick);
    protocol::PoseOut pose;
    EXPECT_TRUE(protocol::decode_pose(c.protocol, out.frame[0], out.frame[1], &pose));
    const auto j = nlohmann::json::parse(status_json(s, {}, "run"));
    std::map<std::string, double> samples;
    check_prometheus(metrics_text(s, {}), &samples);
    return Seen{pose.valid,
                j["pose"]["valid"].get<bool>(),
                j["pose"]["initialised"].get<bool>(),
                samples["agvloc_pose_valid"],
                samples["agvloc_pose_initialised"],
                s.tick.status.health};
  };
  std::int64_t t = 1000 * kMs;
  // Uninitialised: nothing valid.
  loc.on_odometry(t, 0.5, 0.0);
  Seen seen = tick(t += 10 * kMs);
  EXPECT_FALSE(seen.can);
  EXPECT_FALSE(seen.page);
  EXPECT_FALSE(seen.initialised);
  EXPECT_EQ(seen.metric, 0.0);
  // Placed with a sigma beyond the lost limit: initialised, but LOST, so PoseValid 0.
  const double sigma_mm = 2.0 * c.fusion.health.lost_position_sigma_mm;
  ASSERT_TRUE(loc.set_pose(t, {100.0, 0.0, 0.0}, sigma_mm, 0.01));
  for (int i = 0; i < 3; ++i) {
    loc.on_odometry(t, 0.5, 0.0);
    seen = tick(t += 10 * kMs);
  }
  EXPECT_EQ(seen.health, protocol::Health::kLost);
  EXPECT_FALSE(seen.can);
  EXPECT_FALSE(seen.page);
  EXPECT_EQ(seen.metric, 0.0);
  EXPECT_TRUE(seen.initialised);
  EXPECT_EQ(seen.metric_initialised, 1.0);
  // Placed well within the limits with odometry flowing: valid everywhere.
  ASSERT_TRUE(loc.set_pose(t, {100.0, 0.0, 0.0}, 1.0, 0.001));
  loc.on_odometry(t, 0.5, 0.0);
  seen = tick(t += 10 * kMs);
  EXPECT_TRUE(seen.can);
  EXPECT_TRUE(seen.page);
  EXPECT_EQ(seen.metric, 1.0);
  // Odometry stops: PoseValid 0 (FaultOdomTimeout) while the filter stays initialised.
  seen = tick(t += 60 * kMs);
  EXPECT_FALSE(seen.can);
  EXPECT_FALSE(seen.page);
  EXPECT_EQ(seen.metric, 0.0);
  EXPECT_TRUE(seen.initialised);
}

TEST(DiagJson, NonFiniteIsNull) {
  Snapshot s = sample_snapshot();
  s.tick.estimate.pose.x_mm = kNaN;
  s.tick.estimate.position_sigma_mm = kInf;
  const auto j = nlohmann::json::parse(status_json(s, {}, "run"));
  EXPECT_TRUE(j["pose"]["x_mm"].is_null());
  EXPECT_TRUE(j["pose"]["position_sigma_mm"].is_null());
}

TEST(DiagJson, StringsEscaped) {
  std::string out;
  append_json_string(&out, "a\"b\\c\n\x01");
  EXPECT_EQ(nlohmann::json::parse(out).get<std::string>(), "a\"b\\c\n\x01");
}

TEST(DiagJson, MapLandmarksAndTrack) {
  LandmarkMap map;
  map.entries[3] = {3, {1000.0, 2000.0, kPi / 2}};
  map.entries[4] = {4, {-500.0, 0.0, 0.0}};
  const Snapshot s = sample_snapshot();
  const auto j = nlohmann::json::parse(map_json(&map, s));
  ASSERT_EQ(j["landmarks"].size(), 2u);
  EXPECT_EQ(j["landmarks"][0]["id"], 3);
  EXPECT_DOUBLE_EQ(j["landmarks"][0]["heading_deg"].get<double>(), 90.0);
  ASSERT_EQ(j["track"].size(), 4u);  // the invalid first point is left out
  EXPECT_DOUBLE_EQ(j["track"][3][1].get<double>(), 40.0);
  EXPECT_DOUBLE_EQ(j["pose"]["x_mm"].get<double>(), 1234.5);
  const auto none = nlohmann::json::parse(map_json(nullptr, Snapshot{}));
  EXPECT_TRUE(none["landmarks"].empty());
  EXPECT_TRUE(none["pose"].is_null());
}

TEST(DiagRing, KeepsNewestOldestFirst) {
  Ring<int, 3> r;
  EXPECT_EQ(r.size(), 0u);
  for (int i = 1; i <= 5; ++i) r.push(i);
  ASSERT_EQ(r.size(), 3u);
  EXPECT_EQ(r.at(0), 3);
  EXPECT_EQ(r.at(2), 5);
}

}  // namespace
}  // namespace agv::diag
