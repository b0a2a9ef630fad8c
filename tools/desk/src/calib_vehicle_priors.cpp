// The filter's odometry priors after commissioning (calib_vehicle.hpp, odometry_priors).
#include <algorithm>

#include "calib_vehicle.hpp"

namespace agv::desk::vcal {

std::vector<FilterPrior> odometry_priors(const Result& r, double sigma_factor) {
  struct Row {
    const char* param;
    const char* key;
    double floor;
    bool relative;  // the filter's state is the scale's relative error
  };
  const Row rows[] = {
      {"odometry.speed_scale", "init_v_scale_sigma", kMinPriorScale, true},
      {"odometry.yaw_rate_scale", "init_omega_scale_sigma", kMinPriorScale, true},
      {"odometry.yaw_rate_bias_degps", "init_omega_bias_sigma_degps", kMinPriorDegps, false},
      {"odometry.yaw_per_metre_deg", "init_omega_per_v_sigma_degpm", kMinPriorDegpm, false},
  };
  std::vector<FilterPrior> out;
  for (const Row& row : rows) {
    const ParamReport& p = r.param(row.param);
    if (!p.determined) continue;
    const double sigma = row.relative && p.value > 0.0 ? p.sigma / p.value : p.sigma;
    out.push_back({row.key, std::max(sigma_factor * sigma, row.floor)});
  }
  return out;
}

}  // namespace agv::desk::vcal
