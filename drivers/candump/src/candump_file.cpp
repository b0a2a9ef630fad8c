#include "agv/can/candump_file.hpp"

#include <climits>
#include <filesystem>
#include <fstream>

namespace agv::can {

bool read_candump_file(const std::string& path, std::vector<protocol::CandumpRecord>* out,
                       std::string* error) {
  // A regular file of bounded size only (docs/design/security.md): never /dev/zero or a FIFO.
  constexpr std::uintmax_t kMaxBytes = 256u << 20;
  std::error_code ec;
  if (!std::filesystem::is_regular_file(path, ec) ||
      std::filesystem::file_size(path, ec) > kMaxBytes || ec) {
    if (error) *error = path + ": not a regular file of at most 256 MiB";
    return false;
  }
  std::ifstream in(path);
  if (!in) {
    if (error) *error = path + ": cannot open";
    return false;
  }
  std::vector<protocol::CandumpRecord> recs;
  std::string line, why;
  int n = 0;
  while (std::getline(in, line)) {
    ++n;
    if (line.empty() || line == "\r") continue;
    protocol::CandumpRecord r;
    if (!protocol::parse_candump_line(line, &r, &why)) {
      if (error) *error = path + ":" + std::to_string(n) + ": " + why;
      return false;
    }
    recs.push_back(std::move(r));
  }
  *out = std::move(recs);
  return true;
}

CandumpWriter::~CandumpWriter() { close(); }

bool CandumpWriter::open(const std::string& path, std::string* error) {
  close();
  f_ = std::fopen(path.c_str(), "w");
  ok_ = f_ != nullptr;
  if (!f_ && error) *error = path + ": cannot create";
  return ok_;
}

bool CandumpWriter::write(const protocol::CandumpRecord& rec) {
  if (!f_) return false;
  const std::string s = protocol::format_candump_line(rec) + "\n";
  if (std::fwrite(s.data(), 1, s.size(), f_) != s.size()) ok_ = false;
  return ok_;
}

bool CandumpWriter::write(const hal::CanFrame& frame, const std::string& iface, std::int64_t t_ns) {
  protocol::CandumpRecord r;
  r.t_ns = t_ns;
  r.iface = iface;
  r.frame = frame;
  return write(r);
}

bool CandumpWriter::close() {
  if (!f_) return ok_;
  if (std::fclose(f_) != 0) ok_ = false;
  f_ = nullptr;
  return ok_;
}

CandumpReplayBus::CandumpReplayBus(std::vector<protocol::CandumpRecord> records, std::string iface,
                                   std::int64_t time_offset_ns)
    : records_(std::move(records)), iface_(std::move(iface)), offset_ns_(time_offset_ns) {}

bool CandumpReplayBus::wanted(const protocol::CandumpRecord& r) const {
  if (!iface_.empty() && r.iface != iface_) return false;
  if (r.error_frame || r.rtr) return false;
  if (filters_.empty()) return true;
  for (const hal::CanFilter& f : filters_) {
    if (f.extended == r.frame.extended && (r.frame.id & f.mask) == (f.id & f.mask)) return true;
  }
  return false;
}

hal::CanStatus CandumpReplayBus::send(const hal::CanFrame& frame) {
  if (frame.len > 8) return hal::CanStatus::kInvalidArgument;
  sent_.push_back(frame);
  if (tx_log_) tx_log_->write(frame, tx_iface_, last_t_ns_);
  ++stats_.tx_ok;
  return hal::CanStatus::kOk;
}

hal::CanStatus CandumpReplayBus::receive(hal::CanFrame* frame, std::int64_t /*timeout_ns*/) {
  while (next_ < records_.size()) {
    const protocol::CandumpRecord& r = records_[next_++];
    if (r.error_frame && (iface_.empty() || r.iface == iface_)) ++stats_.rx_error_frames;
    if (!wanted(r)) continue;
    *frame = r.frame;
    frame->t_ns = r.t_ns + offset_ns_;
    last_t_ns_ = r.t_ns;
    ++stats_.rx_frames;
    return hal::CanStatus::kOk;
  }
  return hal::CanStatus::kEndOfStream;
}

hal::CanStatus CandumpReplayBus::set_filters(const hal::CanFilter* filters, std::size_t count) {
  if (count > hal::kMaxCanFilters || (count > 0 && !filters)) {
    return hal::CanStatus::kInvalidArgument;
  }
  filters_.assign(filters, filters + count);
  return hal::CanStatus::kOk;
}

std::int64_t CandumpReplayBus::peek_time_ns() const {
  for (std::size_t i = next_; i < records_.size(); ++i) {
    if (wanted(records_[i])) return records_[i].t_ns + offset_ns_;
  }
  return INT64_MAX;
}

}  // namespace agv::can
