// Simulated MEMS yaw-rate gyro: a pure function of the true trajectory, the error parameters and
// a seed (no I/O, no clock). Model and defaults: docs/design/simulator.md "Gyro".
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "agv/common/geometry.hpp"
#include "agv/sim/trajectory.hpp"

namespace agv::sim {

// Error model of the gyro's z axis. Defaults: a typical industrial MEMS gyro.
struct GyroParams {
  double rate_hz = 200.0;  // output data rate: one sample every round(1e9 / rate_hz) ns
  // White rate noise (angle random walk) as a density: the mean of the noise over a time T has
  // sigma = density / sqrt(T s), so one sample has density * sqrt(rate_hz).
  double noise_density_radps_rthz = deg_to_rad(0.01);
  double bias_radps = deg_to_rad(0.2);  // constant (turn-on) bias
  // Bias instability: a first-order Gauss-Markov bias with this stationary sigma, correlated over
  // bias_correlation_s (started from its stationary distribution).
  double bias_instability_radps = deg_to_rad(0.005);
  double bias_correlation_s = 100.0;
  // Bias random walk (rate random walk), rad/s per sqrt(s): starts at 0 and wanders for ever;
  // after 1 h at the default its sigma (0.006 deg/s) is about the bias instability.
  double bias_random_walk_radps_rts = deg_to_rad(1e-4);
  double scale_error = 0.003;  // reported = (1 + scale_error) * true rate, before the biases
  double range_radps = deg_to_rad(250.0);  // full scale: samples are clipped to +-range
  std::int64_t latency_ns = 0;  // stamps late by this (negative: early), the gyro's clock offset
  std::uint64_t seed = 1;
};

// False with *error naming the parameter when it is out of its range (rate 1..10000 Hz, non-
// negative noise terms, correlation time > 0, |scale error| < 0.5, range > 0, |latency| <= 1 s).
bool check_gyro_params(const GyroParams& p, std::string* error);

struct ImuSample {
  std::int64_t t_ns = 0;  // stamp: trajectory time of the sample + latency_ns
  double gyro_z_radps = 0.0;
};

// The gyro over [0, duration_ns] of trajectory time: sample k is taken at t_k = k * period
// (k = 0, 1, ... while t_k <= duration_ns). Its true value is the mean yaw rate over
// [t_k - period, t_k] (heading turned / period, exact from trajectory_state, as the sensor's
// digital low-pass roughly gives); then
//   (1 + scale_error) * true + bias + Gauss-Markov bias + random-walk bias + white noise,
// clipped to +-range_radps, stamped t_k + latency_ns. Deterministic for p.seed; the white noise
// and the two bias processes draw from separate streams, so changing one parameter leaves the
// others' realisations unchanged. Empty for invalid parameters (check_gyro_params).
std::vector<ImuSample> simulate_gyro(const GyroParams& p, const Trajectory& tr,
                                     std::int64_t duration_ns);

}  // namespace agv::sim
