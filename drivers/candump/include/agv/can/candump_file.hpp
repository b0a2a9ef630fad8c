// `candump -l` log files (line format: agv/protocol/candump.hpp). A capture made on the vehicle
// (`candump -l can0`) can be replayed into the loop with CandumpReplayBus, and frames the loop
// writes with CandumpWriter can be inspected with can-utils (`canplayer`, `log2asc`, ...).
#pragma once

#include <cstdint>
#include <cstdio>
#include <string>
#include <vector>

#include "agv/hal/can_bus.hpp"
#include "agv/protocol/candump.hpp"

namespace agv::can {

// Reads every line; empty lines are skipped. false + *error "path:line: reason" on the first
// malformed line (nothing is returned then).
bool read_candump_file(const std::string& path, std::vector<protocol::CandumpRecord>* out,
                       std::string* error);

class CandumpWriter {
 public:
  CandumpWriter() = default;
  ~CandumpWriter();
  CandumpWriter(const CandumpWriter&) = delete;
  CandumpWriter& operator=(const CandumpWriter&) = delete;
  // Creates/truncates the file. false + *error when it cannot be opened.
  bool open(const std::string& path, std::string* error);
  // One line per frame; t_ns is the frame's log time (candump uses the wall clock).
  bool write(const hal::CanFrame& frame, const std::string& iface, std::int64_t t_ns);
  bool write(const protocol::CandumpRecord& rec);
  bool close();  // flushes; false when a write failed

 private:
  std::FILE* f_ = nullptr;
  bool ok_ = true;
};

// A CanBus that returns the data frames of a log in order (error and remote frames are skipped
// and counted as rx_error_frames / ignored). Frame time = log time + time_offset_ns, to move a
// wall-clock capture onto the monotonic time line of a replay. Never sleeps: pacing is the
// caller's job. Sent frames are kept (sent()) and written to `tx_log` when one is attached.
class CandumpReplayBus : public hal::CanBus {
 public:
  // iface: only records of this interface are replayed ("" = all).
  CandumpReplayBus(std::vector<protocol::CandumpRecord> records, std::string iface = "",
                   std::int64_t time_offset_ns = 0);

  hal::CanStatus send(const hal::CanFrame& frame) override;
  hal::CanStatus receive(hal::CanFrame* frame, std::int64_t timeout_ns) override;
  hal::CanStatus set_filters(const hal::CanFilter* filters, std::size_t count) override;
  hal::CanBusState state() const override { return hal::CanBusState::kErrorActive; }
  hal::CanErrorCounters error_counters() const override { return {}; }
  hal::CanStats stats() const override { return stats_; }
  const char* last_error() const override { return ""; }

  // Time of the next data frame (INT64_MAX at the end): lets a replay loop pace itself.
  std::int64_t peek_time_ns() const;
  void attach_tx_log(CandumpWriter* w, std::string iface) {
    tx_log_ = w;
    tx_iface_ = std::move(iface);
  }
  const std::vector<hal::CanFrame>& sent() const { return sent_; }

 private:
  bool wanted(const protocol::CandumpRecord& r) const;
  std::vector<protocol::CandumpRecord> records_;
  std::string iface_;
  std::int64_t offset_ns_;
  std::size_t next_ = 0;
  std::int64_t last_t_ns_ = 0;
  std::vector<hal::CanFilter> filters_;
  std::vector<hal::CanFrame> sent_;
  CandumpWriter* tx_log_ = nullptr;
  std::string tx_iface_;
  hal::CanStats stats_;
};

}  // namespace agv::can
