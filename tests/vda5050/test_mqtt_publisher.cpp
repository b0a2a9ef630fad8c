// The position provider on a real broker (label mqtt: needs mosquitto): stamps from the wall
// clock from the first message, the last will above every headerId before it, the state answering
// initPosition with the pose after the action, publish refusals counted apart from what was
// published, and broker losses logged once per change (docs/guide/vda5050.md).
#include <gtest/gtest.h>

#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <memory>
#include <nlohmann/json.hpp>
#include <string>
#include <thread>

#include "mqtt_handoff.hpp"
#include "mqtt_publisher.hpp"
#include "mqtt_test_broker.hpp"

namespace agv::app {
namespace {

using nlohmann::json;
using test::Broker;
using test::Subscriber;
using test::wait_until;

const char* kBase = "uagv/v2/acme/agv-7/";

std::int64_t steady_now_ns() {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(
             std::chrono::steady_clock::now().time_since_epoch())
      .count();
}

std::int64_t wall_now_ms() {
  return std::chrono::duration_cast<std::chrono::milliseconds>(
             std::chrono::system_clock::now().time_since_epoch())
      .count();
}

// ms since the epoch of "YYYY-MM-DDTHH:MM:SS.mmmZ".
std::int64_t stamp_ms(const std::string& ts) {
  std::tm tm{};
  if (!strptime(ts.c_str(), "%Y-%m-%dT%H:%M:%S", &tm)) return -1;
  return static_cast<std::int64_t>(timegm(&tm)) * 1000 + std::atoi(ts.c_str() + 20);
}

config::Vda5050Section section(int port) {
  config::Vda5050Section c;
  c.enabled = true;
  c.broker_host = "127.0.0.1";
  c.broker_port = port;
  c.manufacturer = "acme";
  c.serial_number = "agv-7";
  c.map_id = "hall-1";
  c.rate_hz = 2.0;  // a sample every 500 ms: the answer must not wait for the next one
  return c;
}

std::string work_dir() {
  const std::string d =
      (std::filesystem::temp_directory_path() / ("agv_mqtt_pub_" + std::to_string(::getpid())))
          .string();
  std::filesystem::create_directories(d);
  return d;
}

// The output loop's side, in real time (10 ms ticks on CLOCK_MONOTONIC): applies a pose command
// the way OutputLoop::tick does (report, then this tick's offer).
class FakeLoop {
 public:
  explicit FakeLoop(MqttHandoff& h) : h_(h) {
    thread_ = std::thread([this] {
      double x = 262.0, y = 20.0, th = 0.0;
      while (!stop_) {
        InitPoseCommand c;
        if (h_.take_command(&c)) {
          x = c.x_mm;
          y = c.y_mm;
          th = c.theta_rad;
          h_.report(c.seq, true);
        }
        localizer::TickRecord r;
        r.t_ns = steady_now_ns();
        r.estimate.pose = {x, y, th};
        r.estimate.valid = true;
        h_.offer(r);
        std::this_thread::sleep_for(std::chrono::milliseconds(10));
      }
    });
  }
  ~FakeLoop() {
    stop_ = true;
    thread_.join();
  }

 private:
  MqttHandoff& h_;
  std::atomic<bool> stop_{false};
  std::thread thread_;
};

std::vector<json> on_topic(Subscriber& s, const std::string& leaf) {
  std::vector<json> out;
  for (const auto& m : s.messages()) {
    if (m.topic == kBase + leaf) out.push_back(json::parse(m.payload));
  }
  return out;
}

class MqttPublisherBroker : public ::testing::Test {
 protected:
  void SetUp() override {
    if (test::mosquitto_binary().empty()) GTEST_SKIP() << "mosquitto not installed";
    broker_ = std::make_unique<Broker>(work_dir());
    ASSERT_TRUE(broker_->start()) << "mosquitto did not start";
  }
  // A subscriber to every topic under the base, then a started publisher with wall-clock stamps.
  void subscribe_and_start() {
    sub_ = std::make_unique<Subscriber>(broker_->port(), std::string(kBase) + "#");
    ASSERT_TRUE(sub_->wait_subscribed());
    pub_ = std::make_unique<MqttPublisher>(section(broker_->port()), handoff_, StampClock::kWall);
    std::string error;
    ASSERT_TRUE(pub_->start(&error)) << error;
  }
  std::unique_ptr<Broker> broker_;
  std::unique_ptr<Subscriber> sub_;
  MqttHandoff handoff_;
  std::unique_ptr<MqttPublisher> pub_;
};

// agvloc run: the first ONLINE is sent before any tick; it was stamped with the machine's boot
// time (the loop's monotonic zero plus the wall-minus-monotonic offset).
TEST_F(MqttPublisherBroker, WallClockStampsFromTheFirstMessage) {
  ASSERT_NO_FATAL_FAILURE(subscribe_and_start());
  Subscriber& sub = *sub_;
  ASSERT_TRUE(wait_until([&] { return !on_topic(sub, "connection").empty(); }));
  const json online = on_topic(sub, "connection").front();
  EXPECT_EQ(online["connectionState"], "ONLINE");
  EXPECT_LT(std::llabs(stamp_ms(online["timestamp"]) - wall_now_ms()), 60'000) << online.dump();
  {
    FakeLoop loop(handoff_);
    ASSERT_TRUE(wait_until([&] { return !on_topic(sub, "visualization").empty(); }));
  }
  const json vis = on_topic(sub, "visualization").front();
  EXPECT_LT(std::llabs(stamp_ms(vis["timestamp"]) - wall_now_ms()), 60'000) << vis.dump();
  pub_->stop();
}

TEST_F(MqttPublisherBroker, InitPositionStateCarriesThePoseAfterTheAction) {
  ASSERT_NO_FATAL_FAILURE(subscribe_and_start());
  Subscriber& sub = *sub_;
  FakeLoop loop(handoff_);
  ASSERT_TRUE(wait_until([&] { return !on_topic(sub, "visualization").empty(); }));
  const json action = {{"headerId", 1},
                       {"timestamp", "2026-01-01T00:00:00.000Z"},
                       {"version", "2.1.0"},
                       {"manufacturer", "acme"},
                       {"serialNumber", "agv-7"},
                       {"actions",
                        {{{"actionId", "init-1"},
                          {"actionType", "initPosition"},
                          {"blockingType", "NONE"},
                          {"actionParameters",
                           {{{"key", "x"}, {"value", 10.014}},
                            {{"key", "y"}, {"value", 10.021}},
                            {{"key", "theta"}, {"value", 0.5}},
                            {{"key", "mapId"}, {"value", "hall-1"}}}}}}}};
  sub.publish(std::string(kBase) + "instantActions", action.dump());
  ASSERT_TRUE(wait_until([&] { return !on_topic(sub, "state").empty(); }));
  const json state = on_topic(sub, "state").front();
  ASSERT_EQ(state["actionStates"].size(), 1u) << state.dump();
  EXPECT_EQ(state["actionStates"][0]["actionStatus"], "FINISHED");
  EXPECT_NEAR(state["agvPosition"]["x"].get<double>(), 10.014, 1e-9) << state.dump();
  EXPECT_NEAR(state["agvPosition"]["y"].get<double>(), 10.021, 1e-9) << state.dump();
  pub_->stop();
}

// The will (CONNECTIONBROKEN) is set before ONLINE is sent; a fleet control that drops
// non-increasing headerIds must still take it. The publisher runs in a child process that is
// killed, so the broker sees the connection break without a DISCONNECT.
TEST_F(MqttPublisherBroker, LastWillHeaderIdIsAboveOnline) {
  const pid_t child = ::fork();
  ASSERT_GE(child, 0);
  if (child == 0) {
    MqttHandoff handoff;
    MqttPublisher pub(section(broker_->port()), handoff, StampClock::kWall);
    std::string error;
    if (!pub.start(&error)) ::_exit(3);
    for (;;) ::pause();
  }
  Subscriber sub(broker_->port(), std::string(kBase) + "connection");
  ASSERT_TRUE(sub.wait_subscribed());
  // ONLINE is retained: it arrives whether the child sent it before or after the subscription.
  const bool online = wait_until([&] { return !on_topic(sub, "connection").empty(); });
  ::kill(child, SIGKILL);
  ::waitpid(child, nullptr, 0);
  ASSERT_TRUE(online);
  ASSERT_TRUE(wait_until([&] { return on_topic(sub, "connection").size() >= 2; }));
  const std::vector<json> c = on_topic(sub, "connection");
  EXPECT_EQ(c[0]["connectionState"], "ONLINE");
  EXPECT_EQ(c.back()["connectionState"], "CONNECTIONBROKEN");
  EXPECT_GT(c.back()["headerId"].get<int>(), c[0]["headerId"].get<int>()) << c[0].dump() << "\n"
                                                                          << c.back().dump();
}

// A topic the client library refuses (a wildcard that slipped past the checker): nothing reaches
// the broker, so nothing may be counted as published (the summary said "published 59" before),
// and the reason is logged once.
TEST_F(MqttPublisherBroker, RefusedTopicIsNeverCountedAsPublished) {
  config::Vda5050Section cfg = section(broker_->port());
  cfg.serial_number = "agv+7";
  cfg.rate_hz = 50.0;
  MqttHandoff handoff;
  MqttPublisher pub(cfg, handoff, StampClock::kWall);
  std::string error;
  testing::internal::CaptureStderr();
  ASSERT_TRUE(pub.start(&error)) << error;
  {
    FakeLoop loop(handoff);
    ASSERT_TRUE(wait_until([&] {
      const MqttCounters c = pub.counters();
      return c.connect_failures >= 3 && c.dropped_offline >= 5;
    }));
  }
  pub.stop();
  const std::string log = testing::internal::GetCapturedStderr();
  const MqttCounters c = pub.counters();
  EXPECT_EQ(c.published, 0u);
  EXPECT_EQ(c.connects, 0u);
  const std::string summary = format_mqtt_counters(c, handoff);
  EXPECT_NE(summary.find("visualization published 0, publish failed 0"), std::string::npos)
      << summary;
  EXPECT_NE(log.find("the last will on uagv/v2/acme/agv+7/connection"), std::string::npos) << log;
}

// Losing and regaining the broker: one line per change, not one per retry, not none.
TEST_F(MqttPublisherBroker, BrokerLossAndReturnLoggedOncePerChange) {
  MqttHandoff handoff;
  MqttPublisher pub(section(broker_->port()), handoff, StampClock::kWall);
  std::string error;
  testing::internal::CaptureStderr();
  ASSERT_TRUE(pub.start(&error)) << error;
  ASSERT_TRUE(wait_until([&] { return pub.counters().connects >= 1; }));
  broker_->stop();
  // Several failed attempts while it is down (backoff 0.1, 0.2, 0.4 s ...).
  const bool retried = wait_until([&] { return pub.counters().connect_failures >= 3; });
  ASSERT_TRUE(broker_->start());
  const bool back = wait_until([&] { return pub.counters().connects >= 2; });
  pub.stop();
  const std::string log = testing::internal::GetCapturedStderr();
  ASSERT_TRUE(retried && back) << log;
  auto count = [&log](const std::string& what) {
    int n = 0;
    for (auto p = log.find(what); p != std::string::npos; p = log.find(what, p + 1)) ++n;
    return n;
  };
  EXPECT_EQ(count("vda5050: connected to 127.0.0.1:"), 2) << log;
  EXPECT_EQ(count("vda5050: no connection to 127.0.0.1:"), 1) << log;
}

}  // namespace
}  // namespace agv::app
