// eval_ranging: Monte-Carlo over simulated geometry (not recorded images) of range models and
// fixes from landmarks seen at a distance. Square tags of 150 mm on vertical surfaces 2-8 m away,
// a 1280x800 camera with a 1000 px focal length (65 degrees across), corner noise 0.3 px.
// Compares the pinhole size range with the range from a full tag pose (OpenCV's IPPE square
// solver on the same noisy corners), the two-circle fix with the image left/right rule against
// the bearing-difference rule and the Gauss-Newton refinement, and determinant trilateration
// against weighted least squares. Figures: docs/design/ranging.md.
#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <limits>
#include <map>
#include <opencv2/calib3d.hpp>
#include <random>
#include <string>
#include <vector>

#include "agv/ranging/fix.hpp"
#include "agv/ranging/range_models.hpp"
#include "fix_errors.hpp"

namespace {

using namespace agv;
using namespace agv::ranging;
using Eigen::Matrix3d;
using Eigen::Vector3d;

constexpr double kTagMm = 150.0;
constexpr double kCornerSigmaPx = 0.3;
using ranging_eval::FixErrors;
using ranging_eval::kNees3Sigma;
// The pose-based range's covariance: the closed form for a tag facing the camera, or the corner
// Fisher information at the estimated pose (the default).
bool pose_cov_closed_form = false;

CameraIntrinsics eval_camera() {
  return {.width_px = 1280, .height_px = 800, .fx = 1000.0, .fy = 1000.0, .cx = 639.5, .cy = 399.5};
}

// A landmark as the simulation knows it: centre and face normal in V, world position.
struct Truth {
  Vector3d p_V;
  double facing_V_rad;  // face normal direction in V (towards the viewer, roughly)
  Vec2 world_mm;
  int camera;
};

enum class Method { kSizeLiteral, kSizeDepth, kPose };

// What one camera measures of one landmark, by each method.
struct Measured {
  bool ok = false;
  Observation size_literal, size_depth, pose;
  bool l_column_valid = false;
  double column_px = 0.0;
};

Vec2 world_of(const Pose2& vehicle, const Vector3d& p_V) {
  return transform(vehicle, {p_V.x(), p_V.y()});
}

std::vector<cv::Point3d> tag_object_points() {
  const double h = kTagMm / 2;
  return {{-h, h, 0}, {h, h, 0}, {h, -h, 0}, {-h, -h, 0}};
}

Observation to_observation(const RangeBearing& rb, Vec2 world) {
  Observation o;
  o.landmark_mm = world;
  o.range_mm = rb.range_mm;
  o.bearing_rad = rb.bearing_rad;
  o.cov = rb.cov.topLeftCorner<2, 2>();
  return o;
}

Measured measure(const Truth& t, const RangingMount& mount, std::mt19937_64& rng) {
  const CameraIntrinsics k = eval_camera();
  std::normal_distribution<double> noise(0.0, kCornerSigmaPx);
  const Matrix3d R_VC = rotation_vehicle_from_camera(mount);
  const Vector3d m(mount.x_mm, mount.y_mm, mount.z_mm);
  // Tag frame: z into the tag (against the face normal), y down, x = y cross z.
  const Vector3d z_T(-std::cos(t.facing_V_rad), -std::sin(t.facing_V_rad), 0.0), y_T(0, 0, -1);
  Matrix3d R_VT;
  R_VT << y_T.cross(z_T), y_T, z_T;
  const Matrix3d R_CT = R_VC.transpose() * R_VT;
  const Vector3d t_C = R_VC.transpose() * (t.p_V - m);
  Measured out;
  std::vector<cv::Point2d> px;
  for (const cv::Point3d& c : tag_object_points()) {
    const Vector3d X = R_CT * Vector3d(c.x, c.y, c.z) + t_C;
    if (X.z() <= 0.0) return out;
    const double u = k.fx * X.x() / X.z() + k.cx + noise(rng),
                 v = k.fy * X.y() / X.z() + k.cy + noise(rng);
    if (u < 0 || v < 0 || u > k.width_px - 1 || v > k.height_px - 1) return out;
    px.push_back({u, v});
  }
  // Size range from the two vertical edges (corners 0-3 and 1-2): each edge's length has
  // variance 2 sigma^2, their mean sigma^2.
  const double h_px = 0.5 * ((px[0].y - px[3].y) + (px[1].y - px[2].y));
  const SizeRange depth = size_range(k.fx, kTagMm, h_px, kCornerSigmaPx);
  Vec2 centre{0, 0};
  for (const cv::Point2d& p : px) centre = {centre.x + p.x / 4, centre.y + p.y / 4};
  const CameraPoint cp = size_camera_point(k, centre, kCornerSigmaPx / 2, depth);
  out.size_depth = to_observation(range_bearing_from_camera_point(mount, cp), t.world_mm);
  // The paper's reading: the size range is the distance along the ray.
  CameraPoint literal = cp;
  literal.p_mm = cp.p_mm.normalized() * depth.depth_mm;
  out.size_literal = to_observation(range_bearing_from_camera_point(mount, literal), t.world_mm);
  // Full pose from the same corners.
  cv::Mat rvec, tvec;
  const cv::Matx33d K(k.fx, 0, k.cx, 0, k.fy, k.cy, 0, 0, 1);
  if (!cv::solvePnP(tag_object_points(), px, K, cv::noArray(), rvec, tvec, false,
                    cv::SOLVEPNP_IPPE_SQUARE)) {
    return out;
  }
  const Vector3d t_est(tvec.at<double>(0), tvec.at<double>(1), tvec.at<double>(2));
  cv::Matx33d R_cv;
  cv::Rodrigues(rvec, R_cv);
  Matrix3d R_est;
  for (int i = 0; i < 9; ++i) R_est(i / 3, i % 3) = R_cv(i / 3, i % 3);
  if (pose_cov_closed_form) {
    const Matrix3d cov_t = tag_translation_covariance(k.fx, kTagMm, t_est, kCornerSigmaPx);
    out.pose = to_observation(range_bearing_from_tag_translation(mount, t_est, cov_t), t.world_mm);
  } else {
    const auto cov6 = tag_pose_covariance(k.fx, kTagMm, t_est, R_est, kCornerSigmaPx);
    out.pose = to_observation(range_bearing_from_tag_pose(mount, t_est, R_est, cov6), t.world_mm);
  }
  out.column_px = centre.x;
  out.ok = true;
  return out;
}

const Observation& pick(const Measured& m, Method method) {
  return method == Method::kPose        ? m.pose
         : method == Method::kSizeDepth ? m.size_depth
                                        : m.size_literal;
}

// Percentiles of a sample, in place.
double percentile(std::vector<double>& v, double p) {
  if (v.empty()) return std::numeric_limits<double>::quiet_NaN();
  const std::size_t i =
      std::min(v.size() - 1, static_cast<std::size_t>(p * static_cast<double>(v.size())));
  std::nth_element(v.begin(), v.begin() + static_cast<std::ptrdiff_t>(i), v.end());
  return v[i];
}

// A landmark in camera c's view: range from the camera 2-8 m, within the field of view.
Truth sample_landmark(const RangingMount& mount, int camera, double bearing_lo, double bearing_hi,
                      std::mt19937_64& rng) {
  std::uniform_real_distribution<double> uni(0.0, 1.0);
  const double range = 2000.0 + 6000.0 * uni(rng);
  const double b = mount.yaw_rad + bearing_lo + (bearing_hi - bearing_lo) * uni(rng);
  Truth t;
  t.p_V = Vector3d(mount.x_mm + range * std::cos(b), mount.y_mm + range * std::sin(b),
                   700.0 + 900.0 * uni(rng));
  // Faces the camera within +-30 degrees.
  t.facing_V_rad = b + kPi + deg_to_rad(60.0 * uni(rng) - 30.0);
  t.camera = camera;
  return t;
}

void range_table(std::mt19937_64& rng) {
  const RangingMount mount{300.0, 0.0, 1000.0, 0.0, 0.0, 0.0};
  const char* names[4] = {"size, paper (range = f H / h)", "size, as depth along the axis",
                          "tag pose, Fisher cov", "tag pose, closed-form cov"};
  std::printf("\n== Range and bearing per landmark (10000 landmarks, simulated geometry) ==\n");
  std::printf("%-32s %-8s %8s %8s %8s %9s %9s %10s\n", "method", "range m", "bias mm", "p50 mm",
              "p95 mm", "sd mm", "model sd", "brg p95 mr");
  const std::uint64_t seed = rng();
  for (int method = 0; method < 4; ++method) {
    std::mt19937_64 r(seed);  // the same landmarks and corner noise for every method
    pose_cov_closed_form = method == 3;
    std::map<int, std::vector<Vector3d>> bins;  // (error, predicted sd, bearing error)
    for (int i = 0; i < 10000; ++i) {
      const Truth t = sample_landmark(mount, 0, -0.5, 0.5, r);
      const Measured m = measure(t, mount, r);
      if (!m.ok) continue;
      const Observation& o = pick(m, static_cast<Method>(std::min(method, 2)));
      const double truth_range = std::hypot(t.p_V.x(), t.p_V.y());
      const double truth_bearing = std::atan2(t.p_V.y(), t.p_V.x());
      const double cam_range = std::hypot(t.p_V.x() - mount.x_mm, t.p_V.y() - mount.y_mm);
      bins[static_cast<int>(cam_range / 2000.0)].push_back(
          {o.range_mm - truth_range, std::sqrt(o.cov(0, 0)),
           wrap_angle_rad(o.bearing_rad - truth_bearing)});
    }
    pose_cov_closed_form = false;
    for (auto& [bin, v] : bins) {
      if (bin < 1 || bin > 3) continue;
      double mean = 0, var = 0, model = 0;
      std::vector<double> abs_e, abs_b;
      for (const Vector3d& e : v) mean += e.x() / static_cast<double>(v.size());
      for (const Vector3d& e : v) {
        var += (e.x() - mean) * (e.x() - mean) / static_cast<double>(v.size());
        model += e.y() * e.y() / static_cast<double>(v.size());
        abs_e.push_back(std::abs(e.x()));
        abs_b.push_back(std::abs(e.z()) * 1e3);
      }
      std::printf("%-32s %d-%d     %8.1f %8.1f %8.1f %9.1f %9.1f %10.3f\n", names[method], 2 * bin,
                  2 * bin + 2, mean, percentile(abs_e, 0.5), percentile(abs_e, 0.95),
                  std::sqrt(var), std::sqrt(model), percentile(abs_b, 0.95));
    }
  }
}

struct Tally : FixErrors {
  int covered = 0;
  void add(const FixResult& f, const Pose2& truth) {
    const std::optional<Eigen::Vector3d> e = FixErrors::add(f, truth);
    if (!e) return;
    const Eigen::Matrix3d cov = f.cov;
    covered += cov.determinant() > 0.0 && e->dot(cov.ldlt().solve(*e)) <= kNees3Sigma;
  }
  void print(const char* name) {
    std::string refused;
    for (const auto& [k, n] : refusals) refused += " " + k + "=" + std::to_string(n);
    std::printf("%-46s %5d/%-5d %7.1f %7.1f %6.2f %6.2f %6.1f%% %5d %s\n", name, ok, tried,
                percentile(pos_mm, 0.5), percentile(pos_mm, 0.95), percentile(heading_deg, 0.5),
                percentile(heading_deg, 0.95), ok ? 100.0 * covered / ok : 0.0, wrong,
                refused.c_str());
  }
};

void print_fix_header(const char* title) {
  std::printf("\n== %s ==\n", title);
  std::printf("%-46s %11s %7s %7s %6s %6s %7s %5s %s\n", "fix", "ok/trials", "p50 mm", "p95 mm",
              "p50 deg", "p95 deg", "3sig cov", "wrong", "refusals");
}

Pose2 random_pose(std::mt19937_64& rng) {
  std::uniform_real_distribution<double> uni(0.0, 1.0);
  return {50000.0 * uni(rng), 30000.0 * uni(rng), kPi * (2 * uni(rng) - 1)};
}

const RangingMount kMounts[2] = {{300.0, 0.0, 1000.0, 0.0, 0.0, 0.0},
                                 {0.0, 250.0, 1000.0, 0.0, 0.0, kPi / 2}};

// One trial: the vehicle somewhere, landmarks in the given cameras' views, measured.
struct Scene {
  Pose2 truth;
  std::vector<Truth> landmarks;
  std::vector<Measured> measured;
};

bool make_scene(const std::vector<int>& cameras, std::mt19937_64& rng, Scene* s) {
  s->truth = random_pose(rng);
  s->landmarks.clear();
  s->measured.clear();
  for (int c : cameras) {
    Truth t = sample_landmark(kMounts[c], c, -0.5, 0.5, rng);
    t.world_mm = world_of(s->truth, t.p_V);
    const Measured m = measure(t, kMounts[c], rng);
    if (!m.ok) return false;
    s->landmarks.push_back(t);
    s->measured.push_back(m);
  }
  return true;
}

std::vector<Observation> observations(const Scene& s, Method method) {
  std::vector<Observation> obs;
  for (const Measured& m : s.measured) obs.push_back(pick(m, method));
  return obs;
}

void two_landmark_table(const char* title, const std::vector<int>& cameras, std::mt19937_64& rng) {
  print_fix_header(title);
  FixOptions paper_opt;
  paper_opt.min_crossing_angle_rad = 0.0;  // the paper has no geometry check
  const FixOptions opt;
  Tally paper, lr_size, lr_pose, bd_pose, wls_size, wls_pose;
  Scene s;
  for (int trial = 0; trial < 4000; ++trial) {
    if (!make_scene(cameras, rng, &s)) continue;
    // Left in the image: the smaller column, compared across images when there are two cameras.
    const bool l0_left = s.measured[0].column_px < s.measured[1].column_px;
    const auto lit = observations(s, Method::kSizeLiteral),
               dep = observations(s, Method::kSizeDepth), pos = observations(s, Method::kPose);
    paper.add(fix_two_circles(lit[0], lit[1], TwoLandmarkRule::kLeftRight, l0_left, paper_opt),
              s.truth);
    lr_size.add(fix_two_circles(dep[0], dep[1], TwoLandmarkRule::kLeftRight, l0_left, opt),
                s.truth);
    lr_pose.add(fix_two_circles(pos[0], pos[1], TwoLandmarkRule::kLeftRight, l0_left, opt),
                s.truth);
    bd_pose.add(fix_two_circles(pos[0], pos[1], TwoLandmarkRule::kBearingDifference, false, opt),
                s.truth);
    wls_size.add(fix_from_landmarks(dep, opt), s.truth);
    wls_pose.add(fix_from_landmarks(pos, opt), s.truth);
  }
  paper.print("paper: size (paper) + circles + left/right");
  lr_size.print("size (depth) + circles + left/right");
  lr_pose.print("tag pose + circles + left/right");
  bd_pose.print("tag pose + circles + bearing difference");
  wls_size.print("size (depth) + bearing difference + WLS");
  wls_pose.print("tag pose + bearing difference + WLS");
}

void many_landmark_table(const char* title, const std::vector<int>& cameras, std::mt19937_64& rng) {
  print_fix_header(title);
  const FixOptions opt;
  Tally det_size, det_pose, wls_size, wls_pose;
  Scene s;
  for (int trial = 0; trial < 4000; ++trial) {
    if (!make_scene(cameras, rng, &s)) continue;
    const auto dep = observations(s, Method::kSizeDepth), pos = observations(s, Method::kPose);
    det_size.add(fix_trilateration(dep, opt), s.truth);
    det_pose.add(fix_trilateration(pos, opt), s.truth);
    wls_size.add(fix_from_landmarks(dep, opt), s.truth);
    wls_pose.add(fix_from_landmarks(pos, opt), s.truth);
  }
  det_size.print("size (depth) + determinants");
  det_pose.print("tag pose + determinants");
  wls_size.print("size (depth) + determinants + WLS");
  wls_pose.print("tag pose + determinants + WLS");
}

void wrong_map_table(std::mt19937_64& rng) {
  std::printf("\n== One landmark's map entry 0.5 m off (tag pose + WLS) ==\n");
  std::printf("%-28s %8s %9s %16s\n", "landmarks", "trials", "refused", "confident+wrong");
  for (const std::vector<int>& cams :
       {std::vector<int>{0, 1}, std::vector<int>{0, 0, 1}, std::vector<int>{0, 0, 1, 1}}) {
    int trials = 0, refused = 0, wrong = 0;
    Scene s;
    std::uniform_real_distribution<double> uni(0.0, 1.0);
    for (int trial = 0; trial < 2000; ++trial) {
      if (!make_scene(cams, rng, &s)) continue;
      auto pos = observations(s, Method::kPose);
      const double a = 2 * kPi * uni(rng);
      pos[0].landmark_mm = {pos[0].landmark_mm.x + 500.0 * std::cos(a),
                            pos[0].landmark_mm.y + 500.0 * std::sin(a)};
      const FixResult f = fix_from_landmarks(pos, FixOptions{});
      ++trials;
      if (f.status != FixStatus::kOk) {
        ++refused;
        continue;
      }
      const Eigen::Vector3d e(f.pose.x_mm - s.truth.x_mm, f.pose.y_mm - s.truth.y_mm,
                              wrap_angle_rad(f.pose.theta_rad - s.truth.theta_rad));
      wrong += e.dot(f.cov.ldlt().solve(e)) > kNees3Sigma;
    }
    std::printf("%-28zu %8d %8.1f%% %15.1f%%\n", cams.size(), trials, 100.0 * refused / trials,
                100.0 * wrong / trials);
  }
}

}  // namespace

int main() {
  std::mt19937_64 rng(20240613);
  std::printf(
      "eval_ranging: SIMULATED geometry (no rendered images). Camera 1280x800, f = 1000 px, corner "
      "sigma\n"
      "%.1f px, tags %.0f mm at 2-8 m facing the camera within 30 deg; forward camera at (300, 0, "
      "1000) mm,\n"
      "left camera at (0, 250, 1000) mm yaw 90 deg. 3sig cov: share of ok fixes whose pose error "
      "is inside\n"
      "the 3-sigma ellipsoid of the reported covariance (NEES <= 14.16). wrong: ok fixes more than "
      "1 m off.\n",
      kCornerSigmaPx, kTagMm);
  range_table(rng);
  two_landmark_table("Two landmarks, one forward camera", {0, 0}, rng);
  two_landmark_table("Two landmarks, forward and left camera (one each)", {0, 1}, rng);
  many_landmark_table("Three landmarks, one forward camera", {0, 0, 0}, rng);
  many_landmark_table("Three landmarks, two forward + one left", {0, 0, 1}, rng);
  many_landmark_table("Four landmarks, two forward + two left", {0, 0, 1, 1}, rng);
  wrong_map_table(rng);
  return 0;
}
