#include <gtest/gtest.h>

#include "agv/can/fake_can.hpp"
#include "agv/localizer/can_fault_monitor.hpp"
#include "agv/protocol/codec.hpp"

using agv::hal::CanBusState;
using agv::hal::CanFrame;
using agv::hal::CanStatus;

namespace {
CanFrame frame(std::uint32_t id, bool ext = false) {
  CanFrame f;
  f.id = id;
  f.extended = ext;
  f.len = 2;
  f.data[0] = 0xAB;
  return f;
}
}  // namespace

TEST(FakeCan, DeliversToOtherEndpointsWithNetworkTime) {
  agv::can::FakeCanNetwork net;
  auto a = net.create_endpoint(), b = net.create_endpoint(), c = net.create_endpoint();
  net.set_time_ns(123);
  ASSERT_EQ(a->send(frame(0x10)), CanStatus::kOk);
  CanFrame r;
  EXPECT_EQ(a->receive(&r, 0), CanStatus::kTimeout);  // no echo to the sender
  ASSERT_EQ(b->receive(&r, 0), CanStatus::kOk);
  EXPECT_EQ(r.id, 0x10u);
  EXPECT_EQ(r.t_ns, 123);
  EXPECT_EQ(r.data[0], 0xAB);
  ASSERT_EQ(c->receive(&r, 0), CanStatus::kOk);
  EXPECT_EQ(b->receive(&r, 0), CanStatus::kTimeout);
  EXPECT_EQ(a->stats().tx_ok, 1u);
  EXPECT_EQ(b->stats().rx_frames, 1u);
  EXPECT_EQ(net.wire_log().size(), 1u);
}

TEST(FakeCan, FiltersMatchIdMaskAndIdType) {
  agv::can::FakeCanNetwork net;
  auto a = net.create_endpoint(), b = net.create_endpoint();
  const agv::hal::CanFilter f[] = {{0x300, 0x7F0, false}};
  ASSERT_EQ(b->set_filters(f, 1), CanStatus::kOk);
  a->send(frame(0x305));
  a->send(frame(0x315));
  a->send(frame(0x305, true));
  CanFrame r;
  ASSERT_EQ(b->receive(&r, 0), CanStatus::kOk);
  EXPECT_EQ(r.id, 0x305u);
  EXPECT_FALSE(r.extended);
  EXPECT_EQ(b->receive(&r, 0), CanStatus::kTimeout);
  std::vector<agv::hal::CanFilter> many(agv::hal::kMaxCanFilters + 1);
  EXPECT_EQ(b->set_filters(many.data(), many.size()), CanStatus::kInvalidArgument);
}

TEST(FakeCan, InvalidFramesAreRefused) {
  agv::can::FakeCanNetwork net;
  auto a = net.create_endpoint();
  CanFrame f = frame(0x800);
  EXPECT_EQ(a->send(f), CanStatus::kInvalidArgument);
  f = frame(0x100);
  f.len = 9;
  EXPECT_EQ(a->send(f), CanStatus::kInvalidArgument);
  EXPECT_EQ(a->send(frame(0x1FFFFFFF, true)), CanStatus::kOk);
}

TEST(FakeCan, FaultsDropFullQueueBusOffDownUp) {
  agv::can::FakeCanNetwork net;
  auto a = net.create_endpoint(), b = net.create_endpoint(/*rx_capacity=*/2);
  CanFrame r;
  a->drop_next_tx(1);
  EXPECT_EQ(a->send(frame(1)), CanStatus::kOk);  // lost on the wire
  EXPECT_EQ(b->receive(&r, 0), CanStatus::kTimeout);

  a->set_tx_queue_full(true);
  EXPECT_EQ(a->send(frame(2)), CanStatus::kWouldBlock);
  EXPECT_EQ(a->stats().tx_dropped_queue_full, 1u);
  a->set_tx_queue_full(false);

  a->set_bus_off(true);
  EXPECT_EQ(a->state(), CanBusState::kBusOff);
  EXPECT_EQ(a->send(frame(3)), CanStatus::kBusOff);
  EXPECT_EQ(a->stats().bus_off_count, 1u);
  EXPECT_EQ(a->stats().tx_errors, 1u);
  a->set_bus_off(false);
  EXPECT_EQ(a->state(), CanBusState::kErrorActive);

  a->set_error_counters(100, 0);
  EXPECT_EQ(a->state(), CanBusState::kErrorWarning);
  a->set_error_counters(130, 2);
  EXPECT_EQ(a->state(), CanBusState::kErrorPassive);
  EXPECT_EQ(a->error_counters().tx, 130);
  EXPECT_EQ(a->stats().error_passive_count, 1u);
  a->set_error_counters(0, 0);

  // Receive queue overflow.
  a->send(frame(4));
  a->send(frame(5));
  a->send(frame(6));
  EXPECT_EQ(b->stats().rx_dropped, 1u);
  EXPECT_EQ(b->rx_queued(), 2u);

  b->set_down(true);
  EXPECT_EQ(b->state(), CanBusState::kDown);
  EXPECT_EQ(b->receive(&r, 0), CanStatus::kDown);
  EXPECT_EQ(b->send(frame(7)), CanStatus::kDown);
  a->send(frame(8));  // lost for b
  b->set_down(false);
  EXPECT_EQ(b->stats().restarts, 1u);
  EXPECT_EQ(b->receive(&r, 0), CanStatus::kTimeout);  // queue was cleared by the restart
  a->send(frame(9));
  ASSERT_EQ(b->receive(&r, 0), CanStatus::kOk);
  EXPECT_EQ(r.id, 9u);
}

TEST(FakeCan, EndpointsMayOutliveTheNetworkSafely) {
  std::unique_ptr<agv::can::FakeCanEndpoint> a;
  {
    agv::can::FakeCanNetwork net;
    a = net.create_endpoint();
  }
  EXPECT_EQ(a->send(frame(1)), CanStatus::kDown);
  EXPECT_EQ(a->state(), CanBusState::kDown);
}

// The receive path the real-time loop will use: bus -> OdometryDecoder, with a lost frame.
TEST(FakeCan, OdometryThroughTheFakeBus) {
  namespace p = agv::protocol;
  agv::can::FakeCanNetwork net;
  auto mc = net.create_endpoint(), loc = net.create_endpoint();
  p::ProtocolConfig cfg;
  p::OdometryDecoder dec(cfg);
  const agv::hal::CanFilter f{dec.can_id(), 0x7FF, false};
  loc->set_filters(&f, 1);
  int accepted = 0;
  for (int i = 0; i < 10; ++i) {
    net.set_time_ns(i * 10'000'000LL);
    agv::hal::CanFrame o;
    p::encode_odometry(cfg, 0.5, 0.5, static_cast<std::uint8_t>(i % 15), &o);
    if (i == 4) mc->drop_next_tx(1);
    mc->send(o);
    CanFrame r;
    while (loc->receive(&r, 0) == CanStatus::kOk) {
      p::OdomSample s;
      if (dec.decode(r, &s) == p::DecodeResult::kOk) {
        ++accepted;
        EXPECT_NEAR(s.v_mps, 0.5, 1e-9);
        EXPECT_EQ(s.lost_before, i == 5 ? 1u : 0u);
      }
    }
  }
  EXPECT_EQ(accepted, 9);
  EXPECT_EQ(dec.counters().lost_frames, 1u);
  EXPECT_EQ(dec.last_accepted_ns(), 90'000'000);
}

TEST(FakeCan, FaultMonitorMapsBusHealthToStatusFlags) {
  namespace p = agv::protocol;
  agv::can::FakeCanNetwork net;
  auto a = net.create_endpoint();
  agv::localizer::CanFaultMonitor mon;
  EXPECT_EQ(mon.update(a->state(), a->stats()), 0);
  a->set_tx_queue_full(true);
  a->send(frame(1));
  a->set_tx_queue_full(false);
  EXPECT_EQ(mon.update(a->state(), a->stats()), p::fault::kCanBusOff);  // a dropped frame
  EXPECT_EQ(mon.update(a->state(), a->stats()), 0);
  a->set_error_counters(130, 0);
  EXPECT_EQ(mon.update(a->state(), a->stats()), p::fault::kCanErrorPassive);
  a->set_error_counters(0, 0);
  EXPECT_EQ(mon.update(a->state(), a->stats()), 0);
  a->set_bus_off(true);
  a->set_bus_off(false);  // short bus-off between two status frames is still reported
  EXPECT_EQ(mon.update(a->state(), a->stats()), p::fault::kCanBusOff);
  a->set_down(true);
  EXPECT_EQ(mon.update(a->state(), a->stats()), p::fault::kCanBusOff);
  a->set_down(false);
  EXPECT_EQ(mon.update(a->state(), a->stats()), p::fault::kCanBusOff);  // the restart
  EXPECT_EQ(mon.update(a->state(), a->stats()), 0);
}
