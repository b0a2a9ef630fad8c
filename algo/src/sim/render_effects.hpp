// The frame renderer's image formation after scene radiance: illumination, motion blur and the
// sensor's noise and 8-bit quantisation (render.cpp composes them).
#pragma once

#include <random>

#include "agv/sim/render.hpp"

namespace agv::sim {

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
