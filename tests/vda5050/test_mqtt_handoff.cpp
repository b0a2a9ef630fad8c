// The loop side of the MQTT hand-off never waits: a held slot skips the sample (counted), newest
// wins, the rate limit runs in loop time, a pose command is taken once (docs/guide/vda5050.md
// "Threads").
#include <gtest/gtest.h>

#include <atomic>
#include <chrono>
#include <string>
#include <thread>
#include <vector>

#include "../support/thread_cpus.hpp"
#include "mqtt_handoff.hpp"
#include "mqtt_publisher.hpp"

namespace agv::app {
namespace {

localizer::TickRecord at(std::int64_t t_ns) {
  localizer::TickRecord r;
  r.t_ns = t_ns;
  return r;
}

TEST(MqttHandoff, RateLimitedInLoopTimeAndNewestWins) {
  MqttHandoff h;
  h.set_period_ns(100);
  h.offer(at(0));
  h.offer(at(50));   // not due
  h.offer(at(100));  // due: replaces the sample not taken yet
  localizer::TickRecord out;
  ASSERT_TRUE(h.take_sample(&out));
  EXPECT_EQ(out.t_ns, 100);
  EXPECT_EQ(h.superseded(), 1u);
  EXPECT_FALSE(h.take_sample(&out));
  h.offer(at(1000));  // after a gap: due at once, next due one period later
  h.offer(at(1050));
  ASSERT_TRUE(h.take_sample(&out));
  EXPECT_EQ(out.t_ns, 1000);
}

TEST(MqttHandoff, LoopSkipsInsteadOfWaitingForTheMqttThread) {
  MqttHandoff h;
  h.set_period_ns(1);
  std::atomic<bool> holding{false}, release{false};
  // A reader that is slow to come back: take_sample holds the lock only for a copy, so simulate
  // the worst case by a thread that keeps taking samples while the loop offers.
  std::thread reader([&] {
    localizer::TickRecord r;
    holding = true;
    while (!release.load()) h.take_sample(&r);
  });
  while (!holding.load()) std::this_thread::yield();
  for (int i = 0; i < 100000; ++i) h.offer(at(i));  // must return every time
  release = true;
  reader.join();
  SUCCEED() << "busy skips " << h.busy_skips();
}

TEST(MqttHandoff, CommandTakenOnceAndAnswered) {
  MqttHandoff h;
  InitPoseCommand c;
  EXPECT_FALSE(h.take_command(&c));
  EXPECT_EQ(h.post_command({1, 10.0, 20.0, 0.5}), 0u);
  EXPECT_EQ(h.post_command({2, 30.0, 40.0, 0.25}), 1u);  // replaced before the loop took it
  ASSERT_TRUE(h.take_command(&c));
  EXPECT_EQ(c.seq, 2u);
  EXPECT_DOUBLE_EQ(c.x_mm, 30.0);
  EXPECT_FALSE(h.take_command(&c));
  h.report(2, true);
  bool ok = false;
  EXPECT_EQ(h.applied_seq(&ok), 2u);
  EXPECT_TRUE(ok);
}

// loop.service_cpus: the MQTT thread runs on the service CPUs, connected or not (here no broker
// listens on the port: the thread keeps retrying with backoff).
TEST(MqttPublisher, ServiceCpusPinTheMqttThread) {
  const int target = test::lowest_allowed_cpu();
  ASSERT_GE(target, 0);
  config::Vda5050Section cfg;
  cfg.enabled = true;
  cfg.broker_host = "127.0.0.1";
  cfg.broker_port = 9;  // discard: nothing listens there in a test environment
  MqttHandoff handoff;
  MqttPublisher pub(cfg, handoff, 0, std::to_string(target));
  std::string error;
  ASSERT_TRUE(pub.start(&error)) << error;
  std::vector<std::string> cpus;
  for (int i = 0; i < 500 && cpus.empty(); ++i) {
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
    cpus = test::cpus_of_threads_named("agv-mqtt");
  }
  pub.stop();
  ASSERT_EQ(cpus.size(), 1u);
  EXPECT_EQ(cpus[0], std::to_string(target));
}

}  // namespace
}  // namespace agv::app
