// The square tag's pose refinement and covariance in closed form (agv/ranging/square_pose.hpp)
// against what measure() used before them: OpenCV's IPPE + solvePnPRefineLM and a Jacobian by
// central differences, on simulated corners (distortion, 0.3 px noise, oblique tags, 1-8 m).
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <opencv2/calib3d.hpp>
#include <random>
#include <vector>

#include "agv/ranging/observe.hpp"
#include "agv/ranging/range_models.hpp"
#include "agv/ranging/square_pose.hpp"

namespace agv::ranging {
namespace {

using Eigen::Matrix3d;
using Eigen::Vector3d;
using Mat6 = Eigen::Matrix<double, 6, 6>;

constexpr double kSideMm = 150.0;

CameraIntrinsics sq_camera() {
  return {.width_px = 1280,
          .height_px = 800,
          .fx = 1002.0,
          .fy = 998.0,
          .cx = 641.5,
          .cy = 398.0,
          .k1 = -0.08,
          .k2 = 0.02,
          .p1 = 0.0005,
          .p2 = -0.0003};
}

struct TruePose {
  Matrix3d R_CT;
  Vector3d t_C_mm;
};

// A tag 1-8 m ahead within the image, turned up to 60 deg about its vertical axis, 20 deg about
// its horizontal one, 10 deg in plane.
TruePose draw_pose(std::mt19937_64& rng) {
  std::uniform_real_distribution<double> U(-1.0, 1.0);
  const double z = 1000.0 + 3500.0 * (U(rng) + 1.0);
  const Matrix3d R = (Eigen::AngleAxisd(0.17 * U(rng), Vector3d::UnitZ()) *
                      Eigen::AngleAxisd(1.05 * U(rng), Vector3d::UnitY()) *
                      Eigen::AngleAxisd(0.35 * U(rng), Vector3d::UnitX()))
                         .toRotationMatrix();
  return {R, Vector3d(0.45 * z * U(rng), 0.28 * z * U(rng), z)};
}

// The corners in IPPE's order, projected with distortion and noise, returned in page order as
// measure() takes them (page corner 3 - i is IPPE corner i).
std::array<Vec2, 4> page_corners(const CameraIntrinsics& k, const TruePose& p, double noise_px,
                                 std::mt19937_64& rng) {
  const double h = kSideMm / 2.0;
  const std::vector<cv::Point3d> obj = {{-h, h, 0}, {h, h, 0}, {h, -h, 0}, {-h, -h, 0}};
  cv::Matx33d R;
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 3; ++c) R(r, c) = p.R_CT(r, c);
  cv::Vec3d rvec;
  cv::Rodrigues(R, rvec);
  const cv::Vec3d tvec(p.t_C_mm.x(), p.t_C_mm.y(), p.t_C_mm.z());
  const cv::Matx33d K(k.fx, 0, k.cx, 0, k.fy, k.cy, 0, 0, 1);
  std::vector<cv::Point2d> img;
  cv::projectPoints(obj, rvec, tvec, K, std::vector<double>{k.k1, k.k2, k.p1, k.p2, k.k3}, img);
  std::normal_distribution<double> n(0.0, noise_px);
  std::array<Vec2, 4> page;
  for (std::size_t i = 0; i < 4; ++i) page[3 - i] = {img[i].x + n(rng), img[i].y + n(rng)};
  return page;
}

struct RefPose {
  Matrix3d R_CT;
  Vector3d t_C_mm;
  double err_px2;
  Matrix3d R0;  // IPPE's start
  Vector3d t0;
};

Matrix3d sq_rotation(const cv::Mat& r) {
  const Vector3d w(r.at<double>(0), r.at<double>(1), r.at<double>(2));
  const double a = w.norm();
  return a > 0.0 ? Eigen::AngleAxisd(a, w / a).toRotationMatrix() : Matrix3d::Identity();
}

// What measure() did before: IPPE's solutions each refined by solvePnPRefineLM (undistorted pixel
// corners in IPPE's order, pinhole K).
std::vector<RefPose> opencv_poses(const CameraIntrinsics& k, const std::array<Vec2, 4>& image) {
  const double h = kSideMm / 2.0;
  const std::vector<cv::Point3d> obj = {{-h, h, 0}, {h, h, 0}, {h, -h, 0}, {-h, -h, 0}};
  std::vector<cv::Point2d> img;
  for (const Vec2& c : image) img.emplace_back(c.x, c.y);
  const cv::Matx33d K(k.fx, 0, k.cx, 0, k.fy, k.cy, 0, 0, 1);
  std::vector<cv::Mat> rvecs, tvecs;
  const int n =
      cv::solvePnPGeneric(obj, img, K, cv::Mat(), rvecs, tvecs, false, cv::SOLVEPNP_IPPE_SQUARE);
  std::vector<RefPose> out;
  for (std::size_t s = 0; s < static_cast<std::size_t>(n); ++s) {
    RefPose p;
    p.R0 = sq_rotation(rvecs[s]);
    p.t0 = Vector3d(tvecs[s].at<double>(0), tvecs[s].at<double>(1), tvecs[s].at<double>(2));
    cv::solvePnPRefineLM(obj, img, K, cv::Mat(), rvecs[s], tvecs[s]);
    p.R_CT = sq_rotation(rvecs[s]);
    p.t_C_mm = Vector3d(tvecs[s].at<double>(0), tvecs[s].at<double>(1), tvecs[s].at<double>(2));
    std::vector<cv::Point2d> re;
    cv::projectPoints(obj, rvecs[s], tvecs[s], K, cv::Mat(), re);
    p.err_px2 = 0.0;
    for (std::size_t i = 0; i < 4; ++i) p.err_px2 += std::pow(cv::norm(re[i] - img[i]), 2);
    out.push_back(p);
  }
  return out;
}

// The covariance as measure() computed it before: the Jacobian by central differences.
Mat6 central_difference_covariance(double f, const Vector3d& t, const Matrix3d& R, double sigma) {
  using Vec6 = Eigen::Matrix<double, 6, 1>;
  const double h = kSideMm / 2;
  const double corners[4][2] = {{-h, h}, {h, h}, {h, -h}, {-h, -h}};
  auto project = [&](const Vec6& d) {
    SquareCorners8 uv;
    const double a = d.head<3>().norm();
    const Matrix3d dR =
        a > 0.0 ? Eigen::AngleAxisd(a, d.head<3>() / a).toRotationMatrix() : Matrix3d::Identity();
    for (int i = 0; i < 4; ++i) {
      const Vector3d X = dR * R * Vector3d(corners[i][0], corners[i][1], 0.0) + t + d.tail<3>();
      uv[2 * i] = f * X.x() / X.z();
      uv[2 * i + 1] = f * X.y() / X.z();
    }
    return uv;
  };
  SquareJacobian J;
  for (int k = 0; k < 6; ++k) {
    Vec6 d = Vec6::Zero();
    d[k] = k < 3 ? 1e-6 : 1e-3;
    J.col(k) = (project(d) - project(-d)) / (2.0 * d[k]);
  }
  return sigma * sigma * (J.transpose() * J).inverse();
}

double rotation_angle(const Matrix3d& a, const Matrix3d& b) {
  return Eigen::AngleAxisd(a.transpose() * b).angle();
}

// Each entry within `rel` of the diagonal scale: |a - b|_ij <= rel sqrt(b_ii b_jj).
double covariance_difference(const Mat6& a, const Mat6& b) {
  double worst = 0.0;
  for (int i = 0; i < 6; ++i)
    for (int j = 0; j < 6; ++j)
      worst = std::max(worst, std::abs(a(i, j) - b(i, j)) / std::sqrt(b(i, i) * b(j, j)));
  return worst;
}

TEST(RangingSquarePose, ClosedFormJacobianMatchesCentralDifferences) {
  std::mt19937_64 rng(11);
  double worst = 0.0;
  for (int trial = 0; trial < 500; ++trial) {
    const TruePose p = draw_pose(rng);
    const Mat6 a = tag_pose_covariance(1000.0, kSideMm, p.t_C_mm, p.R_CT, 0.3);
    const Mat6 b = central_difference_covariance(1000.0, p.t_C_mm, p.R_CT, 0.3);
    worst = std::max(worst, covariance_difference(a, b));
  }
  EXPECT_LT(worst, 1e-5);
  std::printf("closed-form vs central-difference covariance: worst entry %.3g of its scale\n",
              worst);
}

// Both minimise the same error from the same start. OpenCV's LM stops after 20 iterations or a
// relative step of FLT_EPSILON; in the flat valley of IPPE's second (mirrored) solution it can stop
// short of the minimum, which the refinement here reaches (about 1 solution in 800 below, error
// 0.2 % lower). Elsewhere the two agree far within the pose's own uncertainty: in that valley the
// error changes by less than 1e-6 over hundredths of a millimetre, and where each stops there
// depends on rounding (an ASan build differs from the default one).
TEST(RangingSquarePose, RefinementMatchesOpenCvLevenbergMarquardt) {
  const CameraIntrinsics k = sq_camera();
  CameraIntrinsics pin = k;
  pin.k1 = pin.k2 = pin.p1 = pin.p2 = 0.0;
  std::mt19937_64 rng(3);
  double worst_t_mm = 0.0, worst_r_rad = 0.0, worst_t_sd = 0.0, worst_r_sd = 0.0;
  int compared = 0, lower = 0;
  for (int trial = 0; trial < 400; ++trial) {
    const TruePose p = draw_pose(rng);
    const std::array<Vec2, 4> page = page_corners(pin, p, 0.3, rng);
    const std::array<Vec2, 4> image = {page[3], page[2], page[1], page[0]};
    for (const RefPose& ref : opencv_poses(k, image)) {
      const SquarePose s =
          refine_square_pose(k.fx, k.fy, k.cx, k.cy, kSideMm, image, ref.R0, ref.t0);
      ASSERT_TRUE(s.ok);
      EXPECT_LE(s.squared_error_px2, ref.err_px2 * (1.0 + 1e-9) + 1e-18);
      ++compared;
      if (s.squared_error_px2 < ref.err_px2 * (1.0 - 1e-6)) {
        ++lower;
        continue;
      }
      const Mat6 cov = tag_pose_covariance(k.fx, kSideMm, ref.t_C_mm, ref.R_CT, 0.3);
      const double dt_mm = (s.t_C_mm - ref.t_C_mm).norm();
      const double dr_rad = rotation_angle(s.R_CT, ref.R_CT);
      worst_t_mm = std::max(worst_t_mm, dt_mm);
      worst_r_rad = std::max(worst_r_rad, dr_rad);
      worst_t_sd = std::max(worst_t_sd, dt_mm / std::sqrt(cov.bottomRightCorner<3, 3>().trace()));
      worst_r_sd = std::max(worst_r_sd, dr_rad / std::sqrt(cov.topLeftCorner<3, 3>().trace()));
    }
  }
  std::printf(
      "refinement vs OpenCV LM on %d solutions: %d with a lower error; the others t %.3g mm "
      "(%.3g sd), R %.3g rad (%.3g sd)\n",
      compared, lower, worst_t_mm, worst_t_sd, worst_r_rad, worst_r_sd);
  EXPECT_GT(compared, 400);
  EXPECT_LE(lower, compared / 100);
  EXPECT_LT(worst_t_sd, 0.01);
  EXPECT_LT(worst_r_sd, 0.01);
}

TEST(RangingSquarePose, MeasureMatchesTheOpenCvPipeline) {
  const CameraIntrinsics k = sq_camera();
  const std::vector<site::WallLandmark> table = {{.id = 5, .x_mm = 4000.0, .size_mm = kSideMm}};
  const LandmarkObserver obs(k, RangingMount{.z_mm = 1000.0}, table);
  std::mt19937_64 rng(17);
  double worst_t_mm = 0.0, worst_r_rad = 0.0, worst_cov = 0.0;
  int measured = 0, yaw_unresolved = 0;
  for (int trial = 0; trial < 300; ++trial) {
    const TruePose p = draw_pose(rng);
    const std::array<Vec2, 4> page = page_corners(k, p, 0.3, rng);
    LandmarkObservation o;
    RefusalReason why{};
    if (!obs.measure(5, page, 0.3, &o, &why)) continue;
    const auto& u = o.corners_undistorted_px;
    const std::vector<RefPose> ref = opencv_poses(k, {u[3], u[2], u[1], u[0]});
    ASSERT_FALSE(ref.empty());
    const auto best = std::min_element(
        ref.begin(), ref.end(), [](const auto& a, const auto& b) { return a.err_px2 < b.err_px2; });
    worst_t_mm = std::max(worst_t_mm, (o.t_C_mm - best->t_C_mm).norm());
    worst_r_rad = std::max(worst_r_rad, rotation_angle(o.R_CT, best->R_CT));
    EXPECT_NEAR(o.reprojection_rms_px, std::sqrt(best->err_px2 / 8.0), 1e-6);
    // The turn left unresolved when the other solution is nearly as good: the same decision.
    const double floor_err = 8.0 * o.corner_sigma_px * o.corner_sigma_px;
    bool ambiguous = false;
    for (const RefPose& r : ref) {
      ambiguous = ambiguous || (&r != &*best && r.err_px2 < ObserveOptions{}.yaw_ambiguity_ratio *
                                                                std::max(best->err_px2, floor_err));
    }
    EXPECT_EQ(o.pose.has_yaw, !ambiguous) << trial;
    yaw_unresolved += ambiguous ? 1 : 0;
    const Mat6 old_cov = central_difference_covariance(std::sqrt(k.fx * k.fy), best->t_C_mm,
                                                       best->R_CT, o.corner_sigma_px);
    worst_cov = std::max(worst_cov, covariance_difference(o.cov6, old_cov));
    ++measured;
  }
  EXPECT_GT(measured, 250);
  std::printf(
      "measure() vs OpenCV pipeline on %d tags (%d with the turn unresolved): t %.3g mm, "
      "R %.3g rad, cov6 %.3g\n",
      measured, yaw_unresolved, worst_t_mm, worst_r_rad, worst_cov);
  EXPECT_LT(worst_t_mm, 1e-3);
  EXPECT_LT(worst_r_rad, 1e-6);
  EXPECT_LT(worst_cov, 1e-4);
}

TEST(RangingSquarePose, FarStartConvergesAndNeverGetsWorse) {
  const CameraIntrinsics k = sq_camera();
  const TruePose p{Eigen::AngleAxisd(0.4, Vector3d::UnitY()).toRotationMatrix(),
                   Vector3d(300.0, -200.0, 3000.0)};
  std::mt19937_64 rng(1);
  CameraIntrinsics pin = k;
  pin.k1 = pin.k2 = pin.p1 = pin.p2 = 0.0;
  const std::array<Vec2, 4> page = page_corners(pin, p, 0.0, rng);
  const std::array<Vec2, 4> image = {page[3], page[2], page[1], page[0]};
  const Matrix3d R0 = Eigen::AngleAxisd(0.1, Vector3d(1, 2, 3).normalized()) * p.R_CT;
  const SquarePose s = refine_square_pose(k.fx, k.fy, k.cx, k.cy, kSideMm, image, R0,
                                          p.t_C_mm + Vector3d(60.0, -40.0, 300.0));
  ASSERT_TRUE(s.ok);
  EXPECT_LT(s.squared_error_px2, 1e-12);
  EXPECT_LT((s.t_C_mm - p.t_C_mm).norm(), 1e-6);
  EXPECT_LT(rotation_angle(s.R_CT, p.R_CT), 1e-9);
}

TEST(RangingSquarePose, StartBehindTheCameraIsRefused) {
  const std::array<Vec2, 4> image = {{{600, 420}, {680, 420}, {680, 380}, {600, 380}}};
  const SquarePose s = refine_square_pose(1000.0, 1000.0, 640.0, 400.0, kSideMm, image,
                                          Matrix3d::Identity(), Vector3d(0.0, 0.0, -2000.0));
  EXPECT_FALSE(s.ok);
  const SquarePose nan =
      refine_square_pose(1000.0, 1000.0, 640.0, 400.0, kSideMm, image, Matrix3d::Identity(),
                         Vector3d(0.0, std::nan(""), 2000.0));
  EXPECT_FALSE(nan.ok);
}

}  // namespace
}  // namespace agv::ranging
