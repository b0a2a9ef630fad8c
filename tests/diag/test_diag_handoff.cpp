// The loop side of the diagnostics hand-off (firmware/src/diag_handoff.hpp): rate limit in loop
// time, never waiting on a busy slot, the final state; the frame tap's copies on request.
#include <arpa/inet.h>
#include <gtest/gtest.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>

#include <atomic>
#include <chrono>
#include <string>
#include <thread>
#include <vector>

#include "../support/thread_cpus.hpp"
#include "diag_handoff.hpp"
#include "diag_server.hpp"

namespace agv::app {
namespace {

localizer::TickRecord tick_at(std::int64_t t_ns, double x_mm) {
  localizer::TickRecord t;
  t.t_ns = t_ns;
  t.estimate.valid = true;
  t.estimate.pose.x_mm = x_mm;
  return t;
}

TEST(DiagHandoff, OffersAtTheHandoffRateInLoopTime) {
  DiagHandoff h;
  localizer::OutputStats st;
  diag::Snapshot s;
  std::uint64_t seq = 0;
  EXPECT_FALSE(h.take(&s, &seq));
  // 10 ms ticks for 1 s: 10 hand-offs at 100 ms.
  for (int i = 0; i < 100; ++i) {
    st.ticks = static_cast<std::uint64_t>(i + 1);
    h.offer(tick_at(i * 10'000'000LL, i), st, nullptr, 0);
  }
  ASSERT_TRUE(h.take(&s, &seq));
  EXPECT_EQ(seq, 10u);
  EXPECT_EQ(s.track.size(), 10u);
  EXPECT_EQ(s.tick.t_ns, 900'000'000);
  EXPECT_EQ(s.stats.ticks, 91u);
  EXPECT_FALSE(s.can_present);
  EXPECT_FALSE(s.finished);
  EXPECT_FALSE(h.take(&s, &seq));  // nothing newer
}

TEST(DiagHandoff, BusySlotIsSkippedNotWaitedFor) {
  DiagHandoff h;
  localizer::OutputStats st;
  std::atomic<bool> holding{false}, release{false};
  // The server side holds the slot (take copies under its lock) from another thread: simulate by
  // taking in a loop while the loop side offers; every offer must return, skips are counted.
  std::thread server([&] {
    diag::Snapshot s;
    std::uint64_t seq = 0;
    holding = true;
    while (!release.load()) h.take(&s, &seq);
  });
  while (!holding.load()) std::this_thread::yield();
  for (int i = 0; i < 2000; ++i) h.offer(tick_at(i * 100'000'000LL, i), st, nullptr, 0);
  release = true;
  server.join();
  diag::Snapshot s;
  std::uint64_t seq = 0;
  h.take(&s, &seq);
  EXPECT_EQ(seq + h.busy_skips(), 2000u);
}

TEST(DiagHandoff, FinishHandsTheFinalState) {
  DiagHandoff h;
  localizer::OutputStats st;
  h.offer(tick_at(0, 1.0), st, nullptr, 0);
  h.offer(tick_at(10'000'000, 2.0), st, nullptr, 0);  // not due
  vision::LandmarkFix fix;
  fix.status = vision::FixStatus::kOk;
  fix.landmark_id = 42;
  h.record_fix(fix, 5'000'000, 35'000'000);
  st.fixes_fused = 1;
  const localizer::TickRecord last = tick_at(20'000'000, 3.0);
  h.finish(&last, st, nullptr, 4);
  diag::Snapshot s;
  std::uint64_t seq = 0;
  ASSERT_TRUE(h.take(&s, &seq));
  EXPECT_TRUE(h.finished());
  EXPECT_TRUE(s.finished);
  EXPECT_EQ(s.tick.t_ns, 20'000'000);
  EXPECT_EQ(s.stats.fixes_fused, 1u);
  EXPECT_EQ(s.frames_dropped, 4u);
  ASSERT_EQ(s.fixes.size(), 1u);
  EXPECT_EQ(s.fixes.at(0).landmark_id, 42u);
  EXPECT_EQ(s.track.size(), 2u);
}

TEST(FrameTap, CopiesOnRequestOrWhenStale) {
  FrameTap tap;
  cv::Mat img(4, 6, CV_8UC1, cv::Scalar(7));
  tap.offer(img, 0);  // nothing kept yet: copied
  EXPECT_EQ(tap.seq(), 1u);
  tap.offer(img, 100'000'000);  // fresh enough, not asked for
  EXPECT_EQ(tap.seq(), 1u);
  tap.request();
  img.setTo(9);
  tap.offer(img, 200'000'000);
  EXPECT_EQ(tap.seq(), 2u);
  tap.offer(img, 300'000'000);  // request served
  EXPECT_EQ(tap.seq(), 2u);
  tap.offer(img, FrameTap::kRefreshNs + 200'000'000);  // stale: refreshed
  EXPECT_EQ(tap.seq(), 3u);
  cv::Mat out;
  std::int64_t t = 0;
  ASSERT_TRUE(tap.take(&out, &t));
  EXPECT_EQ(t, FrameTap::kRefreshNs + 200'000'000);
  EXPECT_EQ(out.at<std::uint8_t>(3, 5), 9);
}

TEST(DiagServer, LoopbackAddresses) {
  EXPECT_TRUE(is_loopback_address("127.0.0.1"));
  EXPECT_TRUE(is_loopback_address("127.1.2.3"));
  EXPECT_TRUE(is_loopback_address("::1"));
  EXPECT_TRUE(is_loopback_address("localhost"));
  EXPECT_FALSE(is_loopback_address("0.0.0.0"));
  EXPECT_FALSE(is_loopback_address("::"));
  EXPECT_FALSE(is_loopback_address("192.168.1.10"));
  EXPECT_FALSE(is_loopback_address("127example.com"));
  EXPECT_FALSE(is_loopback_address("127.evil.example"));
  EXPECT_FALSE(is_loopback_address("::ffff:10.0.0.1"));
}

// The start-up error names the real reason (the errno of the failing call), not a guess.
TEST(DiagServer, ListenFailureNamesTheErrno) {
  // A port taken by a listening socket of this process.
  const int fd = ::socket(AF_INET, SOCK_STREAM, 0);
  ASSERT_GE(fd, 0);
  sockaddr_in a{};
  a.sin_family = AF_INET;
  a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  a.sin_port = 0;
  ASSERT_EQ(::bind(fd, reinterpret_cast<sockaddr*>(&a), sizeof a), 0);
  ASSERT_EQ(::listen(fd, 1), 0);
  socklen_t len = sizeof a;
  ASSERT_EQ(::getsockname(fd, reinterpret_cast<sockaddr*>(&a), &len), 0);
  const int port = ntohs(a.sin_port);
  const std::string in_use = listen_failure_reason("127.0.0.1", port);
  EXPECT_NE(in_use.find("bind: "), std::string::npos) << in_use;
  EXPECT_NE(in_use.find("EADDRINUSE"), std::string::npos) << in_use;
  ::close(fd);
  // Free again: nothing to report.
  EXPECT_EQ(listen_failure_reason("127.0.0.1", port), "");
  // TEST-NET-1 is no address of this host.
  const std::string foreign = listen_failure_reason("192.0.2.1", 8088);
  EXPECT_NE(foreign.find("EADDRNOTAVAIL"), std::string::npos) << foreign;
}

TEST(DiagServer, PngEncodes) {
  cv::Mat bgr(3, 5, CV_8UC3, cv::Scalar(1, 2, 3));
  std::string png;
  ASSERT_TRUE(encode_png(bgr, &png));
  ASSERT_GT(png.size(), 8u);
  EXPECT_EQ(png.substr(1, 3), "PNG");
  EXPECT_FALSE(encode_png(cv::Mat(), &png));
  EXPECT_FALSE(encode_png(cv::Mat(2, 2, CV_16UC1), &png));
}

// loop.service_cpus: the page's listener and every worker it starts run on the service CPUs.
TEST(DiagServer, ServiceCpusPinTheListenerAndItsWorkers) {
  const int target = test::lowest_allowed_cpu();
  ASSERT_GE(target, 0);
  config::Config cfg;
  cfg.diag.port = 0;
  cfg.diag.threads = 3;
  cfg.loop.service_cpus = std::to_string(target);
  DiagHandoff handoff;
  FrameTap frames;
  DiagServer server(cfg, nullptr, handoff, frames, "test");
  std::string error;
  if (!server.start(&error)) GTEST_SKIP() << error;  // built without libmicrohttpd
  std::vector<std::string> cpus;
  // The deadline keeper ("agv-diag") and the HTTP library's 3 polling threads, which it names
  // itself; all created by a thread already pinned.
  for (int i = 0; i < 500 && cpus.size() < 4; ++i) {
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
    cpus = test::cpus_of_threads_named("agv-diag");
    const auto workers = test::cpus_of_threads_named("MHD-worker");
    cpus.insert(cpus.end(), workers.begin(), workers.end());
  }
  server.stop();
  ASSERT_EQ(cpus.size(), 4u) << "deadline keeper and 3 polling threads";
  for (const auto& c : cpus) EXPECT_EQ(c, std::to_string(target));
}

}  // namespace
}  // namespace agv::app
