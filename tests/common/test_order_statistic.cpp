// select_kth against std::nth_element: the same value for every k, on sizes around the
// insertion-sort cut-off and larger, with distinct values, many repeats, sorted and reversed
// input, and residual-like data; a NaN neither hangs nor crashes it.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <random>
#include <vector>

#include "agv/common/order_statistic.hpp"

namespace agv {
namespace {

double reference(std::vector<double> v, size_t k) {
  std::nth_element(v.begin(), v.begin() + static_cast<std::ptrdiff_t>(k), v.end());
  return v[k];
}

void expect_all_k(const std::vector<double>& v, const char* what) {
  for (size_t k = 0; k < v.size(); ++k) {
    std::vector<double> w = v;
    const double got = select_kth(w, k);
    ASSERT_EQ(got, reference(v, k)) << what << " n " << v.size() << " k " << k;
    // Reordered only: the same values.
    std::vector<double> a = v, b = w;
    std::sort(a.begin(), a.end());
    std::sort(b.begin(), b.end());
    ASSERT_EQ(a, b) << what;
  }
}

TEST(SelectKth, EqualsNthElementForEveryK) {
  std::mt19937_64 rng(11);
  std::uniform_real_distribution<double> uni(0.0, 1.0);
  std::uniform_int_distribution<int> few(0, 3);
  for (size_t n : {1u, 2u, 3u, 15u, 16u, 17u, 18u, 33u, 64u, 101u, 400u}) {
    for (int rep = 0; rep < 4; ++rep) {
      std::vector<double> distinct(n), repeats(n), residual(n);
      for (size_t i = 0; i < n; ++i) {
        distinct[i] = uni(rng);
        repeats[i] = few(rng);  // mostly ties, the smallest value often the pivot
        residual[i] = std::abs(0.01 * std::log(uni(rng) + 1e-300));
      }
      expect_all_k(distinct, "distinct");
      expect_all_k(repeats, "repeats");
      expect_all_k(residual, "residual");
      std::sort(distinct.begin(), distinct.end());
      expect_all_k(distinct, "sorted");
      std::reverse(distinct.begin(), distinct.end());
      expect_all_k(distinct, "reversed");
      expect_all_k(std::vector<double>(n, 0.25), "constant");
    }
  }
}

TEST(SelectKth, NanTerminates) {
  const double nan = std::numeric_limits<double>::quiet_NaN();
  for (size_t n : {5u, 40u, 300u}) {
    std::vector<double> all_nan(n, nan);
    for (size_t k = 0; k < n; k += 7) {
      std::vector<double> w = all_nan;
      EXPECT_TRUE(std::isnan(select_kth(w, k)));
    }
    std::mt19937_64 rng(n);
    std::uniform_real_distribution<double> uni(0.0, 1.0);
    std::vector<double> some(n);
    for (size_t i = 0; i < n; ++i) some[i] = i % 5 == 0 ? nan : uni(rng);
    for (size_t k = 0; k < n; k += 3) {
      std::vector<double> w = some;
      (void)select_kth(w, k);  // unspecified value; must return
    }
  }
}

}  // namespace
}  // namespace agv
