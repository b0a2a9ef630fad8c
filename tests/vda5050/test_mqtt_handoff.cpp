// The loop side of the MQTT hand-off never waits: a held slot skips the sample (counted), newest
// wins, the rate limit runs in loop time, a pose command is taken once (docs/guide/vda5050.md
// "Threads").
#include <gtest/gtest.h>
#include <unistd.h>

#include <atomic>
#include <chrono>
#include <filesystem>
#include <fstream>
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
  h.offer(at(0));
  localizer::TickRecord out;
  CommandAnswer answer;
  ASSERT_TRUE(h.take_sample(&out, &answer));
  EXPECT_EQ(answer.seq, 2u);
  EXPECT_TRUE(answer.ok);
  h.offer(at(1'000'000'000));
  ASSERT_TRUE(h.take_sample(&out, &answer));
  EXPECT_EQ(answer.seq, 0u);  // answered once
}

// The state answering initPosition carries the pose after the action: the answer travels with
// the sample of the tick that applied it, which is offered even when the visualization period is
// not due (a 10 Hz sample would otherwise be the one from before the command).
TEST(MqttHandoff, AnswerTravelsWithTheTickThatAppliedTheCommand) {
  MqttHandoff h;
  h.set_period_ns(100);
  localizer::TickRecord before = at(0);
  before.estimate.pose.x_mm = 262.0;
  h.offer(before);
  localizer::TickRecord out;
  CommandAnswer answer;
  ASSERT_TRUE(h.take_sample(&out, &answer));
  EXPECT_EQ(answer.seq, 0u);
  h.report(7, true);  // the loop applied command 7 at t 10 (not due until t 100)
  localizer::TickRecord after = at(10);
  after.estimate.pose.x_mm = 10014.0;
  h.offer(after);
  ASSERT_TRUE(h.take_sample(&out, &answer));
  EXPECT_EQ(answer.seq, 7u);
  EXPECT_EQ(out.t_ns, 10);
  EXPECT_DOUBLE_EQ(out.estimate.pose.x_mm, 10014.0);
  // A newer sample replacing it before the MQTT thread looked keeps the answer (also after it).
  h.report(8, false);
  h.offer(at(20));
  h.offer(at(100));
  ASSERT_TRUE(h.take_sample(&out, &answer));
  EXPECT_EQ(answer.seq, 8u);
  EXPECT_FALSE(answer.ok);
  EXPECT_EQ(out.t_ns, 100);
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
  MqttPublisher pub(cfg, handoff, StampClock::kLoop, std::to_string(target));
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

// --check-config reads the files the way the start does: a directory, a device (/dev/null,
// /dev/zero: never read, which took 33 s and 1 GB before), a missing file or an empty password
// are refused with the key's name; nothing is read beyond a bound.
TEST(MqttPublisher, FileChecksRefuseWhatTheStartCannotUse) {
  const std::filesystem::path dir =
      std::filesystem::temp_directory_path() / ("agv_vda_files_" + std::to_string(::getpid()));
  std::filesystem::create_directories(dir);
  const std::string good_password = (dir / "password").string();
  const std::string empty = (dir / "empty").string();
  const std::string ca = (dir / "ca.pem").string();
  const std::string big = (dir / "big").string();
  std::ofstream(good_password) << "secret\n";
  std::ofstream(empty).flush();
  std::ofstream(ca) << "-----BEGIN CERTIFICATE-----\nMIIB\n-----END CERTIFICATE-----\n";
  std::ofstream(big) << std::string(2u << 20, 'x');
  auto refused = [](const std::string& password_file, const std::string& ca_file, const char* key) {
    config::Vda5050Section cfg;
    cfg.password_file = password_file;
    cfg.tls_ca_file = ca_file;
    std::vector<std::string> errors;
    const auto t0 = std::chrono::steady_clock::now();
    const bool ok = check_vda5050_files(cfg, &errors);
    EXPECT_LT(std::chrono::steady_clock::now() - t0, std::chrono::seconds(5));
    std::string all;
    for (const auto& e : errors) all += e + "\n";
    return !ok && all.find(key) != std::string::npos;
  };
  for (const std::string& bad : {dir.string(), (dir / "missing").string(), std::string("/dev/null"),
                                 std::string("/dev/zero"), empty, big}) {
    EXPECT_TRUE(refused(bad, "", "vda5050.password_file")) << bad;
    EXPECT_TRUE(refused("", bad, "vda5050.tls_ca_file")) << bad;
  }
  EXPECT_TRUE(refused("", good_password, "vda5050.tls_ca_file"));  // not PEM
  config::Vda5050Section cfg;
  cfg.password_file = good_password;
  cfg.tls_ca_file = ca;
  std::vector<std::string> errors;
  EXPECT_TRUE(check_vda5050_files(cfg, &errors)) << (errors.empty() ? "" : errors[0]);
  // The start refuses the same (it used to read /dev/zero until memory ran out).
  cfg.password_file = "/dev/zero";
  MqttHandoff handoff;
  MqttPublisher pub(cfg, handoff, StampClock::kLoop);
  std::string error;
  EXPECT_FALSE(pub.start(&error));
  EXPECT_NE(error.find("vda5050.password_file"), std::string::npos) << error;
  std::filesystem::remove_all(dir);
}

}  // namespace
}  // namespace agv::app
