// The k-th smallest of a set of doubles, for the robust scales of the line and square fits (the
// median absolute residual). std::nth_element gives the same value; it was a tenth of a tracked
// frame on x86-64, most of it mispredicted branches of its partition on residuals in random
// order (docs/design/performance.md).
#pragma once

#include <cstddef>
#include <span>

namespace agv {

// Robust scale from the median absolute residual: 1 / Phi^-1(3/4) = 1.4826, consistent for
// Gaussian residuals.
inline constexpr double kMadToSigma = 1.4826;

// The value std::nth_element(v.begin(), v.begin() + k, v.end()) would leave at v[k]: the k-th
// order statistic is one value, so the same to the bit, except that with both +0 and -0 in v
// either may come back (they compare equal). Reorders v. Requires k < v.size(); with a NaN in v
// the result is unspecified, as std::nth_element's. Quickselect with a branchless partition (the
// compare moves the split index instead of choosing a branch) and a median-of-three pivot; when
// the pivot is the smallest value, the values equal to it are split off in a second pass, so
// repeated values cannot stall it.
double select_kth(std::span<double> v, std::size_t k);

}  // namespace agv
