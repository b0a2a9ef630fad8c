#include "agv/sim/imu_model.hpp"

#include <algorithm>
#include <cmath>
#include <random>

namespace agv::sim {

bool check_gyro_params(const GyroParams& p, std::string* error) {
  auto fail = [&](const char* why) {
    if (error) *error = why;
    return false;
  };
  if (!(p.rate_hz >= 1.0 && p.rate_hz <= 10000.0))
    return fail("gyro rate must be in [1, 10000] Hz");
  if (!(p.noise_density_radps_rthz >= 0.0 && std::isfinite(p.noise_density_radps_rthz))) {
    return fail("gyro noise density must be finite and >= 0");
  }
  if (!std::isfinite(p.bias_radps)) return fail("gyro bias must be finite");
  if (!(p.bias_instability_radps >= 0.0 && std::isfinite(p.bias_instability_radps))) {
    return fail("gyro bias instability must be finite and >= 0");
  }
  if (!(p.bias_correlation_s > 0.0 && std::isfinite(p.bias_correlation_s))) {
    return fail("gyro bias correlation time must be finite and > 0");
  }
  if (!(p.bias_random_walk_radps_rts >= 0.0 && std::isfinite(p.bias_random_walk_radps_rts))) {
    return fail("gyro bias random walk must be finite and >= 0");
  }
  if (!(std::abs(p.scale_error) < 0.5)) return fail("gyro scale error must be in (-0.5, 0.5)");
  if (!(p.range_radps > 0.0 && std::isfinite(p.range_radps))) {
    return fail("gyro range must be finite and > 0");
  }
  if (std::abs(p.latency_ns) > 1'000'000'000) return fail("gyro latency must be within +-1 s");
  return true;
}

std::vector<ImuSample> simulate_gyro(const GyroParams& p, const Trajectory& tr,
                                     std::int64_t duration_ns) {
  std::vector<ImuSample> out;
  if (!check_gyro_params(p, nullptr) || duration_ns < 0) return out;
  const auto period_ns = std::max<std::int64_t>(1, std::llround(1e9 / p.rate_hz));
  const double period_s = static_cast<double>(period_ns) * 1e-9;
  // The true value of a sample is the mean rate over its period: the period-mean odometry's
  // heading term computes exactly that (unwrapped heading change / period).
  OdometryParams mean_over_period;
  mean_over_period.timing = OdomSampleTiming::kPeriodMean;
  mean_over_period.period_ns = period_ns;
  // Separate streams (distinct seeds) for the white noise and the two bias processes.
  std::mt19937_64 white_rng(p.seed * 0xD1B54A32D192ED03ULL + 101);
  std::mt19937_64 markov_rng(p.seed * 0xD1B54A32D192ED03ULL + 202);
  std::mt19937_64 walk_rng(p.seed * 0xD1B54A32D192ED03ULL + 303);
  std::normal_distribution<double> n01(0.0, 1.0);
  const double white_sigma = p.noise_density_radps_rthz / std::sqrt(period_s);
  // Exact discretisation of the Gauss-Markov process: stays at its stationary sigma.
  const double phi = std::exp(-period_s / p.bias_correlation_s);
  const double markov_step = p.bias_instability_radps * std::sqrt(1.0 - phi * phi);
  const double walk_step = p.bias_random_walk_radps_rts * std::sqrt(period_s);
  double markov = p.bias_instability_radps * n01(markov_rng);
  double walk = 0.0;
  out.reserve(static_cast<std::size_t>(duration_ns / period_ns) + 1);
  for (std::int64_t t = 0; t <= duration_ns; t += period_ns) {
    if (t > 0) {
      markov = phi * markov + markov_step * n01(markov_rng);
      walk += walk_step * n01(walk_rng);
    }
    const double truth = true_odometry(mean_over_period, tr, t).omega_radps;
    const double rate =
        (1.0 + p.scale_error) * truth + p.bias_radps + markov + walk + white_sigma * n01(white_rng);
    // A real sensor reports its full scale, not more, however fast the vehicle turns.
    out.push_back({t + p.latency_ns, std::clamp(rate, -p.range_radps, p.range_radps)});
  }
  return out;
}

}  // namespace agv::sim
