#include "agv/common/clock_map.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <sstream>

namespace agv {

std::string validate_clock_map_config(const ClockMapConfig& c) {
  std::ostringstream e;
  if (c.bins < 2) {
    e << "clock map: bins " << c.bins << " must be >= 2";
  } else if (c.window_samples < 2 * c.bins) {
    e << "clock map: window_samples " << c.window_samples << " must be >= 2 * bins (" << 2 * c.bins
      << ")";
  } else if (c.min_drift_span_ns <= 0) {
    e << "clock map: min_drift_span_ns must be > 0";
  } else if (c.early_tolerance_ns < 0) {
    e << "clock map: early_tolerance_ns must be >= 0";
  } else if (c.late_threshold_ns <= 0) {
    e << "clock map: late_threshold_ns must be > 0";
  } else if (c.relock_samples < 2 || c.relock_samples > c.window_samples) {
    e << "clock map: relock_samples " << c.relock_samples << " must be in [2, window_samples]";
  } else if (c.relock_tolerance_ns <= 0) {
    e << "clock map: relock_tolerance_ns must be > 0";
  } else if (!(c.max_drift_ppm > 0.0) || !std::isfinite(c.max_drift_ppm)) {
    e << "clock map: max_drift_ppm must be a positive number";
  }
  return e.str();
}

const char* to_string(ClockSample s) {
  switch (s) {
    case ClockSample::kAccepted:
      return "accepted";
    case ClockSample::kJump:
      return "jump";
    case ClockSample::kHeldBack:
      return "held back";
    case ClockSample::kRefused:
      return "refused";
  }
  return "unknown clock sample";
}

ClockMap::ClockMap(ClockMapConfig config) : cfg_(config) {}

void ClockMap::reset() {
  window_.clear();
  candidates_.clear();
  have_host_ = false;
  last_host_ns_ = 0;
  ref_device_ns_ = 0;
  ref_diff_ns_ = 0;
  drift_ppm_ = 0.0;
  drift_locked_ = false;
}

std::int64_t ClockMap::offset_ns() const { return ref_diff_ns_; }

bool ClockMap::map(std::int64_t device_ns, std::int64_t* host_ns) const {
  if (window_.empty() || host_ns == nullptr) return false;
  std::int64_t since_ref = 0;
  if (__builtin_sub_overflow(device_ns, ref_device_ns_, &since_ref)) return false;
  const double correction = drift_ppm_ * 1e-6 * static_cast<double>(since_ref);
  if (!(std::fabs(correction) < 1e18)) return false;
  std::int64_t out = 0;
  if (__builtin_add_overflow(device_ns, ref_diff_ns_, &out)) return false;
  if (__builtin_add_overflow(out, std::llround(correction), &out)) return false;
  *host_ns = out;
  return true;
}

bool ClockMap::consistent_with_lock(const Pair& p, std::int64_t host_rx_ns) const {
  if (p.device_ns <= window_.back().device_ns) return false;
  std::int64_t mapped = 0;
  if (!map(p.device_ns, &mapped)) return false;
  // Latency of this sample above the envelope; negative: mapped after it was received.
  std::int64_t above = 0;
  if (__builtin_sub_overflow(host_rx_ns, mapped, &above)) return false;
  if (above > cfg_.late_threshold_ns) return false;
  const bool floor_settled = static_cast<int>(window_.size()) >= cfg_.relock_samples;
  return !(floor_settled && above < -cfg_.early_tolerance_ns);
}

bool ClockMap::candidates_agree(const Pair& p) const {
  if (candidates_.empty() || p.device_ns <= candidates_.back().device_ns) return false;
  for (const Pair& c : candidates_) {
    std::int64_t d = 0;
    if (__builtin_sub_overflow(p.diff_ns, c.diff_ns, &d) || d > cfg_.relock_tolerance_ns ||
        d < -cfg_.relock_tolerance_ns) {
      return false;
    }
  }
  return true;
}

ClockSample ClockMap::add(std::int64_t device_ns, std::int64_t host_rx_ns) {
  Pair p{device_ns, 0};
  if ((have_host_ && host_rx_ns < last_host_ns_) ||
      __builtin_sub_overflow(host_rx_ns, device_ns, &p.diff_ns)) {
    ++refused_;
    return ClockSample::kRefused;
  }
  have_host_ = true;
  last_host_ns_ = host_rx_ns;
  if (window_.empty() || consistent_with_lock(p, host_rx_ns)) {
    candidates_.clear();
    window_.push_back(p);
    while (static_cast<int>(window_.size()) > cfg_.window_samples) window_.pop_front();
    refit();
    return ClockSample::kAccepted;
  }
  ++held_back_;
  if (!candidates_agree(p)) candidates_.clear();
  candidates_.push_back(p);
  if (static_cast<int>(candidates_.size()) < cfg_.relock_samples) return ClockSample::kHeldBack;
  window_.assign(candidates_.begin(), candidates_.end());
  candidates_.clear();
  ++jumps_;
  refit();
  return ClockSample::kJump;
}

void ClockMap::refit() {
  const Pair& newest = window_.back();
  ref_device_ns_ = newest.device_ns;
  std::int64_t span = 0;
  const bool span_fits =
      !__builtin_sub_overflow(newest.device_ns, window_.front().device_ns, &span);
  std::int64_t min_diff = std::numeric_limits<std::int64_t>::max();
  for (const Pair& q : window_) min_diff = std::min(min_diff, q.diff_ns);
  ref_diff_ns_ = min_diff;
  drift_ppm_ = 0.0;
  drift_locked_ = false;
  if (!span_fits || span < cfg_.min_drift_span_ns) return;

  // Lower envelope: the smallest host - device of each bin along the device time.
  const int bins = cfg_.bins;
  std::vector<const Pair*> lowest(static_cast<std::size_t>(bins), nullptr);
  const std::int64_t first = window_.front().device_ns;
  for (const Pair& q : window_) {
    const double frac = static_cast<double>(q.device_ns - first) / static_cast<double>(span);
    const int b = std::min(bins - 1, static_cast<int>(frac * bins));
    const Pair*& slot = lowest[static_cast<std::size_t>(b)];
    if (slot == nullptr || q.diff_ns < slot->diff_ns) slot = &q;
  }
  // Least squares through the minima, in coordinates relative to the newest sample and the
  // smallest difference (doubles keep ns resolution over spans of hours there).
  double n = 0, sx = 0, sy = 0, sxx = 0, sxy = 0;
  for (const Pair* q : lowest) {
    if (q == nullptr) continue;
    const double x = static_cast<double>(q->device_ns - newest.device_ns);
    const double y = static_cast<double>(q->diff_ns - min_diff);
    n += 1;
    sx += x;
    sy += y;
    sxx += x * x;
    sxy += x * y;
  }
  const double den = n * sxx - sx * sx;
  if (n < 2 || !(den > 0.0)) return;
  const double slope = (n * sxy - sx * sy) / den;
  const double intercept = (sy - slope * sx) / n;
  if (!(std::fabs(slope * 1e6) <= cfg_.max_drift_ppm)) return;
  drift_ppm_ = slope * 1e6;
  drift_locked_ = true;
  ref_diff_ns_ = min_diff + std::llround(intercept);
}

}  // namespace agv
