// eval_vision's degradations of a rendered floor frame beyond the realistic rendering, which
// eval_tracking measures under the same names.
#pragma once

#include <random>

#include "agv/sim/render.hpp"

namespace agv::bench {

// Motion blur of `px` pixels during a 1 ms exposure (px * mm/px per ms = m/s).
inline void motion_blur(double px, double mm_per_px, sim::RenderOptions* o) {
  o->exposure_s = 0.001;
  o->speed_mps = px * mm_per_px;
}

// Every degradation at once, each drawn up to its limit.
inline void combined_degradations(double mm_per_px, std::mt19937_64& r, sim::RenderOptions* o) {
  std::uniform_real_distribution<double> u(0, 1);
  o->defocus_sigma_px = 2.0 * u(r);
  motion_blur(7.0 * u(r), mm_per_px, o);
  o->read_noise_sigma = 4.0 * u(r);
  o->shot_noise_gain = 0.3 * u(r);
  o->illumination_ratio = 1.0 - 0.5 * u(r);
  o->illumination_direction_deg = 360 * u(r);
  o->scratches_per_landmark = static_cast<int>(4 * u(r));
  o->dirt_spots_per_landmark = 3 * u(r);
  o->occluder_border_fraction = 0.15 * u(r);
}

// Beyond the degraded set's limits: defocus, motion blur and noise all at their limits at once.
inline void stress_degradations(double mm_per_px, sim::RenderOptions* o) {
  o->defocus_sigma_px = 2.0;
  motion_blur(7.0, mm_per_px, o);
  o->read_noise_sigma = 4.0;
  o->shot_noise_gain = 0.3;
}

}  // namespace agv::bench
