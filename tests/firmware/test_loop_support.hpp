// Test doubles for the loop tests: a fixed-capacity CAN bus that never allocates, and the
// localizer core driven through the firmware's output step on a stepped clock.
#pragma once

#include <array>
#include <cstddef>

#include "agv/adapters/stepped_clock.hpp"
#include "agv/hal/can_bus.hpp"
#include "config.hpp"
#include "output_loop.hpp"

namespace agv::test {

class StaticBus final : public hal::CanBus {
 public:
  static constexpr std::size_t kCap = 4096;
  hal::CanStatus send(const hal::CanFrame& f) override {
    if (fail_sends) {
      ++stats_.tx_errors;
      return hal::CanStatus::kError;
    }
    if (sent_n < kCap) sent[sent_n++] = f;
    ++stats_.tx_ok;
    return hal::CanStatus::kOk;
  }
  hal::CanStatus receive(hal::CanFrame* f, std::int64_t) override {
    if (rx_head == rx_n) return hal::CanStatus::kTimeout;
    *f = rx[rx_head++];
    ++stats_.rx_frames;
    return hal::CanStatus::kOk;
  }
  hal::CanStatus set_filters(const hal::CanFilter*, std::size_t) override {
    return hal::CanStatus::kOk;
  }
  hal::CanBusState state() const override { return bus_state; }
  hal::CanErrorCounters error_counters() const override { return {}; }
  hal::CanStats stats() const override { return stats_; }
  const char* last_error() const override { return ""; }

  void inject(const hal::CanFrame& f) {
    if (rx_n < kCap) rx[rx_n++] = f;
  }
  void clear_sent() { sent_n = 0; }

  std::array<hal::CanFrame, kCap> sent{};
  std::size_t sent_n = 0;
  std::array<hal::CanFrame, kCap> rx{};
  std::size_t rx_n = 0, rx_head = 0;
  bool fail_sends = false;
  hal::CanBusState bus_state = hal::CanBusState::kErrorActive;

 private:
  hal::CanStats stats_;
};

// The core plus the output step (the one CAN writer) on a stepped clock: what every mode runs.
class CoreHarness {
 public:
  CoreHarness(const config::Config& cfg, hal::CanBus* bus)
      : core_(app::localizer_config(cfg)), loop_(core_, bus, clock_, nullptr, fixes_, 0) {}
  void on_odometry(std::int64_t t_ns, double v, double w) { core_.on_odometry(t_ns, v, w); }
  // Drains the bus into the core.
  void poll_can() { loop_.take_inputs(INT64_MIN); }
  void on_fix(const vision::LandmarkFix& fix, std::int64_t t_exposure_ns,
              std::int64_t t_arrival_ns = INT64_MAX) {
    core_.on_fix(fix, t_exposure_ns, t_arrival_ns);
  }
  // A fix handed over by the vision worker, ready at t_arrival_ns (pose_on_fix path).
  bool fix_arrives(const vision::LandmarkFix& fix, std::int64_t t_exposure_ns,
                   std::int64_t t_arrival_ns) {
    app::FixRecord r;
    r.fix = fix;
    r.t_exposure_ns = t_exposure_ns;
    r.t_done_ns = t_arrival_ns;
    fixes_.push(r);
    clock_.sleep_until_ns(t_arrival_ns);
    return loop_.on_wake(t_arrival_ns);
  }
  void tick(std::int64_t t_ns, app::TickRecord* rec = nullptr,
            const app::CameraState& cam = app::CameraState{}) {
    clock_.sleep_until_ns(t_ns);
    loop_.tick(t_ns, cam, rec);
  }
  const localizer::OutputStats& stats() const { return core_.stats(); }
  const fusion::Ekf& ekf() const { return core_.ekf(); }
  const protocol::OdometryDecoder& odometry_decoder() const { return core_.odometry_decoder(); }

 private:
  adapters::SteppedClock clock_;
  localizer::Localizer core_;
  app::FixRing fixes_;
  app::OutputLoop loop_;
};

}  // namespace agv::test
