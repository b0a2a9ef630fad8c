// Three-or-more-landmark fixes (linear trilateration), the Gauss-Newton refinement over ranges and
// bearings, the chi-square check, and the fix to initialise from.
#include "agv/ranging/fix.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <vector>

#include "fix_internal.hpp"

namespace agv::ranging {

namespace fix_detail {

bool fix_predict(const Observation& o, const Eigen::Vector3d& s, Eigen::Vector2d* h,
                 Eigen::Matrix<double, 2, 3>* J) {
  const double dx = o.landmark_mm.x - s.x(), dy = o.landmark_mm.y - s.y();
  const double r2 = dx * dx + dy * dy;
  if (!(r2 > 0.0)) return false;
  const double r = std::sqrt(r2);
  *h = Eigen::Vector2d(r, std::atan2(dy, dx) - s.z());
  if (J) *J << -dx / r, -dy / r, 0.0, dy / r2, -dx / r2, -1.0;
  return true;
}

Eigen::Vector2d fix_residual(const Observation& o, const Eigen::Vector2d& h) {
  return {o.range_mm - h.x(), wrap_angle_rad(o.bearing_rad - h.y())};
}

// The face yaw predicted from the pose is the landmark's facing minus the heading.
bool fix_residual_yaw(const Observation& o, const Eigen::Vector3d& s, Eigen::Vector3d* r,
                      Eigen::Matrix3d* J) {
  Eigen::Vector2d h;
  Eigen::Matrix<double, 2, 3> J2;
  if (!fix_predict(o, s, &h, &J2)) return false;
  *r << fix_residual(o, h), wrap_angle_rad(o.face_yaw_rad - (o.landmark_facing_rad - s.z()));
  if (J) {
    J->topRows<2>() = J2;
    J->row(2) << 0.0, 0.0, -1.0;
  }
  return true;
}

Eigen::Matrix3d face_yaw_covariance(const Observation& o) {
  Eigen::Matrix3d R;
  R.topLeftCorner<2, 2>() = o.cov;
  R.topRightCorner<2, 1>() = o.face_yaw_cov;
  R.bottomLeftCorner<1, 2>() = o.face_yaw_cov.transpose();
  R(2, 2) = o.face_yaw_var_rad2;
  return R;
}

void padded_cov_and_lens(const Observation& o, Eigen::Matrix3d* R, Eigen::Matrix<double, 3, 2>* L) {
  *L = o.lens_response;
  if (o.has_face_yaw) {
    *R = face_yaw_covariance(o);
    return;
  }
  R->setIdentity();
  R->topLeftCorner<2, 2>() = o.cov;
  L->row(2).setZero();
}

bool linearise(const Observation& o, const State& x, bool lens_shared, Linearised* out) {
  const Eigen::Vector3d s = x.head<3>();
  Linearised l;
  if (o.has_face_yaw) {
    Eigen::Matrix3d J;
    if (!fix_residual_yaw(o, s, &l.r, &J)) return false;
    l.A.leftCols<3>() = J;
  } else {
    Eigen::Vector2d h;
    Eigen::Matrix<double, 2, 3> J;
    if (!fix_predict(o, s, &h, &J)) return false;
    l.r.head<2>() = fix_residual(o, h);
    l.A.topLeftCorner<2, 3>() = J;
  }
  Eigen::Matrix3d R;
  Eigen::Matrix<double, 3, 2> L;
  padded_cov_and_lens(o, &R, &L);
  if (lens_shared) {
    l.A.rightCols<2>() = L;
    l.r -= L * x.tail<2>();
    R -= L * L.transpose();
  }
  const Eigen::LLT<Eigen::Matrix3d> llt(R);
  if (llt.info() != Eigen::Success) return false;
  l.W = llt.solve(Eigen::Matrix3d::Identity());
  *out = l;
  return true;
}

bool lens_shareable(std::span<const Observation> obs) {
  bool any = false;
  for (const Observation& o : obs) {
    Eigen::Matrix3d R;
    Eigen::Matrix<double, 3, 2> L;
    padded_cov_and_lens(o, &R, &L);
    any = any || !L.isZero(0.0);
    // What is left of the covariance must stay clearly positive, in units of its own diagonal
    // (mm and rad differ by orders of magnitude): a response the covariance does not hold is not
    // a share of it.
    const Eigen::Vector3d d = R.diagonal();
    if (!(d.minCoeff() > 0.0)) return false;
    const Eigen::Vector3d n = d.cwiseSqrt().cwiseInverse();
    const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig(
        n.asDiagonal() * (R - L * L.transpose()) * n.asDiagonal());
    if (eig.info() != Eigen::Success || !(eig.eigenvalues().minCoeff() > 1e-6)) return false;
  }
  return any;
}

bool normal_equations(std::span<const Observation> obs, const State& x, bool lens_shared,
                      Matrix5d* H, State* g) {
  H->setZero();
  g->setZero();
  for (const Observation& o : obs) {
    Linearised l;
    if (!linearise(o, x, lens_shared, &l)) return false;
    const Eigen::Matrix<double, 5, 3> AtW = l.A.transpose() * l.W;
    *H += AtW * l.A;
    *g += AtW * l.r;
  }
  H->bottomRightCorner<2, 2>() += Eigen::Matrix2d::Identity();
  g->tail<2>() -= x.tail<2>();
  return true;
}

}  // namespace fix_detail

namespace {

using fix_detail::face_yaw_covariance;
using fix_detail::fix_predict;
using fix_detail::fix_residual;
using fix_detail::fix_residual_yaw;

// One observation's weighted squared residual at s; false where it cannot be predicted.
bool observation_chi2(const Observation& o, const Eigen::Vector3d& s, double* chi2) {
  if (o.has_face_yaw) {
    Eigen::Vector3d r;
    if (!fix_residual_yaw(o, s, &r, nullptr)) return false;
    *chi2 = r.dot(face_yaw_covariance(o).ldlt().solve(r));
    return true;
  }
  Eigen::Vector2d h;
  if (!fix_predict(o, s, &h, nullptr)) return false;
  const Eigen::Vector2d r = fix_residual(o, h);
  *chi2 = r.dot(o.cov.ldlt().solve(r));
  return true;
}

int measured_quantities(std::span<const Observation> obs) {
  int m = 0;
  for (const Observation& o : obs) m += o.has_face_yaw ? 3 : 2;
  return m;
}

// The largest pose NEES per unit of chi-square rise over one landmark's map errors: the largest
// generalised eigenvalue of (shift, seen), both quadratic forms over the map error.
template <int N>
double worst_hidden_ratio(const Eigen::Matrix<double, N, N>& shift,
                          const Eigen::Matrix<double, N, N>& seen) {
  using Mat = Eigen::Matrix<double, N, N>;
  Eigen::GeneralizedSelfAdjointEigenSolver<Mat> eig;
  const Mat seen_reg = seen + 1e-12 * seen.trace() * Mat::Identity();
  eig.compute(shift, seen_reg);
  if (eig.info() != Eigen::Success) return std::numeric_limits<double>::infinity();
  return eig.eigenvalues().maxCoeff();
}

// The three-or-more-landmark pose as a function of the measurements (r_i, b_i), for the numeric
// Jacobian of fix_trilateration.
bool fix_trilateration_pose(std::span<const Observation> obs, const std::vector<double>& z,
                            const FixOptions& opt, Eigen::Vector3d* pose) {
  std::vector<Observation> o(obs.begin(), obs.end());
  for (std::size_t i = 0; i < o.size(); ++i) {
    o[i].range_mm = z[2 * i];
    o[i].bearing_rad = z[2 * i + 1];
  }
  Vec2 p;
  if (trilaterate(o, opt, &p) != FixStatus::kOk) return false;
  *pose = Eigen::Vector3d(p.x, p.y, heading_from_bearings_rad(p, o, 0.0));
  return true;
}

// The least squares' objective: weighted squared residuals plus the lens error's prior; infinite
// where some landmark cannot be predicted (at the vehicle's point).
double cost_strict(std::span<const Observation> obs, const fix_detail::State& x, bool lens_shared) {
  double cost = x.tail<2>().squaredNorm();
  for (const Observation& o : obs) {
    fix_detail::Linearised l;
    if (!fix_detail::linearise(o, x, lens_shared, &l))
      return std::numeric_limits<double>::infinity();
    cost += l.r.dot(l.W * l.r);
  }
  return cost;
}

// The pose's information with the lens error marginalised out (the Schur complement).
Eigen::Matrix3d pose_information(const fix_detail::Matrix5d& H) {
  return H.topLeftCorner<3, 3>() - H.topRightCorner<3, 2>() *
                                       H.bottomRightCorner<2, 2>().inverse() *
                                       H.bottomLeftCorner<2, 3>();
}

}  // namespace

double hidden_map_shift_sigma(std::span<const Observation> obs, const Pose2& pose,
                              const Eigen::Matrix3d& information, double gate) {
  const Eigen::Vector3d s(pose.x_mm, pose.y_mm, pose.theta_rad);
  const Eigen::Matrix3d H_inv = information.inverse();
  double worst = 0.0;
  for (const Observation& o : obs) {
    if (o.has_face_yaw) {
      // The map error over (x, y, facing): the facing moves only the face yaw.
      Eigen::Vector3d r;
      Eigen::Matrix3d J;
      if (!fix_residual_yaw(o, s, &r, &J)) continue;
      const Eigen::Matrix3d W = face_yaw_covariance(o).inverse();
      Eigen::Matrix3d A = Eigen::Matrix3d::Zero();
      A.topLeftCorner<2, 2>() = -J.topLeftCorner<2, 2>();
      A(2, 2) = 1.0;
      const Eigen::Matrix3d G = J.transpose() * W * A;
      const Eigen::Matrix3d shift = G.transpose() * H_inv * G;
      const Eigen::Matrix3d seen = A.transpose() * W * A - shift;
      worst = std::max(worst, worst_hidden_ratio<3>(shift, seen));
      if (std::isinf(worst)) return worst;
      continue;
    }
    Eigen::Vector2d h;
    Eigen::Matrix<double, 2, 3> J;
    if (!fix_predict(o, s, &h, &J)) continue;
    const Eigen::Matrix2d W = o.cov.inverse();
    // Moving the landmark moves its (range, bearing) as moving the vehicle the other way does.
    const Eigen::Matrix2d A = -J.leftCols<2>();
    const Eigen::Matrix<double, 3, 2> G = J.transpose() * W * A;
    const Eigen::Matrix2d shift = G.transpose() * H_inv * G;     // pose NEES per map error
    const Eigen::Matrix2d seen = A.transpose() * W * A - shift;  // chi-square per map error
    worst = std::max(worst, worst_hidden_ratio<2>(shift, seen));
    if (std::isinf(worst)) return worst;
  }
  return std::sqrt(worst * gate);
}

const char* fix_status_name(FixStatus status) {
  switch (status) {
    case FixStatus::kOk:
      return "ok";
    case FixStatus::kTooFew:
      return "too_few";
    case FixStatus::kNoIntersection:
      return "no_intersection";
    case FixStatus::kShallowGeometry:
      return "shallow_geometry";
    case FixStatus::kCollinear:
      return "collinear";
    case FixStatus::kAmbiguous:
      return "ambiguous";
    case FixStatus::kInconsistent:
      return "inconsistent";
    case FixStatus::kUnverifiable:
      return "unverifiable";
  }
  return "?";
}

double chi2_gate(int dof, double z) {
  if (dof <= 0) return 0.0;
  const double k = dof;
  const double c = 1.0 - 2.0 / (9.0 * k) + z * std::sqrt(2.0 / (9.0 * k));
  return k * c * c * c;
}

double fix_chi2(std::span<const Observation> obs, const Pose2& pose) {
  const Eigen::Vector3d s(pose.x_mm, pose.y_mm, pose.theta_rad);
  double chi2 = 0.0;
  for (const Observation& o : obs) {
    double c = 0.0;
    if (observation_chi2(o, s, &c)) chi2 += c;
  }
  return chi2;
}

FixStatus trilaterate(std::span<const Observation> obs, const FixOptions& opt, Vec2* position_mm) {
  if (obs.size() < 3) return FixStatus::kTooFew;
  // Coordinates relative to the first landmark: the same equations, without squaring the large
  // absolute coordinates (which would cost about eight digits at warehouse scale).
  const Vec2 o = obs[0].landmark_mm;
  const double d0 = obs[0].range_mm;
  auto row = [&](std::size_t i, double* a, double* b, double* c) {
    const double xi = obs[i].landmark_mm.x - o.x, yi = obs[i].landmark_mm.y - o.y;
    const double di = obs[i].range_mm;
    *a = 2.0 * xi;
    *b = 2.0 * yi;
    *c = d0 * d0 - di * di + xi * xi + yi * yi;
  };
  double x = 0.0, y = 0.0;
  if (obs.size() == 3) {
    double a1, b1, c1, a2, b2, c2;
    row(1, &a1, &b1, &c1);
    row(2, &a2, &b2, &c2);
    const double D = a1 * b2 - a2 * b1;
    const double norm = std::hypot(a1, b1) * std::hypot(a2, b2);
    if (!(norm > 0.0) || std::abs(D) < opt.min_baseline_sine * norm) return FixStatus::kCollinear;
    x = (c1 * b2 - c2 * b1) / D;
    y = (a1 * c2 - a2 * c1) / D;
  } else {
    // Normal equations of the over-determined system, solved by the same determinants.
    double saa = 0, sab = 0, sbb = 0, sac = 0, sbc = 0;
    for (std::size_t i = 1; i < obs.size(); ++i) {
      double a, b, c;
      row(i, &a, &b, &c);
      saa += a * a;
      sab += a * b;
      sbb += b * b;
      sac += a * c;
      sbc += b * c;
    }
    const double D = saa * sbb - sab * sab;
    const double half_trace = 0.5 * (saa + sbb);
    if (!(half_trace > 0.0) || std::sqrt(std::max(0.0, D)) < opt.min_baseline_sine * half_trace) {
      return FixStatus::kCollinear;
    }
    x = (sac * sbb - sbc * sab) / D;
    y = (saa * sbc - sab * sac) / D;
  }
  *position_mm = {o.x + x, o.y + y};
  return FixStatus::kOk;
}

FixResult fix_trilateration(std::span<const Observation> obs, const FixOptions& opt) {
  FixResult out;
  out.dof = measured_quantities(obs) - 3;
  Vec2 p;
  out.status = trilaterate(obs, opt, &p);
  if (out.status != FixStatus::kOk) return out;
  const std::size_t m = 2 * obs.size();
  std::vector<double> z(m);
  Eigen::MatrixXd R =
      Eigen::MatrixXd::Zero(static_cast<Eigen::Index>(m), static_cast<Eigen::Index>(m));
  for (std::size_t i = 0; i < obs.size(); ++i) {
    z[2 * i] = obs[i].range_mm;
    z[2 * i + 1] = obs[i].bearing_rad;
    R.block<2, 2>(static_cast<Eigen::Index>(2 * i), static_cast<Eigen::Index>(2 * i)) = obs[i].cov;
  }
  Eigen::Vector3d pose;
  fix_trilateration_pose(obs, z, opt, &pose);
  out.pose = {pose.x(), pose.y(), pose.z()};
  out.chi2 = fix_chi2(obs, out.pose);
  Eigen::MatrixXd J(3, static_cast<Eigen::Index>(m));
  for (std::size_t k = 0; k < m; ++k) {
    const double step = (k % 2 == 0) ? 1e-6 * std::max(1.0, z[k]) : 1e-7;
    std::vector<double> zp = z, zm = z;
    zp[k] += step;
    zm[k] -= step;
    Eigen::Vector3d fp, fm;
    if (!fix_trilateration_pose(obs, zp, opt, &fp) || !fix_trilateration_pose(obs, zm, opt, &fm)) {
      out.status = FixStatus::kCollinear;
      return out;
    }
    Eigen::Vector3d d = fp - fm;
    d.z() = wrap_angle_rad(d.z());
    J.col(static_cast<Eigen::Index>(k)) = d / (2.0 * step);
  }
  out.cov = J * R * J.transpose();
  return out;
}

FixResult refine_fix(std::span<const Observation> obs, const Pose2& init, const FixOptions& opt) {
  FixResult out;
  out.dof = measured_quantities(obs) - 3;
  if (obs.size() < 2) return out;
  const bool shared = opt.lens_in_weights && fix_detail::lens_shareable(obs);
  fix_detail::State x;
  x << init.x_mm, init.y_mm, init.theta_rad, 0.0, 0.0;
  fix_detail::Matrix5d H;
  bool converged = false;
  for (int it = 0; it <= opt.max_iterations; ++it) {
    fix_detail::State g;
    if (!fix_detail::normal_equations(obs, x, shared, &H, &g)) {
      out.status = FixStatus::kShallowGeometry;
      return out;
    }
    if (converged || it == opt.max_iterations) break;
    fix_detail::State step = H.ldlt().solve(g);
    if (!step.allFinite()) break;
    // Backtracking: a wrong map entry makes the problem far from linear, where full Gauss-Newton
    // steps run away; halve a step until it lowers the objective.
    const double cost_now = cost_strict(obs, x, shared);
    for (int halvings = 0; halvings < 40 && !(cost_strict(obs, x + step, shared) <= cost_now);
         ++halvings) {
      step *= 0.5;
    }
    x += step;
    x(2) = wrap_angle_rad(x(2));
    out.iterations = it + 1;
    // One more pass after a negligible step so that H is evaluated at the final state.
    converged = std::hypot(step(0), step(1)) < 1e-10 && std::abs(step(2)) < 1e-13 &&
                step.tail<2>().norm() < 1e-10;
  }
  const Eigen::Vector3d s = x.head<3>();
  out.lens_estimated = shared;
  out.lens_error_sigma = x.tail<2>();
  out.pose = {s.x(), s.y(), s.z()};
  // With the lens shared, the residuals that one lens error explains are not misfit.
  out.chi2 = shared ? cost_strict(obs, x, true) : fix_chi2(obs, out.pose);
  // A rank-deficient information matrix (the landmarks and the vehicle on one line, ranges only
  // informative along it) has no covariance to report.
  const Eigen::Matrix3d info = pose_information(H);
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig(info);
  if (eig.info() != Eigen::Success ||
      !(eig.eigenvalues().minCoeff() > 1e-12 * eig.eigenvalues().maxCoeff())) {
    out.status = FixStatus::kShallowGeometry;
    return out;
  }
  out.cov = info.inverse();
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix2d> pos(out.cov.topLeftCorner<2, 2>());
  if (!(std::sqrt(std::max(0.0, pos.eigenvalues().maxCoeff())) <= opt.max_position_sd_mm)) {
    out.status = FixStatus::kShallowGeometry;
    return out;
  }
  const double gate = chi2_gate(out.dof, opt.chi2_gate_z);
  out.hidden_map_shift_sigma = hidden_map_shift_sigma(obs, out.pose, info, gate);
  if (out.dof > 0 && out.chi2 > gate) {
    out.status = FixStatus::kInconsistent;
  } else if (out.hidden_map_shift_sigma > opt.max_hidden_map_shift_sigma) {
    out.status = FixStatus::kUnverifiable;
  } else {
    out.status = FixStatus::kOk;
  }
  return out;
}

namespace {

// The vehicle's pose from one landmark read with its face yaw: heading from the landmark's facing
// and the face yaw, position back along the range and bearing.
Pose2 pose_from_face_yaw(const Observation& o) {
  const double theta = wrap_angle_rad(o.landmark_facing_rad - o.face_yaw_rad);
  const double a = theta + o.bearing_rad;
  return {o.landmark_mm.x - o.range_mm * std::cos(a), o.landmark_mm.y - o.range_mm * std::sin(a),
          theta};
}

// A shallow pair's seed from its two single-landmark poses (their mean; the circular mean of the
// headings). Only a seed: the fix is the least squares over both landmarks.
bool face_yaw_pair_seed(const Observation& o0, const Observation& o1, const FixOptions& opt,
                        Pose2* seed) {
  if (!opt.face_yaw_pairs_below_crossing || !o0.has_face_yaw || !o1.has_face_yaw) return false;
  const Pose2 a = pose_from_face_yaw(o0), b = pose_from_face_yaw(o1);
  *seed = {0.5 * (a.x_mm + b.x_mm), 0.5 * (a.y_mm + b.y_mm),
           std::atan2(std::sin(a.theta_rad) + std::sin(b.theta_rad),
                      std::cos(a.theta_rad) + std::cos(b.theta_rad))};
  return std::isfinite(seed->x_mm) && std::isfinite(seed->y_mm) && std::isfinite(seed->theta_rad);
}

// Two landmarks' seed: their circles' crossing, or where it is too shallow, their face yaws.
FixResult pair_seed(const Observation& o0, const Observation& o1, const FixOptions& opt) {
  FixResult seed = fix_two_circles(o0, o1, TwoLandmarkRule::kBearingDifference, false, opt);
  if (seed.status == FixStatus::kShallowGeometry && face_yaw_pair_seed(o0, o1, opt, &seed.pose))
    seed.status = FixStatus::kOk;
  return seed;
}

}  // namespace

FixResult fix_from_landmarks(std::span<const Observation> obs, const FixOptions& opt) {
  FixResult seed;
  if (obs.size() < 2) {
    seed.status = FixStatus::kTooFew;
    return seed;
  }
  if (obs.size() == 2) {
    seed = pair_seed(obs[0], obs[1], opt);
  } else {
    Vec2 p;
    seed.status = trilaterate(obs, opt, &p);
    if (seed.status == FixStatus::kOk) {
      seed.pose = {p.x, p.y, heading_from_bearings_rad(p, obs, 0.0)};
    } else if (seed.status == FixStatus::kCollinear) {
      // Landmarks along one rack face: the ranges alone cannot tell the two sides of the line
      // apart, the bearings can. Start from the widest pair's crossing; its own geometry check
      // refuses a pair too far away.
      std::size_t a = 0, b = 1;
      double widest = -1.0;
      for (std::size_t i = 0; i < obs.size(); ++i) {
        for (std::size_t j = i + 1; j < obs.size(); ++j) {
          const double d = std::hypot(obs[i].landmark_mm.x - obs[j].landmark_mm.x,
                                      obs[i].landmark_mm.y - obs[j].landmark_mm.y);
          if (d > widest) {
            widest = d;
            a = i;
            b = j;
          }
        }
      }
      seed = pair_seed(obs[a], obs[b], opt);
    }
  }
  if (seed.status != FixStatus::kOk) return seed;
  FixResult out = refine_fix(obs, seed.pose, opt);
  out.touching = seed.touching;
  return out;
}

}  // namespace agv::ranging
