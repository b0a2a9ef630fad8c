#include "agv/can/fake_can.hpp"

#include <algorithm>

namespace agv::can {

FakeCanNetwork::~FakeCanNetwork() {
  for (FakeCanEndpoint* ep : endpoints_) ep->net_ = nullptr;
}

std::unique_ptr<FakeCanEndpoint> FakeCanNetwork::create_endpoint(std::size_t rx_capacity) {
  std::unique_ptr<FakeCanEndpoint> ep(new FakeCanEndpoint(this, rx_capacity));
  endpoints_.push_back(ep.get());
  return ep;
}

void FakeCanNetwork::transmit(const FakeCanEndpoint* from, const hal::CanFrame& f) {
  hal::CanFrame stamped = f;
  stamped.t_ns = t_ns_;
  wire_.push_back(stamped);
  for (FakeCanEndpoint* ep : endpoints_) {
    if (ep != from) ep->deliver(stamped);
  }
}

void FakeCanNetwork::detach(FakeCanEndpoint* ep) {
  endpoints_.erase(std::remove(endpoints_.begin(), endpoints_.end(), ep), endpoints_.end());
}

FakeCanEndpoint::~FakeCanEndpoint() {
  if (net_) net_->detach(this);
}

namespace {
bool valid_frame(const hal::CanFrame& f) {
  return f.len <= 8 && f.id <= (f.extended ? 0x1FFFFFFFu : 0x7FFu);
}
}  // namespace

std::size_t FakeCanEndpoint::send_batch(const hal::CanFrame* frames, std::size_t count,
                                        hal::CanStatus* status) {
  batches_.push_back(count);
  return hal::CanBus::send_batch(frames, count, status);
}

hal::CanStatus FakeCanEndpoint::send(const hal::CanFrame& frame) {
  if (!valid_frame(frame)) {
    last_error_ = "invalid frame (len > 8 or ID out of range)";
    return hal::CanStatus::kInvalidArgument;
  }
  if (down_ || !net_) {
    ++stats_.tx_errors;
    last_error_ = "link down";
    return hal::CanStatus::kDown;
  }
  if (bus_off_) {
    ++stats_.tx_errors;
    last_error_ = "bus-off";
    return hal::CanStatus::kBusOff;
  }
  if (tx_full_) {
    ++stats_.tx_dropped_queue_full;
    return hal::CanStatus::kWouldBlock;
  }
  ++stats_.tx_ok;
  if (drop_tx_ > 0) {
    --drop_tx_;  // lost on the wire: the sender cannot tell
    return hal::CanStatus::kOk;
  }
  net_->transmit(this, frame);
  return hal::CanStatus::kOk;
}

hal::CanStatus FakeCanEndpoint::receive(hal::CanFrame* frame, std::int64_t /*timeout_ns*/) {
  if (down_ || !net_) return hal::CanStatus::kDown;
  if (rx_.empty()) return hal::CanStatus::kTimeout;
  *frame = rx_.front();
  rx_.pop_front();
  ++stats_.rx_frames;
  return hal::CanStatus::kOk;
}

hal::CanStatus FakeCanEndpoint::set_filters(const hal::CanFilter* filters, std::size_t count) {
  if (count > hal::kMaxCanFilters || (count > 0 && !filters)) {
    last_error_ = "too many filters";
    return hal::CanStatus::kInvalidArgument;
  }
  filters_.assign(filters, filters + count);
  return hal::CanStatus::kOk;
}

hal::CanBusState FakeCanEndpoint::state() const {
  if (down_ || !net_) return hal::CanBusState::kDown;
  if (bus_off_) return hal::CanBusState::kBusOff;
  const std::uint16_t m = std::max(counters_.tx, counters_.rx);
  if (m >= 128) return hal::CanBusState::kErrorPassive;
  if (m >= 96) return hal::CanBusState::kErrorWarning;
  return hal::CanBusState::kErrorActive;
}

void FakeCanEndpoint::set_bus_off(bool on) {
  if (on && !bus_off_) ++stats_.bus_off_count;
  bus_off_ = on;
  if (!on) counters_ = {};  // a restart clears the controller's counters
}

void FakeCanEndpoint::set_error_counters(std::uint16_t tx, std::uint16_t rx) {
  const bool was_passive = state() == hal::CanBusState::kErrorPassive;
  counters_ = {tx, rx};
  if (!was_passive && state() == hal::CanBusState::kErrorPassive) ++stats_.error_passive_count;
}

void FakeCanEndpoint::set_down(bool down) {
  if (down_ && !down) {
    ++stats_.restarts;
    rx_.clear();
  }
  down_ = down;
}

bool FakeCanEndpoint::accepts(const hal::CanFrame& f) const {
  if (filters_.empty()) return true;
  for (const hal::CanFilter& flt : filters_) {
    if (flt.extended == f.extended && (f.id & flt.mask) == (flt.id & flt.mask)) return true;
  }
  return false;
}

void FakeCanEndpoint::deliver(const hal::CanFrame& f) {
  if (down_ || !accepts(f)) return;
  if (rx_.size() >= rx_capacity_) {
    ++stats_.rx_dropped;
    return;
  }
  rx_.push_back(f);
}

}  // namespace agv::can
