// The output side's shared mechanics: the latest-value slot the real-time side never waits on,
// the periodic-due schedule in loop time, and the output loop handing every fix and tick to its
// sinks in order.
#include <gtest/gtest.h>

#include <atomic>
#include <string>
#include <thread>
#include <vector>

#include "agv/adapters/stepped_clock.hpp"
#include "agv/http/latest_slot.hpp"
#include "output_loop.hpp"

namespace agv::app {
namespace {

constexpr std::int64_t kMs = 1'000'000;

TEST(LatestSlot, WriterSkipsAndCountsWhileTheReaderHoldsIt) {
  LatestSlot<int> slot;
  EXPECT_TRUE(slot.try_write([](int& v) { v = 1; }));
  EXPECT_EQ(slot.seq(), 1u);
  std::atomic<bool> holding{false}, release{false};
  std::thread reader([&] {
    slot.read([&](int& v) {
      EXPECT_EQ(v, 1);
      holding = true;
      while (!release.load()) std::this_thread::yield();
      return 0;
    });
  });
  while (!holding.load()) std::this_thread::yield();
  EXPECT_FALSE(slot.try_write([](int& v) { v = 2; }));  // busy: skipped, not waited for
  EXPECT_FALSE(slot.try_read([](int&) {}));
  EXPECT_EQ(slot.busy_skips(), 1u);
  EXPECT_EQ(slot.seq(), 1u);
  release = true;
  reader.join();
  EXPECT_TRUE(slot.try_write([](int& v) { v = 3; }));
  EXPECT_EQ(slot.read([](int& v) { return v; }), 3);
  EXPECT_EQ(slot.seq(), 2u);
  slot.write([](int& v) { v = 4; });
  int seen = 0;
  EXPECT_TRUE(slot.try_read([&](int& v) { seen = v; }));
  EXPECT_EQ(seen, 4);
  EXPECT_EQ(slot.seq(), 3u);
}

TEST(PeriodicDue, DueAtOnceThenEveryPeriodAndRestartsAfterAGap) {
  PeriodicDue due(100);
  EXPECT_TRUE(due.take(1000));
  EXPECT_FALSE(due.take(1050));
  EXPECT_TRUE(due.is_due(1100));
  EXPECT_TRUE(due.is_due(1100));  // is_due alone does not move the schedule
  due.advance(1100);
  EXPECT_FALSE(due.take(1199));
  EXPECT_TRUE(due.take(1230));  // late: the next stays on the schedule (1300)
  EXPECT_FALSE(due.take(1299));
  EXPECT_TRUE(due.take(1300));
  EXPECT_TRUE(due.take(5000));  // after a gap: one output, then a period from the late time
  EXPECT_FALSE(due.take(5050));
  EXPECT_TRUE(due.take(5100));
}

TEST(PeriodicDue, FirstOnePeriodAfterTheStartWhenAsked) {
  PeriodicDue due(100, /*first_at_start=*/false);
  EXPECT_FALSE(due.take(1000));
  EXPECT_FALSE(due.take(1099));
  EXPECT_TRUE(due.take(1100));
  EXPECT_FALSE(due.take(1150));
  EXPECT_TRUE(due.take(1200));
}

// Records what the loop hands it, tagged with its name, into a shared log.
class RecordingSink : public OutputSink {
 public:
  RecordingSink(std::string name, std::vector<std::string>* log)
      : name_(std::move(name)), log_(log) {}
  void before_tick(std::int64_t now_ns, localizer::Localizer&) override {
    log_->push_back(name_ + " before " + std::to_string(now_ns / kMs));
  }
  void on_fix(const FixRecord& r) override {
    log_->push_back(name_ + " fix " + std::to_string(r.t_done_ns / kMs));
  }
  void on_tick(const TickOutput& out) override {
    log_->push_back(name_ + " tick " + std::to_string(out.tick.t_ns / kMs) +
                    (out.bus ? " bus" : " nobus"));
  }
  void finish(const localizer::TickRecord* last, const localizer::OutputStats&, const hal::CanBus*,
              std::uint64_t frames_dropped) override {
    log_->push_back(name_ + " finish " + (last ? std::to_string(last->t_ns / kMs) : "none") + " " +
                    std::to_string(frames_dropped));
  }

 private:
  std::string name_;
  std::vector<std::string>* log_;
};

// What an output loop without a bus runs on: the core on the default configuration, a stepped
// clock at 1 s, the fix ring, and the log its recording sinks write.
struct LoopParts {
  config::Config cfg;
  localizer::Localizer core{localizer_config(cfg)};
  adapters::SteppedClock clock{1000 * kMs};
  FixRing fixes;
  std::vector<std::string> log;
};

TEST(OutputLoop, HandsEveryFixAndTickToItsSinksInOrder) {
  LoopParts parts;
  FixRing& fixes = parts.fixes;
  RecordingSink a("a", &parts.log), b("b", &parts.log);
  OutputLoop loop(parts.core, nullptr, parts.clock, nullptr, fixes, 0, nullptr, {&a, &b});
  FixRecord fix;
  fix.t_exposure_ns = 995 * kMs;
  fix.t_done_ns = 1005 * kMs;
  fix.fix.status = vision::FixStatus::kNoLandmark;
  ASSERT_TRUE(fixes.push(fix));
  CameraState cam;
  loop.tick(1000 * kMs, cam, nullptr);  // the fix has not arrived yet
  loop.tick(1010 * kMs, cam, nullptr);
  cam.frames_dropped = 7;
  loop.finish(cam.frames_dropped);
  const std::vector<std::string> expected = {
      "a before 1000",     "b before 1000",     "a tick 1000 nobus", "b tick 1000 nobus",
      "a fix 1005",        "b fix 1005",        "a before 1010",     "b before 1010",
      "a tick 1010 nobus", "b tick 1010 nobus", "a finish 1010 7",   "b finish 1010 7"};
  EXPECT_EQ(parts.log, expected);
}

TEST(OutputLoop, FinishWithoutATickSaysSo) {
  LoopParts parts;
  RecordingSink a("a", &parts.log);
  OutputLoop loop(parts.core, nullptr, parts.clock, nullptr, parts.fixes, 0, nullptr, {&a});
  loop.finish(0);
  EXPECT_EQ(parts.log, std::vector<std::string>{"a finish none 0"});
}

}  // namespace
}  // namespace agv::app
