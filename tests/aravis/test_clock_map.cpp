// ClockMap: camera clock -> host clock from (camera stamp, receive time) pairs.
#include <gtest/gtest.h>

#include <cstdint>
#include <limits>
#include <random>

#include "agv/common/clock_map.hpp"

namespace {

using agv::ClockMap;
using agv::ClockMapConfig;
using agv::ClockSample;

constexpr std::int64_t kMs = 1'000'000;
constexpr std::int64_t kS = 1'000'000'000;

// A simulated link: host = device * (1 + drift) + offset + latency, the latency a floor plus an
// exponential tail (mostly near the floor, sometimes milliseconds late).
struct Link {
  double drift_ppm = 0.0;
  std::int64_t offset_ns = 0;
  std::int64_t floor_ns = kMs;
  double tail_mean_ns = 300'000.0;
  std::mt19937_64 rng{7};

  std::int64_t true_host(std::int64_t device_ns) const {
    return device_ns + offset_ns +
           static_cast<std::int64_t>(drift_ppm * 1e-6 * static_cast<double>(device_ns));
  }
  std::int64_t receive(std::int64_t device_ns) {
    std::exponential_distribution<double> tail(1.0 / tail_mean_ns);
    return true_host(device_ns) + floor_ns + static_cast<std::int64_t>(tail(rng));
  }
};

// Feeds frames at `fps` from device time t0 for `seconds`; returns the next device time.
std::int64_t feed(ClockMap* map, Link* link, std::int64_t t0, double seconds, double fps,
                  int* jumps_seen = nullptr) {
  const auto period = static_cast<std::int64_t>(1e9 / fps);
  const auto n = static_cast<int>(seconds * fps);
  std::int64_t t = t0;
  for (int i = 0; i < n; ++i, t += period) {
    const ClockSample s = map->add(t, link->receive(t));
    if (jumps_seen != nullptr && s == ClockSample::kJump) ++*jumps_seen;
  }
  return t;
}

// Error of the mapping against the true host time plus the latency floor (which the mapping
// includes by design).
std::int64_t map_error(const ClockMap& map, const Link& link, std::int64_t device_ns) {
  std::int64_t host = 0;
  EXPECT_TRUE(map.map(device_ns, &host));
  return host - (link.true_host(device_ns) + link.floor_ns);
}

TEST(ClockMap, RecoversAConstantOffsetUnderJitter) {
  ClockMap map;
  Link link;
  link.offset_ns = 1'700'000'000 * kS;  // a wall-clock camera against a monotonic host
  const std::int64_t end = feed(&map, &link, 3 * kS, 10.0, 30.0);
  EXPECT_TRUE(map.drift_locked());
  EXPECT_NEAR(map.drift_ppm(), 0.0, 2.0);
  EXPECT_LT(std::llabs(map_error(map, link, end - 33 * kMs)), 50'000);
  EXPECT_LT(std::llabs(map_error(map, link, end + kS)), 50'000);  // one second ahead
  EXPECT_EQ(map.jumps(), 0u);
}

TEST(ClockMap, TracksFiftyPpmOfDrift) {
  for (double ppm : {50.0, -50.0}) {
    ClockMap map;
    Link link;
    link.drift_ppm = ppm;
    link.offset_ns = -42 * kS;
    const std::int64_t end = feed(&map, &link, kS, 30.0, 30.0);
    EXPECT_NEAR(map.drift_ppm(), ppm, 2.0) << ppm;
    // Ignoring the drift would be 500 us off after the 10 s window; the fit stays within 50 us.
    EXPECT_LT(std::llabs(map_error(map, link, end - 33 * kMs)), 50'000) << ppm;
    EXPECT_LT(std::llabs(map_error(map, link, end + kS)), 50'000) << ppm;
    EXPECT_EQ(map.jumps(), 0u);
  }
}

TEST(ClockMap, OffsetOnlyUntilTheWindowSpansEnoughForDrift) {
  ClockMap map;
  Link link;
  link.drift_ppm = 50.0;
  feed(&map, &link, 0, 0.5, 30.0);
  EXPECT_TRUE(map.has_offset());
  EXPECT_FALSE(map.drift_locked());
  EXPECT_EQ(map.drift_ppm(), 0.0);
}

TEST(ClockMap, DetectsABackwardResetAndRelocks) {
  ClockMap map;
  Link link;
  link.drift_ppm = 20.0;
  link.offset_ns = 5 * kS;
  feed(&map, &link, 100 * kS, 10.0, 30.0);
  const std::int64_t before = map.offset_ns();
  // The camera rebooted: its counter restarts near zero while the host goes on.
  Link after = link;
  after.offset_ns = link.true_host(110 * kS);
  int jumps = 0;
  const std::int64_t end = feed(&map, &after, 0, 5.0, 30.0, &jumps);
  EXPECT_EQ(jumps, 1);
  EXPECT_EQ(map.jumps(), 1u);
  EXPECT_NE(map.offset_ns(), before);
  EXPECT_LT(std::llabs(map_error(map, after, end - 33 * kMs)), 100'000);
}

TEST(ClockMap, DetectsAForwardStepAndRelocks) {
  ClockMap map;
  Link link;
  const std::int64_t t = feed(&map, &link, 0, 5.0, 30.0);
  // The device clock steps 0.3 s forward: its samples map 0.3 s after they arrive, impossible
  // with a positive latency. The first few are held back, then the map follows.
  link.offset_ns -= 300 * kMs;
  const std::int64_t stepped = t + 300 * kMs;
  EXPECT_EQ(map.add(stepped, link.receive(stepped)), ClockSample::kHeldBack);
  int jumps = 0;
  const std::int64_t end = feed(&map, &link, stepped + 33 * kMs, 2.0, 30.0, &jumps);
  EXPECT_EQ(jumps, 1);
  EXPECT_LT(std::llabs(map_error(map, link, end - 33 * kMs)), 100'000);
}

TEST(ClockMap, LateFramesDoNotMoveTheMap) {
  ClockMap map;
  Link link;
  std::int64_t t = feed(&map, &link, 0, 5.0, 30.0);
  std::int64_t before = 0;
  ASSERT_TRUE(map.map(t, &before));
  // 40 ms late: within what the link may do; used, but above the envelope.
  EXPECT_EQ(map.add(t, link.true_host(t) + 40 * kMs), ClockSample::kAccepted);
  std::int64_t after = 0;
  ASSERT_TRUE(map.map(t, &after));
  EXPECT_LT(std::llabs(after - before), 20'000);  // a mean would have moved 260 us
  // 200 ms late: held back; the next frames (arriving after it) are normal again.
  t += 33 * kMs;
  EXPECT_EQ(map.add(t, link.true_host(t) + 200 * kMs), ClockSample::kHeldBack);
  t += 250 * kMs;
  feed(&map, &link, t, 1.0, 30.0);
  EXPECT_EQ(map.jumps(), 0u);
  EXPECT_EQ(map.held_back(), 1u);
  EXPECT_LT(std::llabs(map_error(map, link, t)), 100'000);
}

TEST(ClockMap, FramesQueuedBehindAHostStallAreNotAJump) {
  ClockMap map;
  Link link;
  std::int64_t t = feed(&map, &link, 0, 3.0, 100.0);
  // 150 ms stall at 100 fps: 15 frames stamped on arrival at the same host instant.
  const std::int64_t resume = link.true_host(t) + 150 * kMs;
  for (int i = 0; i < 15; ++i, t += 10 * kMs) {
    EXPECT_NE(map.add(t, resume), ClockSample::kJump) << i;
  }
  feed(&map, &link, t, 1.0, 100.0);
  EXPECT_EQ(map.jumps(), 0u);
  EXPECT_LT(std::llabs(map_error(map, link, t)), 100'000);
}

TEST(ClockMap, AHighFirstLatencyIsNotTakenForAJump) {
  ClockMap map;
  Link link;
  EXPECT_EQ(map.add(0, link.true_host(0) + 30 * kMs), ClockSample::kAccepted);
  feed(&map, &link, 33 * kMs, 2.0, 30.0);
  EXPECT_EQ(map.jumps(), 0u);
  EXPECT_LT(std::llabs(map_error(map, link, 2 * kS)), 100'000);
}

TEST(ClockMap, RefusesNonMonotonicAndGarbageStamps) {
  ClockMap map;
  Link link;
  std::int64_t t = feed(&map, &link, 10 * kS, 5.0, 30.0);
  std::int64_t host_before = 0;
  ASSERT_TRUE(map.map(t, &host_before));
  const std::uint64_t accepted_window = static_cast<std::uint64_t>(map.window_size());

  // A stamp older than the last accepted one, and a repeated one.
  const std::int64_t last = t - static_cast<std::int64_t>(1e9 / 30.0);
  EXPECT_EQ(map.add(last - 100 * kMs, link.receive(t)), ClockSample::kHeldBack);
  EXPECT_EQ(map.add(last, link.receive(t)), ClockSample::kHeldBack);
  // Random stamps at a steady host rate never agree on an offset.
  std::mt19937_64 rng(3);
  std::uniform_int_distribution<std::int64_t> any(0, 1'000'000 * kS);
  std::int64_t host = link.receive(t);
  for (int i = 0; i < 200; ++i) {
    host += 33 * kMs;
    EXPECT_EQ(map.add(any(rng), host), ClockSample::kHeldBack) << i;
  }
  EXPECT_EQ(map.jumps(), 0u);
  EXPECT_EQ(static_cast<std::uint64_t>(map.window_size()), accepted_window);
  std::int64_t host_after = 0;
  ASSERT_TRUE(map.map(t, &host_after));
  EXPECT_EQ(host_after, host_before);

  // A host clock going backwards, and differences that do not fit 64 bits.
  EXPECT_EQ(map.add(t, host - kS), ClockSample::kRefused);
  EXPECT_EQ(map.add(std::numeric_limits<std::int64_t>::min(), host + kS), ClockSample::kRefused);
  EXPECT_EQ(map.refused(), 2u);
  std::int64_t out = 0;
  EXPECT_FALSE(map.map(std::numeric_limits<std::int64_t>::max(), &out));
}

TEST(ClockMap, NoMappingBeforeTheFirstSampleAndAfterReset) {
  ClockMap map;
  std::int64_t host = 0;
  EXPECT_FALSE(map.map(0, &host));
  EXPECT_EQ(map.add(5, 10), ClockSample::kAccepted);
  EXPECT_TRUE(map.map(5, &host));
  EXPECT_EQ(host, 10);
  map.reset();
  EXPECT_FALSE(map.map(5, &host));
  // After reset an earlier host time is fine again (a new stream).
  EXPECT_EQ(map.add(1, 2), ClockSample::kAccepted);
}

TEST(ClockMap, ConfigCheckNamesTheField) {
  EXPECT_EQ(agv::validate_clock_map_config(ClockMapConfig{}), "");
  ClockMapConfig c;
  c.bins = 1;
  EXPECT_NE(agv::validate_clock_map_config(c).find("bins"), std::string::npos);
  c = ClockMapConfig{};
  c.window_samples = 10;
  EXPECT_NE(agv::validate_clock_map_config(c).find("window_samples"), std::string::npos);
  c = ClockMapConfig{};
  c.relock_samples = 1;
  EXPECT_NE(agv::validate_clock_map_config(c).find("relock_samples"), std::string::npos);
  c = ClockMapConfig{};
  c.max_drift_ppm = std::numeric_limits<double>::quiet_NaN();
  EXPECT_NE(agv::validate_clock_map_config(c).find("max_drift_ppm"), std::string::npos);
  EXPECT_STREQ(agv::to_string(ClockSample::kJump), "jump");
}

}  // namespace
