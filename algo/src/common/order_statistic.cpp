#include "agv/common/order_statistic.hpp"

#include <algorithm>
#include <cmath>
#include <utility>

namespace agv {

namespace {

// Below this many values the rest is an insertion sort: fewer operations than another pass.
constexpr std::size_t kSmallRange = 16;

// Moves the values for which `before` holds to the front of a[lo, hi) and returns where the rest
// starts. Lomuto's scheme without a branch: every value is written to the split index, which
// advances only when the value belongs in front; the values between the split and the cursor
// are all "after", so the swap keeps them there.
template <class Pred>
std::size_t partition_branchless(double* a, std::size_t lo, std::size_t hi, Pred before) {
  std::size_t i = lo, j = lo;
  const auto step = [&] {
    const double x = a[j];
    const bool front = before(x);
    a[j] = a[i];
    a[i] = x;
    i += front ? 1 : 0;
    ++j;
  };
  // Two values per loop test: the loop's compare and branch were two of nine instructions per
  // value on aarch64.
  for (; j + 1 < hi;) {
    step();
    step();
  }
  if (j < hi) step();
  return i;
}

double median_of_three(double x, double y, double z) {
  return std::max(std::min(x, y), std::min(std::max(x, y), z));
}

}  // namespace

double select_kth(std::span<double> v, std::size_t k) {
  double* a = v.data();
  std::size_t lo = 0, hi = v.size();  // v[k] lies in [lo, hi)
  while (hi - lo > kSmallRange) {
    const double p = median_of_three(a[lo], a[lo + (hi - lo) / 2], a[hi - 1]);
    const std::size_t lt = partition_branchless(a, lo, hi, [p](double x) { return x < p; });
    if (k < lt) {
      hi = lt;
    } else if (lt > lo) {
      lo = lt;
    } else {
      // p is the smallest value: split off the values equal to it (p itself at least).
      const std::size_t le = partition_branchless(a, lo, hi, [p](double x) { return x <= p; });
      if (k < le) return p;
      if (le == lo) {  // a NaN pivot: nothing compares; std::nth_element decides
        std::nth_element(a + lo, a + k, a + hi);
        return a[k];
      }
      lo = le;
    }
  }
  for (std::size_t i = lo + 1; i < hi; ++i) {
    const double x = a[i];
    std::size_t j = i;
    for (; j > lo && x < a[j - 1]; --j) a[j] = a[j - 1];
    a[j] = x;
  }
  return a[k];
}

}  // namespace agv
