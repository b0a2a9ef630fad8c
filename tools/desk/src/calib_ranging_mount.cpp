// The second camera's mount from rack landmarks seen at floor-localized poses. Model:
// calib_ranging_mount.hpp.
#include "calib_ranging_mount.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <map>
#include <set>

#if AGV_HAVE_CERES
#include <ceres/ceres.h>
#endif

namespace agv::desk::rcal {

namespace {

constexpr double kMinDepthMm = 10.0;

// Site point -> undistorted pixel. q: mount {x, y, z, roll, pitch, yaw}; p: vehicle {x, y, theta};
// c: the lens's doubt {focal scale, principal point shift x, y (px)}, {1, 0, 0} as calibrated.
// R_VC = Rz(yaw) Ry(pitch) Rx(roll) R_BC (ranging::rotation_vehicle_from_camera), so the camera
// point is R_BC^T Rx^T Ry^T Rz^T (p_V - m), R_BC^T b = (-b_y, -b_z, b_x).
template <typename T>
bool project_generic(const CameraIntrinsics& k, const T* q, const T* p, const T* c,
                     const double s[3], T* u, T* v) {
  using std::cos;
  using std::sin;
  const T ct = cos(p[2]), st = sin(p[2]);
  const T dx = T(s[0]) - p[0], dy = T(s[1]) - p[1];
  // Vehicle frame, then relative to the optical centre.
  const T d0 = ct * dx + st * dy - q[0], d1 = -st * dx + ct * dy - q[1], d2 = T(s[2]) - q[2];
  const T cy = cos(q[5]), sy = sin(q[5]), cp = cos(q[4]), sp = sin(q[4]), cr = cos(q[3]),
          sr = sin(q[3]);
  const T e0 = cy * d0 + sy * d1, e1 = -sy * d0 + cy * d1, e2 = d2;
  const T f0 = cp * e0 - sp * e2, f1 = e1, f2 = sp * e0 + cp * e2;
  const T b0 = f0, b1 = cr * f1 + sr * f2, b2 = -sr * f1 + cr * f2;
  const T x = -b1, y = -b2, z = b0;
  if (!(z > T(kMinDepthMm))) return false;
  *u = T(k.fx) * c[0] * x / z + T(k.cx) + c[1];
  *v = T(k.fy) * c[0] * y / z + T(k.cy) + c[2];
  return true;
}

std::array<double, 6> params_of(const ranging::RangingMount& m) {
  return {m.x_mm, m.y_mm, m.z_mm, m.roll_rad, m.pitch_rad, m.yaw_rad};
}

#if AGV_HAVE_CERES

ranging::RangingMount mount_of(const double* q) {
  ranging::RangingMount m;
  m.x_mm = q[0];
  m.y_mm = q[1];
  m.z_mm = q[2];
  m.roll_rad = q[3];
  m.pitch_rad = q[4];
  m.yaw_rad = q[5];
  return m;
}

double corner_sigma(const MountSighting& s, const Options& opt) {
  return s.corner_sigma_px > 0.0 ? s.corner_sigma_px : opt.corner_sigma_px;
}

// Per frame (one t_ns): its pose block and the sightings in it.
struct Frame {
  std::array<double, 3> pose{};
  std::array<double, 3> prior{};
  std::array<double, 3> sigma{};
  std::vector<std::size_t> sightings;
};

std::vector<Frame> group_frames(std::span<const MountSighting> s) {
  std::map<std::int64_t, std::size_t> by_t;
  std::vector<Frame> frames;
  for (std::size_t i = 0; i < s.size(); ++i) {
    auto [it, added] = by_t.emplace(s[i].t_ns, frames.size());
    if (added) {
      Frame f;
      f.prior = {s[i].vehicle.x_mm, s[i].vehicle.y_mm, s[i].vehicle.theta_rad};
      f.pose = f.prior;
      f.sigma = s[i].vehicle_sigma;
      frames.push_back(f);
    }
    frames[it->second].sightings.push_back(i);
  }
  return frames;
}

// Per landmark index: corner RMS (pixel distance) of its sightings at the mount and frame poses.
std::map<std::size_t, LandmarkResidual> residuals(const CameraIntrinsics& k,
                                                  std::span<const site::WallLandmark> walls,
                                                  std::span<const MountSighting> s,
                                                  const std::vector<Frame>& frames, const double* q,
                                                  const double* lens) {
  std::map<std::size_t, LandmarkResidual> out;
  std::map<std::size_t, double> sum2;
  for (const Frame& f : frames) {
    for (std::size_t i : f.sightings) {
      const auto corners = wall_corners_site(walls[s[i].landmark_index]);
      LandmarkResidual& r = out[s[i].landmark_index];
      r.id = walls[s[i].landmark_index].id;
      ++r.sightings;
      for (std::size_t c = 0; c < 4; ++c) {
        double u = 0.0, v = 0.0;
        const bool ok = project_generic(k, q, f.pose.data(), lens, corners[c].data(), &u, &v);
        const double du = ok ? u - s[i].corners_undistorted_px[c].x : 1e3;
        const double dv = ok ? v - s[i].corners_undistorted_px[c].y : 1e3;
        sum2[s[i].landmark_index] += du * du + dv * dv;
      }
    }
  }
  for (auto& [index, r] : out) r.rms_px = std::sqrt(sum2[index] / (4.0 * r.sightings));
  return out;
}

struct CornerCost {
  CornerCost(const CameraIntrinsics& k, const std::array<std::array<double, 3>, 4>& corners,
             const std::array<Vec2, 4>& observed, double sigma_px)
      : k_(k), corners_(corners), observed_(observed), inv_sigma_(1.0 / sigma_px) {}
  template <typename T>
  bool operator()(const T* q, const T* p, const T* lens, T* r) const {
    for (std::size_t c = 0; c < 4; ++c) {
      T u, v;
      if (!project_generic(k_, q, p, lens, corners_[c].data(), &u, &v)) return false;
      r[2 * c] = (u - T(observed_[c].x)) * T(inv_sigma_);
      r[2 * c + 1] = (v - T(observed_[c].y)) * T(inv_sigma_);
    }
    return true;
  }
  CameraIntrinsics k_;
  std::array<std::array<double, 3>, 4> corners_;
  std::array<Vec2, 4> observed_;
  double inv_sigma_;
};

// (x - prior) / sigma per component.
template <int N>
struct PriorCost {
  PriorCost(const std::array<double, N>& prior, const std::array<double, N>& sigma)
      : prior_(prior), sigma_(sigma) {}
  template <typename T>
  bool operator()(const T* x, T* r) const {
    for (int i = 0; i < N; ++i) r[i] = (x[i] - T(prior_[i])) / T(sigma_[i]);
    return true;
  }
  std::array<double, N> prior_, sigma_;
};

struct Solved {
  bool ok = false;
  double chi2 = 0.0;  // corner residuals only, in sigmas
  int corner_coords = 0;
};

// The lens's doubt as a nuisance block with its prior (Options::focal_sigma_rel,
// principal_sigma_px): a focal length off by 0.1 % moves every depth by 0.1 %, which the mount's
// offset along the optical axis would otherwise take up with a sigma that knows nothing of it.
// Components without a doubt are held.
void add_lens(const Options& opt, double* lens, ceres::Problem* problem) {
  const std::array<double, 3> sigma{opt.focal_sigma_rel, opt.principal_sigma_px,
                                    opt.principal_sigma_px};
  std::vector<int> held;
  for (int i = 0; i < 3; ++i)
    if (!(sigma[static_cast<std::size_t>(i)] > 0.0)) held.push_back(i);
  if (held.size() == 3) {
    problem->SetParameterBlockConstant(lens);
    return;
  }
  std::array<double, 3> safe = sigma;
  for (int i : held) safe[static_cast<std::size_t>(i)] = 1.0;  // the component is held anyway
  problem->AddResidualBlock(
      new ceres::AutoDiffCostFunction<PriorCost<3>, 3, 3>(new PriorCost<3>({1.0, 0.0, 0.0}, safe)),
      nullptr, lens);
  if (!held.empty()) problem->SetManifold(lens, new ceres::SubsetManifold(3, held));
}

Solved solve_once(const CameraIntrinsics& k, std::span<const site::WallLandmark> walls,
                  std::span<const MountSighting> s, const std::set<std::size_t>& rejected,
                  const std::array<double, 6>& prior, const Options& opt, double* q, double* lens,
                  std::vector<Frame>* frames, ceres::Problem* problem) {
  std::array<double, 6> prior_sigma{};
  for (std::size_t i = 0; i < 6; ++i)
    prior_sigma[i] = i < 3 ? opt.prior_sigma_mm : opt.prior_sigma_rad;
  problem->AddResidualBlock(
      new ceres::AutoDiffCostFunction<PriorCost<6>, 6, 6>(new PriorCost<6>(prior, prior_sigma)),
      nullptr, q);
  Solved out;
  for (Frame& f : *frames) {
    bool used = false;
    for (std::size_t i : f.sightings) {
      if (rejected.count(s[i].landmark_index)) continue;
      auto* cost = new CornerCost(k, wall_corners_site(walls[s[i].landmark_index]),
                                  s[i].corners_undistorted_px, corner_sigma(s[i], opt));
      problem->AddResidualBlock(new ceres::AutoDiffCostFunction<CornerCost, 8, 6, 3, 3>(cost),
                                new ceres::HuberLoss(opt.robust_sigmas), q, f.pose.data(), lens);
      out.corner_coords += 8;
      used = true;
    }
    if (!used) continue;
    problem->AddResidualBlock(
        new ceres::AutoDiffCostFunction<PriorCost<3>, 3, 3>(new PriorCost<3>(f.prior, f.sigma)),
        nullptr, f.pose.data());
  }
  add_lens(opt, lens, problem);
  ceres::Solver::Options so;
  so.linear_solver_type = ceres::SPARSE_SCHUR;
  so.max_num_iterations = 100;
  so.function_tolerance = 1e-12;
  so.parameter_tolerance = 1e-12;
  so.num_threads = 1;
  ceres::Solver::Summary summary;
  ceres::Solve(so, problem, &summary);
  out.ok = summary.IsSolutionUsable();
  for (const Frame& f : *frames) {
    for (std::size_t i : f.sightings) {
      if (rejected.count(s[i].landmark_index)) continue;
      CornerCost cost(k, wall_corners_site(walls[s[i].landmark_index]), s[i].corners_undistorted_px,
                      corner_sigma(s[i], opt));
      double r[8];
      if (!cost(q, f.pose.data(), lens, r)) continue;
      for (double x : r) out.chi2 += x * x;
    }
  }
  return out;
}

// The worst landmark if it stands out (Options::reject_*), else SIZE_MAX.
std::size_t outlier(const std::map<std::size_t, LandmarkResidual>& res,
                    const std::set<std::size_t>& rejected, const Options& opt) {
  std::vector<double> rms;
  std::size_t worst = SIZE_MAX;
  for (const auto& [index, r] : res) {
    if (rejected.count(index)) continue;
    rms.push_back(r.rms_px);
    if (worst == SIZE_MAX || r.rms_px > res.at(worst).rms_px) worst = index;
  }
  if (rms.size() <= static_cast<std::size_t>(opt.min_landmarks)) return SIZE_MAX;
  std::nth_element(rms.begin(), rms.begin() + static_cast<long>(rms.size() / 2), rms.end());
  const double median = rms[rms.size() / 2];
  const double worst_rms = res.at(worst).rms_px;
  return worst_rms > opt.reject_min_px && worst_rms > opt.reject_ratio * median ? worst : SIZE_MAX;
}

// Fills res->sigma from the mount block's covariance; false when singular.
bool mount_sigmas(ceres::Problem* problem, const double* q, double scale, Result* res) {
  ceres::Covariance::Options co;
  co.algorithm_type = ceres::DENSE_SVD;
  co.null_space_rank = 0;
  ceres::Covariance cov(co);
  double c[36];
  const std::vector<std::pair<const double*, const double*>> want = {{q, q}};
  if (!cov.Compute(want, problem) || !cov.GetCovarianceBlock(q, q, c)) return false;
  for (std::size_t i = 0; i < 6; ++i) res->sigma[i] = std::sqrt(std::max(c[i * 7], 0.0) * scale);
  return true;
}

// The landmarks' residuals, the RMS and the counts over what the solve used.
void fill_counts(const std::map<std::size_t, LandmarkResidual>& per_landmark,
                 const std::set<std::size_t>& rejected, const std::vector<Frame>& frames,
                 std::span<const MountSighting> sightings, Result* res) {
  double sum2 = 0.0;
  for (auto [index, r] : per_landmark) {
    r.rejected = rejected.count(index) > 0;
    if (!r.rejected) {
      sum2 += r.rms_px * r.rms_px * 4.0 * r.sightings;
      res->sightings_used += r.sightings;
    }
    res->landmarks.push_back(r);
  }
  res->rms_px = std::sqrt(sum2 / std::max(1, 4 * res->sightings_used));
  for (const Frame& f : frames)
    if (std::any_of(f.sightings.begin(), f.sightings.end(),
                    [&](std::size_t i) { return !rejected.count(sightings[i].landmark_index); }))
      ++res->frames_used;
}

#endif  // AGV_HAVE_CERES

Error count_check(std::span<const MountSighting> s, const Options& opt, std::string* message) {
  std::set<std::int64_t> frames;
  std::set<std::size_t> landmarks;
  for (const MountSighting& m : s) {
    frames.insert(m.t_ns);
    landmarks.insert(m.landmark_index);
  }
  if (static_cast<int>(frames.size()) >= opt.min_frames &&
      static_cast<int>(landmarks.size()) >= opt.min_landmarks)
    return Error::kNone;
  *message = std::to_string(frames.size()) + " frames with " + std::to_string(landmarks.size()) +
             " landmarks at usable poses; at least " + std::to_string(opt.min_frames) + " and " +
             std::to_string(opt.min_landmarks) + " are needed";
  return Error::kTooFewSightings;
}

void check_sigmas(const Options& opt, Result* res) {
  std::string axes;
  const char* names[6] = {"x", "y", "z", "roll", "pitch", "yaw"};
  for (std::size_t i = 0; i < 6; ++i) {
    const double limit = i < 3 ? opt.max_sigma_mm : opt.max_sigma_rad;
    if (!(res->sigma[i] <= limit)) axes += std::string(axes.empty() ? "" : ", ") + names[i];
  }
  if (axes.empty()) return;
  res->error = Error::kPoorlyObserved;
  res->message = "the drive leaves " + axes +
                 " above the sigma limit: drive past landmarks at more distances, heights and "
                 "bearings";
}

}  // namespace

const char* to_string(Error e) {
  switch (e) {
    case Error::kNone:
      return "none";
    case Error::kTooFewSightings:
      return "too-few-sightings";
    case Error::kSolveFailed:
      return "solve-failed";
    case Error::kPoorlyObserved:
      return "poorly-observed";
  }
  return "?";
}

std::array<std::array<double, 3>, 4> wall_corners_site(const site::WallLandmark& w) {
  const double h = w.size_mm / 2.0;
  const double rx = -std::sin(w.facing_rad), ry = std::cos(w.facing_rad);
  auto at = [&](double right, double up) {
    return std::array<double, 3>{w.x_mm + right * rx, w.y_mm + right * ry, w.z_mm + up};
  };
  return {at(-h, h), at(h, h), at(h, -h), at(-h, -h)};
}

bool project_undistorted(const CameraIntrinsics& k, const ranging::RangingMount& mount,
                         const Pose2& vehicle, const std::array<double, 3>& p_site, Vec2* px) {
  const auto q = params_of(mount);
  const double p[3] = {vehicle.x_mm, vehicle.y_mm, vehicle.theta_rad};
  const double lens[3] = {1.0, 0.0, 0.0};
  return project_generic(k, q.data(), p, lens, p_site.data(), &px->x, &px->y);
}

Result solve_mount(const CameraIntrinsics& k, std::span<const site::WallLandmark> walls,
                   std::span<const MountSighting> sightings, const ranging::RangingMount& initial,
                   const Options& opt) {
  Result res;
  res.mount = initial;
  res.error = count_check(sightings, opt, &res.message);
  if (res.error != Error::kNone) return res;
#if AGV_HAVE_CERES
  const std::array<double, 6> prior = params_of(initial);
  std::set<std::size_t> rejected;
  for (;;) {
    std::vector<Frame> frames = group_frames(sightings);
    std::array<double, 6> q = prior;
    std::array<double, 3> lens{1.0, 0.0, 0.0};
    ceres::Problem problem;
    const Solved solved = solve_once(k, walls, sightings, rejected, prior, opt, q.data(),
                                     lens.data(), &frames, &problem);
    if (!solved.ok) {
      res.error = Error::kSolveFailed;
      res.message = "the least squares did not converge";
      return res;
    }
    const auto per_landmark = residuals(k, walls, sightings, frames, q.data(), lens.data());
    const std::size_t bad = outlier(per_landmark, rejected, opt);
    if (bad != SIZE_MAX) {
      rejected.insert(bad);
      continue;
    }
    res.reduced_chi2 = solved.chi2 / std::max(1, solved.corner_coords - 6);
    if (!mount_sigmas(&problem, q.data(), std::max(1.0, res.reduced_chi2), &res)) {
      res.error = Error::kSolveFailed;
      res.message = "the mount's covariance is singular";
      return res;
    }
    res.mount = mount_of(q.data());
    fill_counts(per_landmark, rejected, frames, sightings, &res);
    check_sigmas(opt, &res);
    return res;
  }
#else
  res.error = Error::kSolveFailed;
  res.message = "this build has no Ceres";
  return res;
#endif
}

}  // namespace agv::desk::rcal
