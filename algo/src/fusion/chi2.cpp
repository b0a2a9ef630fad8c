#include "agv/fusion/chi2.hpp"

#include <cmath>
#include <limits>

namespace agv::fusion {

namespace {
constexpr double kSqrt2OverPi = 0.79788456080286535588;  // sqrt(2/pi)
}

double chi2_3dof_cdf(double x) {
  if (!(x > 0.0)) return 0.0;
  return std::erf(std::sqrt(0.5 * x)) - kSqrt2OverPi * std::sqrt(x) * std::exp(-0.5 * x);
}

double chi2_3dof_sf(double x) {
  if (!(x > 0.0)) return 1.0;
  return std::erfc(std::sqrt(0.5 * x)) + kSqrt2OverPi * std::sqrt(x) * std::exp(-0.5 * x);
}

double chi2_3dof_quantile(double p) {
  if (!(p > 0.0 && p < 1.0)) return std::numeric_limits<double>::quiet_NaN();
  const double tail = 1.0 - p;
  // sf is strictly decreasing; sf(1500) underflows to 0, below any representable tail > 0 that
  // 1 - p can produce (>= 1.1e-16), so the root is bracketed.
  double lo = 0.0, hi = 1500.0;
  for (int i = 0; i < 200 && hi - lo > 1e-13 * hi; ++i) {
    const double mid = 0.5 * (lo + hi);
    if (chi2_3dof_sf(mid) > tail) {
      lo = mid;
    } else {
      hi = mid;
    }
  }
  return 0.5 * (lo + hi);
}

}  // namespace agv::fusion
