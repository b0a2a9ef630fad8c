// Ceiling camera pose from surveyed tags. Model and conventions: calib_ceiling.hpp.
#include "calib_ceiling.hpp"

#include <apriltag/apriltag.h>
#include <apriltag/common/homography.h>
#include <apriltag/tag36h11.h>

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <limits>
#include <opencv2/calib3d.hpp>
#include <set>
#include <sstream>

#include "agv/site/site_geometry.hpp"

#if AGV_HAVE_CERES
#include <ceres/ceres.h>
#endif

namespace agv::desk::ccal {

namespace {

// A black square under this many pixels a side has modules under 1.5 px: its corners are
// smeared over the neighbouring cells and bias the pose more than they add.
constexpr double kMinTagSidePx = 12.0;
// libapriltag puts pixel centres at +0.5 (its coordinates count from the first pixel's corner);
// the intrinsics and OpenCV count from its centre. Uncorrected, every corner sat 0.71 px off the
// renderer's truth and the pose 2.5 mm off (tests/calib_ceiling).
constexpr double kApriltagPixelOffset = 0.5;

// R_site_cam of the site file's angles (site_geometry.hpp), generic for automatic
// differentiation.
template <typename T>
void rotation(const T& yaw, const T& pitch, const T& roll, T r[9]) {
  using std::cos;
  using std::sin;
  const T cy = cos(yaw), sy = sin(yaw), cp = cos(pitch), sp = sin(pitch), cr = cos(roll),
          sr = sin(roll);
  // diag(1, -1, -1) * Rx(pitch) * Ry(roll)
  const T m[9] = {cr, T(0), sr, -sp * sr, -cp, sp * cr, cp * sr, -sp, -cp * cr};
  for (int c = 0; c < 3; ++c) {
    r[c] = cy * m[c] - sy * m[3 + c];
    r[3 + c] = sy * m[c] + cy * m[3 + c];
    r[6 + c] = m[6 + c];
  }
}

// Site point -> distorted pixel; q = {x, y, z, yaw, pitch, roll}. False behind the camera.
template <typename T>
bool project_generic(const CameraIntrinsics& k, const T* q, const double p[3], T* u, T* v) {
  T r[9];
  rotation(q[3], q[4], q[5], r);
  const T d[3] = {T(p[0]) - q[0], T(p[1]) - q[1], T(p[2]) - q[2]};
  const T x = r[0] * d[0] + r[3] * d[1] + r[6] * d[2];
  const T y = r[1] * d[0] + r[4] * d[1] + r[7] * d[2];
  const T z = r[2] * d[0] + r[5] * d[1] + r[8] * d[2];
  if (!(z > T(1.0))) return false;
  const T xn = x / z, yn = y / z;
  const T r2 = xn * xn + yn * yn;
  const T radial = T(1) + r2 * (T(k.k1) + r2 * (T(k.k2) + r2 * T(k.k3)));
  const T xd = xn * radial + T(2 * k.p1) * xn * yn + T(k.p2) * (r2 + T(2) * xn * xn);
  const T yd = yn * radial + T(k.p1) * (r2 + T(2) * yn * yn) + T(2 * k.p2) * xn * yn;
  *u = T(k.fx) * xd + T(k.cx);
  *v = T(k.fy) * yd + T(k.cy);
  return true;
}

std::array<double, 6> params_of(const CameraPose& p) {
  return {p.x_mm, p.y_mm, p.z_mm, p.yaw_rad, p.pitch_rad, p.roll_rad};
}

cv::Mat camera_matrix(const CameraIntrinsics& k) {
  return (cv::Mat_<double>(3, 3) << k.fx, 0, k.cx, 0, k.fy, k.cy, 0, 0, 1);
}
cv::Mat dist_coeffs(const CameraIntrinsics& k) {
  return (cv::Mat_<double>(1, 5) << k.k1, k.k2, k.p1, k.p2, k.k3);
}

// Observed centre of a sighting: the undistorted diagonals' intersection (the image of the
// square's centre under a pinhole), normalised coordinates. False for a degenerate quad.
bool observed_centre(const CameraIntrinsics& k, const TagSighting& s, Vec2* n) {
  std::vector<cv::Point2d> px, un;
  for (const Vec2& c : s.corners_px) px.emplace_back(c.x, c.y);
  cv::undistortPoints(px, un, camera_matrix(k), dist_coeffs(k), cv::noArray(), cv::noArray(),
                      cv::TermCriteria(cv::TermCriteria::COUNT | cv::TermCriteria::EPS, 50, 1e-14));
  const cv::Point2d a = un[0], b = un[2], c = un[1], d = un[3];
  const cv::Point2d ab = b - a, cd = d - c, ac = c - a;
  const double den = ab.x * cd.y - ab.y * cd.x;
  if (std::abs(den) < 1e-15) return false;
  const double s_ab = (ac.x * cd.y - ac.y * cd.x) / den;
  *n = {a.x + s_ab * ab.x, a.y + s_ab * ab.y};
  return true;
}

// Sightings of surveyed tags only.
std::vector<const TagSighting*> surveyed(const std::map<std::uint32_t, SurveyedTag>& survey,
                                         const std::vector<TagSighting>& sightings) {
  std::vector<const TagSighting*> out;
  for (const TagSighting& s : sightings) {
    if (survey.count(s.id)) out.push_back(&s);
  }
  return out;
}

// Why the used tags fix the pose poorly, or "" when they do not.
std::string degeneracy(const std::map<std::uint32_t, SurveyedTag>& survey,
                       const std::set<std::uint32_t>& ids, double min_cross_spread) {
  Eigen::Vector3d mean = Eigen::Vector3d::Zero();
  std::vector<double> sizes;
  for (std::uint32_t id : ids) {
    const SurveyedTag& t = survey.at(id);
    mean += Eigen::Vector3d(t.x_mm, t.y_mm, t.z_mm);
    sizes.push_back(t.size_mm);
  }
  mean /= static_cast<double>(ids.size());
  Eigen::Matrix3d cov = Eigen::Matrix3d::Zero();
  for (std::uint32_t id : ids) {
    const SurveyedTag& t = survey.at(id);
    const Eigen::Vector3d d = Eigen::Vector3d(t.x_mm, t.y_mm, t.z_mm) - mean;
    cov += d * d.transpose();
  }
  cov /= static_cast<double>(ids.size());
  const Eigen::Vector3d ev = Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d>(cov).eigenvalues();
  const double along = std::sqrt(std::max(ev(2), 0.0));
  const double across = std::sqrt(std::max(ev(1), 0.0));
  std::nth_element(sizes.begin(), sizes.begin() + static_cast<long>(sizes.size() / 2), sizes.end());
  const double limit = std::max(min_cross_spread * along, sizes[sizes.size() / 2]);
  if (across >= limit) return "";
  std::ostringstream m;
  m.precision(4);
  m << "the " << ids.size() << " tags' centres lie nearly on one line (spread across it " << across
    << " mm RMS, along it " << along << " mm; needs at least " << limit
    << " mm across): place tags off that line";
  return m.str();
}

// PnP on every corner (SQPnP, which handles the planar case; the iterative solver as fallback).
bool pnp_start(const CameraIntrinsics& k, const std::map<std::uint32_t, SurveyedTag>& survey,
               const std::vector<const TagSighting*>& used, CameraPose* out) {
  std::vector<cv::Point3d> obj;
  std::vector<cv::Point2d> img;
  for (const TagSighting* s : used) {
    const auto corners = tag_corners_site(survey.at(s->id));
    for (int c = 0; c < 4; ++c) {
      obj.emplace_back(corners[c][0], corners[c][1], corners[c][2]);
      img.emplace_back(s->corners_px[c].x, s->corners_px[c].y);
    }
  }
  cv::Mat rvec, tvec;
  bool ok = false;
  for (int method : {cv::SOLVEPNP_SQPNP, cv::SOLVEPNP_ITERATIVE}) {
    try {
      ok = cv::solvePnP(obj, img, camera_matrix(k), dist_coeffs(k), rvec, tvec, false, method);
    } catch (const cv::Exception&) {
      ok = false;
    }
    if (ok && cv::checkRange(rvec) && cv::checkRange(tvec)) break;
    ok = false;
  }
  if (!ok) return false;
  cv::Mat r_cam_site;
  cv::Rodrigues(rvec, r_cam_site);
  const cv::Mat r = r_cam_site.t();
  const cv::Mat t = -r * tvec;
  site::CeilingCamera c;
  for (int i = 0; i < 9; ++i)
    c.r_site_cam[static_cast<std::size_t>(i)] = r.at<double>(i / 3, i % 3);
  for (int i = 0; i < 3; ++i) c.t_site_cam_mm[static_cast<std::size_t>(i)] = t.at<double>(i);
  *out = pose_of(c);
  return true;
}

}  // namespace

std::array<std::array<double, 3>, 4> tag_corners_site(const SurveyedTag& t) {
  const double h = t.size_mm / 2.0;
  const double ux = std::cos(t.yaw_rad), uy = std::sin(t.yaw_rad);  // page up
  const double rx = uy, ry = -ux;                                   // page right
  auto at = [&](double up, double right) {
    return std::array<double, 3>{t.x_mm + h * (up * ux + right * rx),
                                 t.y_mm + h * (up * uy + right * ry), t.z_mm};
  };
  return {at(1, -1), at(1, 1), at(-1, 1), at(-1, -1)};
}

std::vector<TagSighting> detect_tags(const cv::Mat& gray, int frame) {
  std::vector<TagSighting> out;
  if (gray.empty() || gray.type() != CV_8UC1) return out;
  const cv::Mat img = gray.isContinuous() ? gray : gray.clone();
  apriltag_family_t* fam = tag36h11_create();
  apriltag_detector_t* det = apriltag_detector_create();
  apriltag_detector_add_family_bits(det, fam, 1);
  det->quad_decimate = 1.0f;
  det->nthreads = 1;
  det->refine_edges = true;
  image_u8_t view{img.cols, img.rows, static_cast<std::int32_t>(img.step), img.data};
  zarray_t* dets = apriltag_detector_detect(det, &view);
  for (int i = 0; i < zarray_size(dets); ++i) {
    apriltag_detection_t* d = nullptr;
    zarray_get(dets, i, &d);
    TagSighting s;
    s.frame = frame;
    s.id = static_cast<std::uint32_t>(d->id);
    s.decision_margin = static_cast<double>(d->decision_margin);
    // Tag coordinates: +-1 the black square's outer edge, page up = -y.
    const double tc[4][2] = {{-1, -1}, {1, -1}, {1, 1}, {-1, 1}};
    for (int c = 0; c < 4; ++c) {
      homography_project(d->H, tc[c][0], tc[c][1], &s.corners_px[c].x, &s.corners_px[c].y);
      s.corners_px[c].x -= kApriltagPixelOffset;
      s.corners_px[c].y -= kApriltagPixelOffset;
    }
    double side = std::numeric_limits<double>::infinity();
    for (int c = 0; c < 4; ++c) {
      const Vec2 a = s.corners_px[c], b = s.corners_px[(c + 1) % 4];
      side = std::min(side, std::hypot(b.x - a.x, b.y - a.y));
    }
    if (!(side >= kMinTagSidePx)) continue;
    out.push_back(s);
  }
  apriltag_detections_destroy(dets);
  apriltag_detector_destroy(det);
  tag36h11_destroy(fam);
  std::sort(out.begin(), out.end(),
            [](const TagSighting& a, const TagSighting& b) { return a.id < b.id; });
  return out;
}

CameraPose pose_of(const site::CeilingCamera& cam) {
  CameraPose p;
  p.x_mm = cam.t_site_cam_mm[0];
  p.y_mm = cam.t_site_cam_mm[1];
  p.z_mm = cam.t_site_cam_mm[2];
  site::camera_angles_from_rotation(cam.r_site_cam, &p.yaw_rad, &p.pitch_rad, &p.roll_rad);
  return p;
}

void set_pose(const CameraPose& p, site::CeilingCamera* cam) {
  cam->r_site_cam = site::camera_rotation_from_angles(p.yaw_rad, p.pitch_rad, p.roll_rad);
  cam->t_site_cam_mm = {p.x_mm, p.y_mm, p.z_mm};
}

bool project(const CameraIntrinsics& k, const CameraPose& pose, const std::array<double, 3>& p,
             Vec2* px) {
  const auto q = params_of(pose);
  return project_generic(k, q.data(), p.data(), &px->x, &px->y);
}

Evaluation evaluate(const CameraIntrinsics& k, const std::map<std::uint32_t, SurveyedTag>& survey,
                    const std::vector<TagSighting>& sightings, const CameraPose& pose) {
  Evaluation ev;
  site::CeilingCamera cam;
  set_pose(pose, &cam);
  const auto& r = cam.r_site_cam;
  struct Acc {
    int n = 0, centres = 0;
    double se = 0.0, sx = 0.0, sy = 0.0;
    bool miss = false;
  };
  std::map<std::uint32_t, Acc> acc;
  double se_all = 0.0;
  for (const TagSighting* s : surveyed(survey, sightings)) {
    const SurveyedTag& t = survey.at(s->id);
    Acc& a = acc[s->id];
    ++a.n;
    const auto corners = tag_corners_site(t);
    for (int c = 0; c < 4; ++c) {
      Vec2 px;
      double e2 = std::numeric_limits<double>::infinity();
      if (project(k, pose, corners[c], &px)) {
        e2 = std::pow(px.x - s->corners_px[c].x, 2) + std::pow(px.y - s->corners_px[c].y, 2);
      }
      a.se += e2;
      se_all += e2;
      ev.max_px = std::max(ev.max_px, std::sqrt(e2));
      ++ev.corners;
    }
    Vec2 n;
    if (!observed_centre(k, *s, &n)) {
      a.miss = true;
      continue;
    }
    const double d[3] = {r[0] * n.x + r[1] * n.y + r[2], r[3] * n.x + r[4] * n.y + r[5],
                         r[6] * n.x + r[7] * n.y + r[8]};
    const double along = (t.z_mm - pose.z_mm) / d[2];
    if (!(along > 0.0) || !std::isfinite(along)) {
      a.miss = true;
      continue;
    }
    a.sx += pose.x_mm + along * d[0];
    a.sy += pose.y_mm + along * d[1];
    ++a.centres;
  }
  ev.rms_px = ev.corners ? std::sqrt(se_all / ev.corners) : 0.0;
  double floor_se = 0.0;
  for (const auto& [id, a] : acc) {
    TagResidual tr;
    tr.id = id;
    tr.sightings = a.n;
    tr.rms_px = std::sqrt(a.se / (4.0 * a.n));
    if (a.miss || a.centres == 0) {
      tr.floor_dx_mm = tr.floor_dy_mm = tr.floor_mm = std::numeric_limits<double>::quiet_NaN();
    } else {
      tr.floor_dx_mm = a.sx / a.centres - survey.at(id).x_mm;
      tr.floor_dy_mm = a.sy / a.centres - survey.at(id).y_mm;
      tr.floor_mm = std::hypot(tr.floor_dx_mm, tr.floor_dy_mm);
      floor_se += tr.floor_mm * tr.floor_mm;
    }
    ev.max_floor_mm = std::isnan(tr.floor_mm) || std::isnan(ev.max_floor_mm)
                          ? std::numeric_limits<double>::quiet_NaN()
                          : std::max(ev.max_floor_mm, tr.floor_mm);
    ev.tags.push_back(tr);
  }
  const double dof = 2.0 * static_cast<double>(ev.tags.size()) - 6.0;
  ev.floor_sigma_mm = dof > 0.0 ? std::sqrt(floor_se / dof) : 0.0;
  return ev;
}

const char* to_string(Error e) {
  switch (e) {
    case Error::kNone:
      return "none";
    case Error::kTooFewTags:
      return "too-few-tags";
    case Error::kDegenerate:
      return "degenerate-geometry";
    case Error::kSolveFailed:
      return "solve-failed";
  }
  return "unknown";
}

#if AGV_HAVE_CERES
namespace {

CameraPose pose_from_params(const double* q) {
  CameraPose p{q[0], q[1], q[2], q[3], q[4], q[5]};
  // Back to the site file's ranges (the same rotation).
  site::CeilingCamera c;
  set_pose(p, &c);
  return pose_of(c);
}

struct CornerCost {
  CornerCost(const CameraIntrinsics& k, const std::array<double, 3>& p, Vec2 obs)
      : k_(k), p_(p), obs_(obs) {}
  template <typename T>
  bool operator()(const T* q, T* res) const {
    T u, v;
    if (!project_generic(k_, q, p_.data(), &u, &v)) return false;
    res[0] = u - T(obs_.x);
    res[1] = v - T(obs_.y);
    return true;
  }
  CameraIntrinsics k_;
  std::array<double, 3> p_;
  Vec2 obs_;
};

// Variance of each parameter (x, y, z, yaw, pitch, roll) with the residuals taken as independent
// between tags only (the cluster-robust estimate by the linearised jackknife over tags, CR3,
// which stays on the safe side with a dozen tags where the plain sandwich does not): a tag's
// corners share its survey error, and its sightings in several frames share that and the
// detector's bias, so counting every corner as independent overstates what the data know. False
// where it cannot be formed (fewer than two tags, a singular normal matrix).
using Mat6 = Eigen::Matrix<double, 6, 6>;
bool tag_clustered_covariance(const ceres::CRSMatrix& jac, const std::vector<double>& r,
                              const std::vector<std::uint32_t>& row_tag, Mat6* out) {
  const int n = jac.num_rows;
  if (jac.num_cols != 6 || n != static_cast<int>(r.size()) ||
      n != static_cast<int>(row_tag.size()) || n <= 6) {
    return false;
  }
  Eigen::MatrixXd j = Eigen::MatrixXd::Zero(n, 6);
  for (int row = 0; row < n; ++row) {
    for (int e = jac.rows[static_cast<std::size_t>(row)];
         e < jac.rows[static_cast<std::size_t>(row) + 1]; ++e) {
      j(row, jac.cols[static_cast<std::size_t>(e)]) = jac.values[static_cast<std::size_t>(e)];
    }
  }
  const Eigen::Matrix<double, 6, 6> a = j.transpose() * j;
  const Eigen::FullPivLU<Eigen::Matrix<double, 6, 6>> lu(a);
  if (lu.rank() < 6) return false;
  struct Tag {
    Eigen::Matrix<double, 6, 6> info = Eigen::Matrix<double, 6, 6>::Zero();
    Eigen::Matrix<double, 6, 1> score = Eigen::Matrix<double, 6, 1>::Zero();
  };
  std::map<std::uint32_t, Tag> tags;
  for (int row = 0; row < n; ++row) {
    Tag& t = tags[row_tag[static_cast<std::size_t>(row)]];
    t.info += j.row(row).transpose() * j.row(row);
    t.score += j.row(row).transpose() * r[static_cast<std::size_t>(row)];
  }
  const double g = static_cast<double>(tags.size());
  if (g < 2) return false;
  // The pose's shift when one tag is left out: (A - A_g)^-1 J_g^T r_g.
  Eigen::Matrix<double, 6, 6> c = Eigen::Matrix<double, 6, 6>::Zero();
  for (const auto& [id, t] : tags) {
    const Eigen::FullPivLU<Eigen::Matrix<double, 6, 6>> without(a - t.info);
    if (without.rank() < 6) return false;
    const Eigen::Matrix<double, 6, 1> d = without.solve(t.score);
    c += d * d.transpose();
  }
  *out = c * ((g - 1.0) / g);
  return true;
}

// Robust refinement from *q; the sigmas from the covariance scaled by the residual variance, or
// from the residuals' spread between tags where that is larger (tag_clustered_covariance).
bool refine(const CameraIntrinsics& k, const std::map<std::uint32_t, SurveyedTag>& survey,
            const std::vector<const TagSighting*>& used, const Options& opt, double q[6],
            Result* res) {
  ceres::Problem problem;
  std::vector<ceres::ResidualBlockId> blocks;
  std::vector<std::uint32_t> row_tag;  // per residual row
  for (const TagSighting* s : used) {
    const auto corners = tag_corners_site(survey.at(s->id));
    for (int c = 0; c < 4; ++c) {
      row_tag.insert(row_tag.end(), 2, s->id);
      blocks.push_back(
          problem.AddResidualBlock(new ceres::AutoDiffCostFunction<CornerCost, 2, 6>(
                                       new CornerCost(k, corners[c], s->corners_px[c])),
                                   new ceres::HuberLoss(opt.robust_px), q));
    }
  }
  ceres::Solver::Options so;
  so.linear_solver_type = ceres::DENSE_QR;
  so.max_num_iterations = 100;
  so.function_tolerance = 1e-12;
  so.parameter_tolerance = 1e-12;
  so.num_threads = 1;
  ceres::Solver::Summary summary;
  ceres::Solve(so, &problem, &summary);
  if (!summary.IsSolutionUsable()) {
    res->message = "the refinement failed: " + summary.message;
    return false;
  }
  // Residual variance per coordinate without the robust loss.
  ceres::Problem::EvaluateOptions eo;
  eo.apply_loss_function = false;
  eo.residual_blocks = blocks;
  std::vector<double> r;
  double cost = 0.0;
  ceres::CRSMatrix jac;
  problem.Evaluate(eo, &cost, &r, nullptr, &jac);
  Mat6 clustered;
  const bool clustered_ok = tag_clustered_covariance(jac, r, row_tag, &clustered);
  double ss = 0.0;
  for (double v : r) ss += v * v;
  const double dof = static_cast<double>(r.size()) - 6.0;
  const double var = dof > 0 ? ss / dof : std::numeric_limits<double>::quiet_NaN();
  res->residual_sigma_px = std::sqrt(var);
  ceres::Covariance::Options co;
  co.algorithm_type = ceres::DENSE_SVD;
  co.null_space_rank = 0;
  ceres::Covariance cov(co);
  double c[36];
  const std::vector<std::pair<const double*, const double*>> want = {{q, q}};
  const bool cov_ok = cov.Compute(want, &problem) && cov.GetCovarianceBlock(q, q, c);
  if (!cov_ok) {
    res->sigma.fill(std::numeric_limits<double>::quiet_NaN());
    return true;
  }
  // Each sigma the larger of the two estimates; the correlations those of the one between tags
  // where it could be formed.
  const Mat6 iid = Eigen::Map<const Eigen::Matrix<double, 6, 6, Eigen::RowMajor>>(c) * var;
  const Mat6& shape = clustered_ok ? clustered : iid;
  // Result order: x, y, z, roll, pitch, yaw; parameter order x, y, z, yaw, pitch, roll.
  const int order[6] = {0, 1, 2, 5, 4, 3};
  for (int i = 0; i < 6; ++i) {
    const int p = order[i];
    const double v = std::max(iid(p, p), clustered_ok ? clustered(p, p) : 0.0);
    res->sigma[static_cast<std::size_t>(i)] = std::sqrt(std::max(v, 0.0));
  }
  std::size_t at = 0;
  for (int i = 0; i < 6; ++i) {
    for (int j = i + 1; j < 6; ++j, ++at) {
      const int a = order[i], b = order[j];
      const double d = std::sqrt(shape(a, a) * shape(b, b));
      res->correlation[at] = d > 0.0 ? std::clamp(shape(a, b) / d, -1.0, 1.0) : 0.0;
    }
  }
  return true;
}

}  // namespace
#endif

namespace {

// One solve on every surveyed tag seen.
Result solve_once(const CameraIntrinsics& k, const std::map<std::uint32_t, SurveyedTag>& survey,
                  const std::vector<TagSighting>& sightings, const Options& opt) {
  Result res;
  const std::vector<const TagSighting*> used = surveyed(survey, sightings);
  std::set<std::uint32_t> ids, unsurveyed;
  for (const TagSighting* s : used) ids.insert(s->id);
  for (const TagSighting& s : sightings) {
    if (!survey.count(s.id)) unsurveyed.insert(s.id);
  }
  res.unsurveyed_ids.assign(unsurveyed.begin(), unsurveyed.end());
  res.tags_used = static_cast<int>(ids.size());
  res.corners_used = 4 * static_cast<int>(used.size());
  if (res.tags_used < opt.min_tags) {
    res.error = Error::kTooFewTags;
    res.message = std::to_string(res.tags_used) + " surveyed tag(s) seen (" +
                  std::to_string(res.unsurveyed_ids.size()) +
                  " more not in the survey); needs at least " + std::to_string(opt.min_tags) +
                  " not on one line";
    return res;
  }
  if (std::string why = degeneracy(survey, ids, opt.min_cross_spread); !why.empty()) {
    res.error = Error::kDegenerate;
    res.message = why;
    return res;
  }
  CameraPose start;
  if (opt.initial) {
    start = *opt.initial;
  } else if (!pnp_start(k, survey, used, &start)) {
    res.error = Error::kSolveFailed;
    res.message = "PnP found no pose for the tags' corners";
    return res;
  }
#if AGV_HAVE_CERES
  auto q = params_of(start);
  if (!refine(k, survey, used, opt, q.data(), &res)) {
    res.error = Error::kSolveFailed;
    return res;
  }
  res.pose = pose_from_params(q.data());
  res.eval = evaluate(k, survey, sightings, res.pose);
  return res;
#else
  res.error = Error::kSolveFailed;
  res.message = "this build has no Ceres (Debian libceres-dev): the pose is not refined";
  return res;
#endif
}

}  // namespace

Result solve_camera_pose(const CameraIntrinsics& k,
                         const std::map<std::uint32_t, SurveyedTag>& survey,
                         const std::vector<TagSighting>& sightings, const Options& opt) {
  std::map<std::uint32_t, SurveyedTag> active = survey;
  std::vector<std::uint32_t> rejected;
  Options o = opt;
  CameraPose last;
  Result res = solve_once(k, active, sightings, o);
  // A tag far off the others' pose was surveyed wrong or has moved: the robust loss only
  // lessens its pull (50 mm off moved the pose by 13 mm in the tests), so it is left out and the
  // pose solved again, while the rest still fix it.
  while (res.error == Error::kNone && !res.eval.tags.empty()) {
    std::vector<double> rms;
    const TagResidual* worst = &res.eval.tags.front();
    for (const TagResidual& t : res.eval.tags) {
      rms.push_back(t.rms_px);
      if (t.rms_px > worst->rms_px) worst = &t;
    }
    std::nth_element(rms.begin(), rms.begin() + static_cast<long>(rms.size() / 2), rms.end());
    const double limit = std::max(opt.reject_min_px, opt.reject_ratio * rms[rms.size() / 2]);
    if (worst->rms_px <= limit || static_cast<int>(res.eval.tags.size()) <= opt.min_tags) break;
    std::set<std::uint32_t> rest;
    for (const TagResidual& t : res.eval.tags) {
      if (t.id != worst->id) rest.insert(t.id);
    }
    if (!degeneracy(active, rest, opt.min_cross_spread).empty()) break;
    rejected.push_back(worst->id);
    active.erase(worst->id);
    last = res.pose;
    o.initial = &last;
    res = solve_once(k, active, sightings, o);
  }
  if (res.error != Error::kNone) return res;
  std::sort(rejected.begin(), rejected.end());
  res.rejected_ids = rejected;
  std::set<std::uint32_t> unsurveyed;
  for (const TagSighting& s : sightings) {
    if (!survey.count(s.id)) unsurveyed.insert(s.id);
  }
  res.unsurveyed_ids.assign(unsurveyed.begin(), unsurveyed.end());
  // The summary over the tags used; the table lists the rejected ones too.
  const Evaluation used = evaluate(k, active, sightings, res.pose);
  res.eval = evaluate(k, survey, sightings, res.pose);
  res.eval.corners = used.corners;
  res.eval.rms_px = used.rms_px;
  res.eval.max_px = used.max_px;
  res.eval.max_floor_mm = used.max_floor_mm;
  res.eval.floor_sigma_mm = used.floor_sigma_mm;
  return res;
}

}  // namespace agv::desk::ccal
