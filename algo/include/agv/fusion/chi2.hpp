// Chi-square distribution with 3 degrees of freedom (the dimension of a landmark fix) and 2 (a
// position, a range-bearing observation), used for the innovation gates of the fusion EKF.
#pragma once

#include <cmath>

namespace agv::fusion {

// P(X <= x) for X ~ chi2(3): erf(sqrt(x/2)) - sqrt(2x/pi) exp(-x/2). x <= 0 gives 0.
double chi2_3dof_cdf(double x);

// Upper tail 1 - cdf, computed directly (no cancellation near 1).
double chi2_3dof_sf(double x);

// Inverse CDF: the x with cdf(x) = p, for p in (0, 1). Found by bisection on the upper tail,
// accurate to ~1e-12 relative. Returns NaN for p outside (0, 1).
// chi2_3dof_quantile(0.999) = 16.266, (0.99) = 11.345, (0.95) = 7.815.
double chi2_3dof_quantile(double p);

// The same for 2 degrees of freedom (a position, a range-bearing pair), in closed form:
// -2 ln(1 - p). chi2_2dof_quantile(0.999) = 13.816.
inline double chi2_2dof_quantile(double p) { return -2.0 * std::log1p(-p); }

}  // namespace agv::fusion
