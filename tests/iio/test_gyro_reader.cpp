// imu.source iio in the firmware: the reader thread hands a hal::Imu's samples to the output
// loop, which fuses them; a device that fails is reopened. A fake device, no IIO needed.
#include <gtest/gtest.h>

#include <atomic>
#include <chrono>
#include <memory>
#include <thread>

#include "agv/adapters/stepped_clock.hpp"
#include "agv/config/config.hpp"
#include "agv/protocol/codec.hpp"
#include "gyro_reader.hpp"
#include "output_loop.hpp"

namespace {

using agv::hal::ImuStatus;

// Delivers `first` samples, then fails once (kDisconnected), then delivers forever.
class FakeImu final : public agv::hal::Imu {
 public:
  explicit FakeImu(int first) : first_(first) {}
  ImuStatus start() override {
    ++starts;
    return ImuStatus::kOk;
  }
  void stop() override {}
  ImuStatus read(agv::hal::GyroSample* out, std::size_t max, std::size_t* n,
                 std::int64_t) override {
    *n = 0;
    if (sent_ == first_ && !failed_) {
      failed_ = true;
      return ImuStatus::kDisconnected;
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(1));
    if (max == 0) return ImuStatus::kTimeout;
    out[0].t_ns = 1'000'000 * (sent_ + 1);
    out[0].gyro_z_radps = 0.1;
    ++sent_;
    *n = 1;
    return ImuStatus::kOk;
  }
  agv::hal::ImuStats stats() const override { return {}; }
  const char* last_error() const override { return "fake"; }
  std::atomic<int> starts{0};

 private:
  int first_;
  int sent_ = 0;
  bool failed_ = false;
};

TEST(GyroReader, SamplesReachTheCoreAndAFailedDeviceIsReopened) {
  agv::app::GyroRing ring;
  auto imu = std::make_unique<FakeImu>(5);
  FakeImu* fake = imu.get();
  agv::app::GyroReader reader(std::move(imu), ring);
  std::string err;
  ASSERT_TRUE(reader.start(&err)) << err;
  // The reopen waits a second after the failure.
  const auto t_end = std::chrono::steady_clock::now() + std::chrono::seconds(10);
  while (reader.counters().reopens == 0 && std::chrono::steady_clock::now() < t_end) {
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
  std::this_thread::sleep_for(std::chrono::milliseconds(50));
  reader.stop();
  const auto c = reader.counters();
  EXPECT_EQ(c.failures, 1u);
  EXPECT_EQ(c.reopens, 1u);
  EXPECT_EQ(fake->starts.load(), 2);
  EXPECT_GT(c.samples, 5u);

  agv::config::Config cfg;
  cfg.imu.source = agv::config::ImuSource::kIio;
  cfg.imu.iio_device = "fake";
  const auto lc = agv::app::localizer_config(cfg);
  EXPECT_TRUE(lc.gyro_expected);
  EXPECT_FALSE(lc.protocol.gyro.enabled);  // no CAN gyro filter for an IIO gyro
  agv::localizer::Localizer core(lc);
  agv::adapters::SteppedClock clock;
  agv::app::FixRing fixes;
  agv::app::OutputLoop loop(core, nullptr, clock, nullptr, fixes, 0);
  loop.set_live_gyro(&ring);
  loop.take_inputs(1'000'000'000);
  EXPECT_EQ(core.stats().gyro_samples, c.samples);  // every sample handed to fusion
}

// An IIO gyro that never delivers raises FaultImuTimeout as a silent CAN gyro does; one that
// delivers does not.
TEST(GyroReader, SilentIioGyroIsAnImuTimeout) {
  namespace p = agv::protocol;
  agv::config::Config cfg;
  cfg.imu.source = agv::config::ImuSource::kIio;
  cfg.imu.iio_device = "fake";
  const auto lc = agv::app::localizer_config(cfg);
  auto faults_at = [&](agv::localizer::Localizer& core, std::int64_t t_ns) {
    agv::localizer::OutFrames out;
    agv::localizer::CanOutput(lc.protocol).encode(core.tick(t_ns), &out);
    for (int i = 0; i < out.n; ++i) {
      if (out.frame[i].id != p::can_id_of(lc.protocol, p::Msg::kStatus)) continue;
      p::StatusOut st;
      EXPECT_TRUE(p::decode_status(lc.protocol, out.frame[i], &st));
      return static_cast<int>(st.faults);
    }
    ADD_FAILURE() << "no status frame";
    return 0;
  };
  const std::int64_t kMs = 1'000'000;
  agv::localizer::Localizer silent(lc);
  faults_at(silent, 1000 * kMs);
  EXPECT_NE(faults_at(silent, 1000 * kMs + lc.gyro_timeout_ns + 10 * kMs) & p::fault::kImuTimeout,
            0);
  agv::localizer::Localizer fed(lc);
  faults_at(fed, 1000 * kMs);
  fed.on_gyro(1000 * kMs + lc.gyro_timeout_ns, 0.1);
  EXPECT_EQ(faults_at(fed, 1000 * kMs + lc.gyro_timeout_ns + 10 * kMs) & p::fault::kImuTimeout, 0);
}

TEST(GyroReader, StartFailureIsReported) {
  agv::app::GyroRing ring;
  agv::app::GyroReader none(nullptr, ring);
  std::string err;
  EXPECT_FALSE(none.start(&err));
  EXPECT_FALSE(err.empty());
}

}  // namespace
