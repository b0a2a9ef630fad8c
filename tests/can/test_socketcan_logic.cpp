// The SocketCAN driver's socket-free logic. The socket itself is tested by test_socketcan in the
// HIL virtual machine (this machine's kernel has no AF_CAN).
#include <gtest/gtest.h>
#include <linux/can.h>
#include <linux/can/error.h>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cstdint>

#include "agv/can/socketcan.hpp"
#include "agv/can/socketcan_logic.hpp"

using agv::hal::CanBusState;
using agv::hal::CanStatus;
namespace c = agv::can;

namespace {
c::ErrorFrameInfo classify(std::uint32_t cls, std::uint8_t d1 = 0, std::uint8_t tx = 0,
                           std::uint8_t rx = 0) {
  std::uint8_t d[8] = {0, d1, 0, 0, 0, 0, tx, rx};
  return c::classify_error_frame(CAN_ERR_FLAG | cls, d);
}
}  // namespace

TEST(ErrorFrames, Classification) {
  c::ErrorFrameInfo e = classify(CAN_ERR_BUSOFF);
  EXPECT_TRUE(e.bus_off);
  EXPECT_FALSE(e.controller);
  e = classify(CAN_ERR_CRTL, CAN_ERR_CRTL_RX_PASSIVE);
  EXPECT_TRUE(e.controller);
  EXPECT_TRUE(e.passive);
  EXPECT_FALSE(e.warning);
  e = classify(CAN_ERR_CRTL, CAN_ERR_CRTL_TX_WARNING | CAN_ERR_CRTL_RX_OVERFLOW);
  EXPECT_TRUE(e.warning);
  EXPECT_TRUE(e.rx_overflow);
  EXPECT_FALSE(e.passive);
  e = classify(CAN_ERR_CRTL | CAN_ERR_CNT, CAN_ERR_CRTL_ACTIVE, 0, 0);
  EXPECT_TRUE(e.back_to_active);
  EXPECT_TRUE(e.has_counters);
  e = classify(CAN_ERR_ACK | CAN_ERR_PROT | CAN_ERR_TRX | CAN_ERR_TX_TIMEOUT | CAN_ERR_RESTARTED);
  EXPECT_TRUE(e.no_ack && e.protocol && e.transceiver && e.tx_timeout && e.restarted);
  // Counters: with CAN_ERR_CNT, or non-zero in a controller frame (pre-5.19 drivers).
  e = classify(CAN_ERR_CNT, 0, 97, 3);
  EXPECT_TRUE(e.has_counters);
  EXPECT_EQ(e.tx_errors, 97);
  EXPECT_EQ(e.rx_errors, 3);
  e = classify(CAN_ERR_CRTL, CAN_ERR_CRTL_TX_PASSIVE, 130, 0);
  EXPECT_TRUE(e.has_counters);
  e = classify(CAN_ERR_PROT, 0, 5, 5);
  EXPECT_FALSE(e.has_counters);
}

TEST(ErrorFrames, BusStateTracking) {
  c::BusStateTracker t;
  EXPECT_EQ(t.state(), CanBusState::kDown);
  t.apply(classify(CAN_ERR_BUSOFF));
  EXPECT_EQ(t.state(), CanBusState::kDown);  // only a reopen leaves "down"
  t.reset_active();
  EXPECT_EQ(t.state(), CanBusState::kErrorActive);
  t.apply(classify(CAN_ERR_CRTL, CAN_ERR_CRTL_TX_WARNING, 96, 0));
  EXPECT_EQ(t.state(), CanBusState::kErrorWarning);
  t.apply(classify(CAN_ERR_CRTL, CAN_ERR_CRTL_TX_PASSIVE, 128, 0));
  t.apply(classify(CAN_ERR_CRTL, CAN_ERR_CRTL_TX_PASSIVE, 140, 0));  // no new transition
  EXPECT_EQ(t.state(), CanBusState::kErrorPassive);
  EXPECT_EQ(t.error_passive_count(), 1u);
  EXPECT_EQ(t.counters().tx, 140);
  t.apply(classify(CAN_ERR_BUSOFF));
  t.apply(classify(CAN_ERR_BUSOFF));
  EXPECT_EQ(t.state(), CanBusState::kBusOff);
  EXPECT_EQ(t.bus_off_count(), 1u);
  t.apply(classify(CAN_ERR_PROT));  // a protocol error does not leave bus-off
  EXPECT_EQ(t.state(), CanBusState::kBusOff);
  t.apply(classify(CAN_ERR_RESTARTED));
  EXPECT_EQ(t.state(), CanBusState::kErrorActive);
  EXPECT_EQ(t.counters().tx, 0);
  t.apply(classify(CAN_ERR_CRTL, CAN_ERR_CRTL_RX_PASSIVE));
  t.apply(classify(CAN_ERR_CRTL, CAN_ERR_CRTL_ACTIVE));
  EXPECT_EQ(t.state(), CanBusState::kErrorActive);
  EXPECT_EQ(t.error_passive_count(), 2u);
  t.set_down();
  EXPECT_EQ(t.state(), CanBusState::kDown);
}

TEST(SocketCanLogic, ErrnoMapping) {
  EXPECT_EQ(c::status_from_errno(EAGAIN), CanStatus::kWouldBlock);
  EXPECT_EQ(c::status_from_errno(ENOBUFS), CanStatus::kWouldBlock);
  EXPECT_EQ(c::status_from_errno(ENETDOWN), CanStatus::kDown);
  EXPECT_EQ(c::status_from_errno(ENODEV), CanStatus::kDown);
  EXPECT_EQ(c::status_from_errno(ENXIO), CanStatus::kDown);
  EXPECT_EQ(c::status_from_errno(EINVAL), CanStatus::kInvalidArgument);
  EXPECT_EQ(c::status_from_errno(EIO), CanStatus::kError);
  EXPECT_TRUE(c::is_link_gone_errno(ENETDOWN));
  EXPECT_FALSE(c::is_link_gone_errno(EAGAIN));
}

TEST(SocketCanLogic, RealtimeStampToMonotonic) {
  // Realtime is 1e18 when monotonic is 5e9; a stamp 2 ms before "now" maps 2 ms before mono now.
  const std::int64_t rt_now = 1'000'000'000'000'000'000, mono_now = 5'000'000'000;
  c::RxStampClock clock;
  EXPECT_EQ(clock.to_monotonic_ns(rt_now - 2'000'000, mono_now - 400, rt_now, mono_now + 400),
            mono_now - 2'000'000);
  // A stamp "after now" (realtime stepped back) is clamped to the last monotonic read.
  c::RxStampClock fresh;
  EXPECT_EQ(fresh.to_monotonic_ns(rt_now + 1000, mono_now - 400, rt_now, mono_now + 400),
            mono_now + 400);
}

// A burst of frames 50 us apart; the reads after the third are descheduled 6 ms between the first
// monotonic read and the realtime one (a loaded machine). Converted with its own reads alone,
// that frame lands 3 ms before the second one, and the odometry decoder dropped it as stale
// (hil_link_flap under load). The clock holds it 1 ns after the previous frame: held at the
// same time, it was still dropped by the filter and made replay refuse the recording
// (hil_garbage under load).
TEST(SocketCanLogic, ReceiveStampsStayInOrderWhenTheClockReadsAreDescheduled) {
  const std::int64_t offset = 5'000'000'000 - 1'000'000'000'000'000'000;  // mono - realtime
  c::RxStampClock clock;
  std::int64_t prev = INT64_MIN;
  for (int i = 0; i < 6; ++i) {
    const std::int64_t stamp_rt = 1'000'000'000'000'000'000 + i * 50'000;
    const std::int64_t read_mono = stamp_rt + offset + 300'000;  // read 0.3 ms after the stamp
    std::int64_t rt_now = read_mono - offset, mono_b = read_mono + 200;
    if (i == 2) {  // descheduled 6 ms between the first and the realtime read
      rt_now += 6'000'000;
      mono_b += 6'000'000;
    }
    const std::int64_t per_frame =
        std::min(stamp_rt + (read_mono + (mono_b - read_mono) / 2 - rt_now), mono_b);
    const std::int64_t t = clock.to_monotonic_ns(stamp_rt, read_mono, rt_now, mono_b);
    if (i == 2) {
      EXPECT_LT(per_frame, prev);  // converted alone: out of order
      EXPECT_EQ(t, prev + 1);      // held just after the previous frame
    } else {
      EXPECT_EQ(t, per_frame) << i;  // otherwise the plain conversion
      EXPECT_GT(t, prev) << i;
    }
    prev = t;
  }
}

// Two frames whose conversions come out equal (the second's clock reads descheduled by just the
// gap between them): the second is 1 ns later, never the same time.
TEST(SocketCanLogic, TwoFramesNeverShareAReceiveStamp) {
  const std::int64_t rt = 1'000'000'000'000'000'000, mono = 5'000'000'000;
  c::RxStampClock clock;
  const std::int64_t a = clock.to_monotonic_ns(rt, mono - 100, rt + 100, mono + 100);
  const std::int64_t b = clock.to_monotonic_ns(rt + 50'000, mono - 100, rt + 50'100, mono + 100);
  EXPECT_EQ(b, a + 1);
}

TEST(SocketCanLogic, Backoff) {
  EXPECT_EQ(c::next_backoff_ns(0, 50, 1000), 50);
  EXPECT_EQ(c::next_backoff_ns(50, 50, 1000), 100);
  EXPECT_EQ(c::next_backoff_ns(600, 50, 1000), 1000);
  EXPECT_EQ(c::next_backoff_ns(1000, 50, 1000), 1000);
}

// Without AF_CAN (this machine) or without the interface, the driver must degrade to "down"
// with a reason, never crash, and keep refusing quickly.
TEST(SocketCanBus, MissingInterfaceIsDownNotFatal) {
  c::SocketCanConfig cfg;
  cfg.iface = "agvnosuch0";
  cfg.reopen_backoff_min_ns = 10'000'000'000;  // no reopen attempt during the test
  c::SocketCanBus bus(cfg);
  EXPECT_FALSE(bus.is_open());
  EXPECT_EQ(bus.state(), CanBusState::kDown);
  EXPECT_STRNE(bus.last_error(), "");
  agv::hal::CanFrame f;
  f.id = 0x123;
  f.len = 1;
  EXPECT_EQ(bus.send(f), CanStatus::kDown);
  EXPECT_EQ(bus.receive(&f, 1'000'000), CanStatus::kDown);
  // A down link makes receive wait (up to the timeout) for the next reopen attempt.
  const auto t0 = std::chrono::steady_clock::now();
  EXPECT_EQ(bus.receive(&f, 20'000'000), CanStatus::kDown);
  const auto waited = std::chrono::steady_clock::now() - t0;
  EXPECT_GE(waited, std::chrono::milliseconds(15));
  EXPECT_LT(waited, std::chrono::seconds(2));
  EXPECT_EQ(bus.stats().tx_errors, 1u);
  f.len = 9;
  EXPECT_EQ(bus.send(f), CanStatus::kInvalidArgument);
  const agv::hal::CanFilter flt{0x100, 0x7FF, false};
  EXPECT_EQ(bus.set_filters(&flt, 1), CanStatus::kOk);  // kept for the next open
  cfg.iface = std::string(40, 'x');
  c::SocketCanBus bad(cfg);
  EXPECT_NE(std::string(bad.last_error()).find("invalid interface name"), std::string::npos);
}
