#include <gtest/gtest.h>

#include "agv/common/latency_histogram.hpp"

using agv::LatencyHistogram;

TEST(LatencyHistogram, PercentilesWithinOneBucket) {
  LatencyHistogram h;
  for (int i = 1; i <= 1000; ++i) h.record_ns(i * 10000);  // 10 us .. 10 ms uniform
  EXPECT_EQ(h.count(), 1000u);
  const double p50 = static_cast<double>(h.percentile_ns(0.5));
  const double p99 = static_cast<double>(h.percentile_ns(0.99));
  EXPECT_NEAR(p50, 5.0e6, 0.04 * 5.0e6);
  EXPECT_NEAR(p99, 9.9e6, 0.04 * 9.9e6);
  EXPECT_EQ(h.percentile_ns(1.0), 10000000);
  EXPECT_EQ(h.max_ns(), 10000000);
}

TEST(LatencyHistogram, EmptyAndNegative) {
  LatencyHistogram h;
  EXPECT_EQ(h.percentile_ns(0.99), 0);
  h.record_ns(-5);
  EXPECT_EQ(h.negative_count(), 1u);
  EXPECT_EQ(h.percentile_ns(0.5), 0);
}
