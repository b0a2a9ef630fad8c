// What fix.cpp (the least squares) and fix_response.cpp (its response to shared errors) share.
// Private to algo/src/ranging.
#pragma once

#include <Eigen/Dense>
#include <span>

#include "agv/ranging/fix.hpp"

// Named, not anonymous: the library is built as one unity source.
namespace agv::ranging::fix_detail {

// The least squares' unknowns: the pose (x_mm, y_mm, theta_rad) and, where the fix estimates it
// (FixResult::lens_estimated), the common lens error in sigmas of fx and fy.
using State = Eigen::Matrix<double, 5, 1>;
using Matrix5d = Eigen::Matrix<double, 5, 5>;

// Predicted (range, bearing) of a landmark from pose, with the 2x3 Jacobian over (x, y, theta).
bool fix_predict(const Observation& o, const Eigen::Vector3d& s, Eigen::Vector2d* h,
                 Eigen::Matrix<double, 2, 3>* J);
Eigen::Vector2d fix_residual(const Observation& o, const Eigen::Vector2d& h);
// An observation with a face yaw: residual over (range, bearing, face yaw) and its 3x3 Jacobian.
bool fix_residual_yaw(const Observation& o, const Eigen::Vector3d& s, Eigen::Vector3d* r,
                      Eigen::Matrix3d* J);
Eigen::Matrix3d face_yaw_covariance(const Observation& o);

// An observation's covariance over (range, bearing, face yaw) and its lens response, the third row
// and column padding (unit variance, zero response) without a face yaw.
void padded_cov_and_lens(const Observation& o, Eigen::Matrix3d* R, Eigen::Matrix<double, 3, 2>* L);

// One observation linearised at x: the residual z - h(pose) - L e over (range, bearing, face yaw),
// its Jacobian over the state, and the inverse of the observation's own covariance (its share of
// the common lens error, L L^T, removed when the lens is shared). Without a face yaw the third
// row is padding: zero residual and Jacobian, unit weight.
struct Linearised {
  Eigen::Vector3d r = Eigen::Vector3d::Zero();
  Eigen::Matrix<double, 3, 5> A = Eigen::Matrix<double, 3, 5>::Zero();
  Eigen::Matrix3d W = Eigen::Matrix3d::Identity();
};
bool linearise(const Observation& o, const State& x, bool lens_shared, Linearised* out);

// True where the lens can be one shared error: some observation carries a lens response and
// every observation's covariance holds its own L L^T (what ranging::fix_observation makes).
bool lens_shareable(std::span<const Observation> obs);

// The normal equations over all observations at x, the lens error's unit prior included; false
// where some landmark cannot be predicted.
bool normal_equations(std::span<const Observation> obs, const State& x, bool lens_shared,
                      Matrix5d* H, State* g);

}  // namespace agv::ranging::fix_detail
