// What the EKF's source files share: units and the generic measurement update (Joseph form) and
// its chi-square gate, for any measurement dimension M.
#pragma once

#include <Eigen/Cholesky>
#include <Eigen/Core>
#include <limits>

#include "agv/fusion/ekf.hpp"

namespace agv::fusion::detail {

inline constexpr double kNsToS = 1e-9;

inline void symmetrize(FilterCov* P) { *P = 0.5 * (*P + P->transpose()); }

template <int M>
using MeasRow = Eigen::Matrix<double, M, kFilterDim>;
template <int M>
using MeasVec = Eigen::Matrix<double, M, 1>;
template <int M>
using MeasCov = Eigen::Matrix<double, M, M>;

// Mahalanobis distance^2 of the innovation nu of a measurement z = h(x) + noise(R) with
// Jacobian H against the prior covariance P (infinity when H P H^T + R is not positive
// definite): what the chi-square gate of M degrees of freedom tests.
template <int M>
double mahalanobis_sq(const FilterCov& P, const MeasRow<M>& H, const MeasVec<M>& nu,
                      const MeasCov<M>& R) {
  const MeasCov<M> S = H * P * H.transpose() + R;
  const Eigen::LLT<MeasCov<M>> llt(S);
  if (llt.info() != Eigen::Success) return std::numeric_limits<double>::infinity();
  return nu.dot(llt.solve(nu));
}

// The Kalman update with innovation nu (angles already wrapped by the caller), in Joseph form
// (P stays symmetric positive semi-definite for any gain), then symmetrised.
template <int M>
void joseph_update(FilterVec* x, FilterCov* P, const MeasRow<M>& H, const MeasVec<M>& nu,
                   const MeasCov<M>& R) {
  const Eigen::Matrix<double, kFilterDim, M> PHt = (*P) * H.transpose();
  const MeasCov<M> S = H * PHt + R;
  const Eigen::Matrix<double, kFilterDim, M> K = S.llt().solve(PHt.transpose()).transpose();
  *x += K * nu;
  const FilterCov IKH = FilterCov::Identity() - K * H;
  *P = IKH * (*P) * IKH.transpose() + K * R * K.transpose();
  symmetrize(P);
}

}  // namespace agv::fusion::detail
