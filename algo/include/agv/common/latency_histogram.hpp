// Fixed-size latency histogram for the real-time loop: recording never allocates, percentiles
// are exact to one bucket (log-spaced, ~4 % relative width from 1 us to ~70 s).
#pragma once

#include <array>
#include <cmath>
#include <cstdint>

namespace agv {

class LatencyHistogram {
 public:
  static constexpr int kBuckets = 512;

  void record_ns(std::int64_t v_ns) {
    ++count_;
    if (v_ns < 0) {
      ++negative_;
      v_ns = 0;
    }
    if (v_ns > max_ns_) max_ns_ = v_ns;
    sum_ns_ += v_ns;
    ++buckets_[static_cast<size_t>(bucket_of(v_ns))];
  }

  std::uint64_t count() const { return count_; }
  std::uint64_t negative_count() const { return negative_; }
  std::int64_t max_ns() const { return max_ns_; }
  // Sum of the recorded values (negative ones as 0): the Prometheus histogram's _sum.
  std::int64_t sum_ns() const { return sum_ns_; }
  // Raw bucket b's count and its upper edge (b < kBuckets - 1; the last bucket is open), for
  // exporters that re-bin at other bounds (algo/src/diag/metrics.cpp).
  std::uint64_t bucket_count(int b) const { return buckets_[static_cast<size_t>(b)]; }
  static std::int64_t bucket_upper_edge_ns(int b) { return upper_edge_ns(b); }

  // Upper edge of the bucket holding the p-quantile (0 < p <= 1); 0 when empty.
  std::int64_t percentile_ns(double p) const {
    if (count_ == 0) return 0;
    const auto target = static_cast<std::uint64_t>(std::ceil(p * static_cast<double>(count_)));
    std::uint64_t acc = 0;
    for (int b = 0; b < kBuckets; ++b) {
      acc += buckets_[static_cast<size_t>(b)];
      if (acc >= target && acc > 0) {
        const std::int64_t edge = upper_edge_ns(b);
        return edge < max_ns_ ? edge : max_ns_;
      }
    }
    return max_ns_;
  }

  void reset() { *this = LatencyHistogram(); }

 private:
  // Bucket 0: < 1 us. Then 24 buckets per octave above 1 us.
  static constexpr double kPerOctave = 24.0;
  static int bucket_of(std::int64_t v_ns) {
    if (v_ns < 1000) return 0;
    const int b = 1 + static_cast<int>(std::log2(static_cast<double>(v_ns) / 1000.0) * kPerOctave);
    return b < kBuckets - 1 ? b : kBuckets - 1;
  }
  static std::int64_t upper_edge_ns(int b) {
    if (b == 0) return 1000;
    return static_cast<std::int64_t>(1000.0 * std::exp2(static_cast<double>(b) / kPerOctave));
  }

  std::array<std::uint64_t, kBuckets> buckets_{};
  std::uint64_t count_ = 0;
  std::uint64_t negative_ = 0;
  std::int64_t max_ns_ = 0;
  std::int64_t sum_ns_ = 0;
};

}  // namespace agv
