// The frame renderer's image formation after scene radiance: illumination, motion blur and the
// sensor's noise and 8-bit quantisation (render.cpp composes them).
#pragma once

#include <random>

#include "agv/sim/render.hpp"

namespace agv::sim {

// Where a pixel lies along a linear illumination gradient: 0 at the image corner first along the
// direction, 1 at the last. The floor and the site renderer share it.
struct IlluminationGradient {
  double dx = 1.0, dy = 0.0;      // the direction in the image
  double tmin = 0.0, span = 1.0;  // the corners' range along it
  double at(int x, int y) const { return (x * dx + y * dy - tmin) / span; }
};
IlluminationGradient illumination_gradient(int width_px, int height_px, double direction_deg);

// Exposure gain and the linear illumination gradient, in place on a CV_32FC1 radiance image.
void apply_illumination(const RenderOptions& o, cv::Mat* img);

// Linear motion blur of the floor point under the image centre (`centre_v`, vehicle frame; no blur
// when `centre_ok` is false) during the exposure, in place on a CV_32FC1 image.
void apply_motion_blur(const RenderOptions& o, const FloorProjector& camera, Vec2 centre_v,
                       bool centre_ok, cv::Mat* img);

// The 8-bit frame of a CV_32FC1 image: Gaussian read noise (sigma in 8-bit units) and shot noise
// (variance = gain * signal) drawn from `rng`, rounded and clamped to 0..255. The floor and the
// site renderer both end with it.
cv::Mat quantise_with_noise(const cv::Mat& img, double read_noise_sigma, double shot_noise_gain,
                            std::mt19937_64& rng);

}  // namespace agv::sim
