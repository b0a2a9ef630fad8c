// The simulated gyro with every error term off (white noise, turn-on bias, bias instability, bias
// random walk, scale error): the sim tests switch on the one they measure, or none.
#pragma once

#include "agv/sim/imu_model.hpp"

namespace agv::testsupport {

inline void switch_off_gyro_errors(sim::GyroParams* p) {
  p->noise_density_radps_rthz = 0.0;
  p->bias_radps = 0.0;
  p->bias_instability_radps = 0.0;
  p->bias_random_walk_radps_rts = 0.0;
  p->scale_error = 0.0;
}

}  // namespace agv::testsupport
