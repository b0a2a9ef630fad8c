// The per-vehicle filter's mathematics (Yang et al. eq. 14-19), apart from the track bookkeeping of
// tracker.cpp. State (x_mm, y_mm, theta_rad, v_mmps, omega_radps): speed in mm/s inside, so that
// every covariance entry is in millimetres and radians; the public outputs convert to m/s.
#pragma once

#include <Eigen/Core>
#include <cstdint>

#include "agv/overhead/tag_fix.hpp"

namespace agv::overhead::tracker_detail {

using Vec5 = Eigen::Matrix<double, 5, 1>;
using Mat5 = Eigen::Matrix<double, 5, 5>;
using Vec3 = Eigen::Matrix<double, 3, 1>;
using Mat3 = Eigen::Matrix<double, 3, 3>;

struct Belief {
  Vec5 x = Vec5::Zero();
  Mat5 p = Mat5::Zero();
};

// Continuous white-noise densities in the filter's units: (mm/s^2)^2 s and (rad/s^2)^2 s.
struct ProcessNoise {
  double accel = 0.0;
  double alpha = 0.0;
};

// Constant speed and turn rate over dt_s (eq. 14 with the arc integrated exactly, so a vehicle
// on a circle stays on it; for omega -> 0 it is eq. 14) and its Jacobian (eq. 15-16). The noise
// is the accelerations' density integrated over |dt_s| through the linearised motion.
Belief predict(const Belief& b, double dt_s, const ProcessNoise& q);

// A fix as the filter uses it: z = (x_mm, y_mm, theta_rad), the covariance R of its own noise
// (the corners'), and that of its camera's calibration error, a bias common to the camera's fixes.
// The filter averages the noise and not the bias: a fix updates with R, the gate compares with
// R + bias plus the track's own bias, and the track reports its covariance plus the bias of its
// newest fix (a consider covariance).
struct Measurement {
  Vec3 z = Vec3::Zero();
  Mat3 r = Mat3::Identity();
  Mat3 bias = Mat3::Zero();
  std::int32_t source = -1;  // TagFix::source
};

// False when the pose is not finite or the covariance is not finite, symmetric and positive
// definite. A camera part that leaves no positive definite noise (or is not finite) is taken as
// noise.
bool make_measurement(const TagFix& fix, Measurement* m);

// Squared Mahalanobis distance of the fix from the belief (heading innovation wrapped);
// track_bias: the calibration error the belief carries.
double distance2(const Belief& b, const Mat3& track_bias, const Measurement& m);

// Squared heading innovation of the fix over its variance (1 dof, wrapped); track_bias as above.
double heading_distance2(const Belief& b, const Mat3& track_bias, const Measurement& m);

// Eq. 17-19 with the covariance in Joseph form (stays symmetric positive definite).
Belief update(const Belief& b, const Measurement& m);
// The same for a prior that came from the fix prior_fix: a fix of another camera than that one
// also carries both cameras' biases (their difference is a jump no motion explains; taken as
// noise, a vehicle seen alternately by two cameras is not given a speed by it).
Belief update(const Belief& b, const Measurement& m, const Measurement& prior_fix);

// A new track's belief: the fix's pose and covariance, at rest with the given sigmas.
Belief start(const Measurement& m, double speed_sigma_mmps, double turn_sigma_radps);

// sqrt of the larger eigenvalue of the 2 x 2 position covariance.
double position_sigma_mm(const Mat5& p);

}  // namespace agv::overhead::tracker_detail
