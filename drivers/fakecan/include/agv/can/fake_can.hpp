// In-process fake CAN bus: several endpoints (each an agv::hal::CanBus) share one FakeCanNetwork;
// a frame sent by one endpoint is delivered to every other endpoint whose filters accept it,
// stamped with the network's simulated time. Faults are injected per endpoint. Single-threaded,
// never sleeps: receive() returns kTimeout at once when nothing is queued (tests drive time with
// set_time_ns). The network must outlive its endpoints.
#pragma once

#include <cstddef>
#include <cstdint>
#include <deque>
#include <memory>
#include <string>
#include <vector>

#include "agv/hal/can_bus.hpp"

namespace agv::can {

class FakeCanEndpoint;

class FakeCanNetwork {
 public:
  FakeCanNetwork() = default;
  FakeCanNetwork(const FakeCanNetwork&) = delete;
  FakeCanNetwork& operator=(const FakeCanNetwork&) = delete;
  ~FakeCanNetwork();

  // rx_capacity: frames an endpoint queues before new ones are dropped (counted in rx_dropped).
  std::unique_ptr<FakeCanEndpoint> create_endpoint(std::size_t rx_capacity = 256);

  void set_time_ns(std::int64_t t_ns) { t_ns_ = t_ns; }
  void advance_ns(std::int64_t dt_ns) { t_ns_ += dt_ns; }
  std::int64_t time_ns() const { return t_ns_; }
  // Frames that reached the wire (for assertions): every successful send in order.
  const std::vector<hal::CanFrame>& wire_log() const { return wire_; }

 private:
  friend class FakeCanEndpoint;
  void transmit(const FakeCanEndpoint* from, const hal::CanFrame& f);
  void detach(FakeCanEndpoint* ep);
  std::vector<FakeCanEndpoint*> endpoints_;
  std::vector<hal::CanFrame> wire_;
  std::int64_t t_ns_ = 0;
};

class FakeCanEndpoint : public hal::CanBus {
 public:
  ~FakeCanEndpoint() override;

  hal::CanStatus send(const hal::CanFrame& frame) override;
  // send() for each; the batch's size is kept (batch_sizes) so tests see how frames were handed
  // over.
  std::size_t send_batch(const hal::CanFrame* frames, std::size_t count,
                         hal::CanStatus* status) override;
  const std::vector<std::size_t>& batch_sizes() const { return batches_; }
  hal::CanStatus receive(hal::CanFrame* frame, std::int64_t timeout_ns) override;
  hal::CanStatus set_filters(const hal::CanFilter* filters, std::size_t count) override;
  hal::CanBusState state() const override;
  hal::CanErrorCounters error_counters() const override { return counters_; }
  hal::CanStats stats() const override { return stats_; }
  const char* last_error() const override { return last_error_.c_str(); }

  // ---- fault injection
  // The next n successfully "sent" frames are lost on the wire (send returns kOk).
  void drop_next_tx(int n) { drop_tx_ = n; }
  // While set, send() returns kWouldBlock (counted) as if the transmit queue were full.
  void set_tx_queue_full(bool full) { tx_full_ = full; }
  // Enters / leaves bus-off. While bus-off, send() returns kBusOff; frames are still received.
  void set_bus_off(bool on);
  // Sets the error counters and derives warning/passive state from them (96 / 128).
  void set_error_counters(std::uint16_t tx, std::uint16_t rx);
  // Link down: send/receive return kDown and incoming frames are lost. Up again counts a
  // restart (as the SocketCAN driver's reopen does) and clears the receive queue.
  void set_down(bool down);
  std::size_t rx_queued() const { return rx_.size(); }

 private:
  friend class FakeCanNetwork;
  FakeCanEndpoint(FakeCanNetwork* net, std::size_t rx_capacity)
      : net_(net), rx_capacity_(rx_capacity) {}
  bool accepts(const hal::CanFrame& f) const;
  void deliver(const hal::CanFrame& f);

  FakeCanNetwork* net_;
  std::size_t rx_capacity_;
  std::deque<hal::CanFrame> rx_;
  std::vector<hal::CanFilter> filters_;
  hal::CanStats stats_;
  hal::CanErrorCounters counters_;
  std::string last_error_;
  std::vector<std::size_t> batches_;
  int drop_tx_ = 0;
  bool tx_full_ = false;
  bool bus_off_ = false;
  bool down_ = false;
};

}  // namespace agv::can
