// Tray-plane fixes (algo/src/overhead/tag_fix.cpp): the camera model against the renderer's
// projection, fixes from the renderer's truth corners and from detected corners on rendered
// frames against the truth poses, the covariance against a Monte-Carlo spread, and bad input.
#include <gtest/gtest.h>

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <random>

#include "agv/overhead/tag_detect.hpp"
#include "agv/overhead/tag_fix.hpp"
#include "agv/site/site_geometry.hpp"
#include "tag_test_scene.hpp"

namespace agv::overhead {
namespace {

constexpr double kTrayMm = 400.0;
constexpr double kTagMm = 160.0;

double angle_err_deg(double a, double b) {
  return std::abs(rad_to_deg(std::remainder(a - b, 2 * kPi)));
}

TEST(TagFixGeometry, SiteToPixelMatchesRendererAndPixelToPlaneInverts) {
  const site::CeilingCamera cam = test::ceiling_camera(50.0);
  const sim::RenderCamera rc = sim::RenderCamera::from_ceiling(cam);
  std::vector<sim::Vec3> pts;
  for (double x = -2000; x <= 2000; x += 500) {
    for (double y = -1000; y <= 1000; y += 500) pts.push_back({x, y, kTrayMm});
  }
  const std::vector<Vec2> want = sim::project_points(rc, pts);
  for (std::size_t i = 0; i < pts.size(); ++i) {
    Vec2 px, back;
    ASSERT_TRUE(site_to_pixel(cam, pts[i].x, pts[i].y, pts[i].z, &px));
    EXPECT_NEAR(px.x, want[i].x, 1e-6);
    EXPECT_NEAR(px.y, want[i].y, 1e-6);
    ASSERT_TRUE(pixel_to_plane(cam, px, kTrayMm, &back));
    EXPECT_NEAR(back.x, pts[i].x, 1e-4);
    EXPECT_NEAR(back.y, pts[i].y, 1e-4);
  }
  Vec2 px;
  EXPECT_FALSE(site_to_pixel(cam, 0, 0, 7000, &px));  // above the camera
  EXPECT_FALSE(site_to_pixel(cam, std::nan(""), 0, 0, &px));
  EXPECT_FALSE(pixel_to_plane(cam, {640, 360}, 7000, &px));  // plane behind the camera
  EXPECT_FALSE(pixel_to_plane(cam, {std::nan(""), 360}, kTrayMm, &px));
}

// Truth corners give the truth pose to numerical precision, at every heading: the page-up
// direction is the vehicle's +x.
TEST(TagFixGeometry, TruthCornersGiveTruthPose) {
  sim::SiteScene s = test::tag_scene(50.0, 8, 1);
  const site::CeilingCamera& cam = s.site.cameras[0];
  // Headings in every quadrant, and the axes themselves.
  const double headings[8] = {0.0, 0.5 * kPi, kPi, -0.5 * kPi, 0.3, -2.5, 2.0, -1.0};
  for (std::size_t i = 0; i < s.agvs.size(); ++i) s.agvs[i].pose.theta_rad = headings[i];
  const sim::RenderResult r =
      sim::render_site_frame(s, sim::RenderCamera::from_ceiling(cam), {}, 1);
  ASSERT_EQ(r.agvs.size(), 8U);
  for (const sim::AgvTruth& t : r.agvs) {
    TagFix fix;
    ASSERT_TRUE(tag_fix_on_plane(cam, t.tag_corners_px, 0.1, kTrayMm, kTagMm, &fix));
    EXPECT_NEAR(fix.pose.x_mm, t.pose.x_mm, 1e-3);
    EXPECT_NEAR(fix.pose.y_mm, t.pose.y_mm, 1e-3);
    EXPECT_LT(angle_err_deg(fix.pose.theta_rad, t.pose.theta_rad), 1e-4) << t.pose.theta_rad;
    EXPECT_NEAR(fix.size_error_rel, 0.0, 1e-6);
    EXPECT_LT(fix.residual_mm, 1e-3);
  }
}

// A tag's corners by the renderer's own projection (no image): page order TL, TR, BR, BL with
// page up along the heading, seen from above.
std::array<Vec2, 4> projected_corners(const site::CeilingCamera& cam, Pose2 p) {
  const double h = 0.5 * kTagMm, c = std::cos(p.theta_rad), s = std::sin(p.theta_rad);
  std::vector<sim::Vec3> pts;
  for (const Vec2 q : {Vec2{h, h}, Vec2{h, -h}, Vec2{-h, -h}, Vec2{-h, h}}) {
    pts.push_back({p.x_mm + c * q.x - s * q.y, p.y_mm + s * q.x + c * q.y, kTrayMm});
  }
  const std::vector<Vec2> px = sim::project_points(sim::RenderCamera::from_ceiling(cam), pts);
  return {px[0], px[1], px[2], px[3]};
}

// Corners as the detector makes them: four lines, each fitted to edge points spread over the
// middle 76 % of its side, with an offset error (variance v0) and an angle error about the span's
// centre (12 v0 / span^2); corner i where lines i - 1 and i meet. Adjacent corners share a line.
struct EdgeLines {
  std::array<Vec2, 4> p{}, d{};
};

EdgeLines lines_of(const std::array<Vec2, 4>& c) {
  EdgeLines l;
  for (std::size_t j = 0; j < 4; ++j) {
    const Vec2 a = c[j], b = c[(j + 1) % 4];
    const double len = std::hypot(b.x - a.x, b.y - a.y);
    l.p[j] = {0.5 * (a.x + b.x), 0.5 * (a.y + b.y)};
    l.d[j] = {(b.x - a.x) / len, (b.y - a.y) / len};
  }
  return l;
}

std::array<Vec2, 4> corners_of(const EdgeLines& l) {
  std::array<Vec2, 4> c{};
  for (std::size_t i = 0; i < 4; ++i) {
    const std::size_t a = (i + 3) % 4;
    const double den = l.d[a].x * l.d[i].y - l.d[a].y * l.d[i].x;
    const double t = ((l.p[i].x - l.p[a].x) * l.d[i].y - (l.p[i].y - l.p[a].y) * l.d[i].x) / den;
    c[i] = {l.p[a].x + t * l.d[a].x, l.p[a].y + t * l.d[a].y};
  }
  return c;
}

// The covariance against the spread of fixes from corners whose edge lines carry the detector's
// errors, with the corner sigma the detector reports for them.
TEST(TagFixGeometry, CovarianceMatchesMonteCarloOfEdgeLines) {
  const site::CeilingCamera cam = test::ceiling_camera(40.0);
  const std::array<Vec2, 4> corners = projected_corners(cam, {1200.0, -700.0, 0.7});
  const double v0 = 0.02;  // px^2
  const EdgeLines truth = lines_of(corners);
  std::array<double, 4> v1{};
  double reported = 0.0;  // the detector's mean over corners of (va + vb) / (2 sin^2)
  for (std::size_t k = 0; k < 4; ++k) {
    const Vec2 a = corners[k], b = corners[(k + 1) % 4];
    const double len = std::hypot(b.x - a.x, b.y - a.y), span = 0.76 * len;
    v1[k] = 12.0 * v0 / (span * span);
  }
  for (std::size_t k = 0; k < 4; ++k) {
    const std::size_t a = (k + 3) % 4;
    const double la = std::hypot(corners[k].x - corners[a].x, corners[k].y - corners[a].y);
    const double lk =
        std::hypot(corners[(k + 1) % 4].x - corners[k].x, corners[(k + 1) % 4].y - corners[k].y);
    const double s = truth.d[a].x * truth.d[k].y - truth.d[a].y * truth.d[k].x;
    reported += 0.25 * 0.5 * (2.0 * v0 + v1[a] * la * la / 4 + v1[k] * lk * lk / 4) / (s * s);
  }
  const double sigma = std::sqrt(reported);
  TagFix fix;
  ASSERT_TRUE(tag_fix_on_plane(cam, corners, sigma, kTrayMm, kTagMm, &fix));
  TagFix half, floor;  // the lines' scatter scales with the sigma, the offset floor does not
  ASSERT_TRUE(tag_fix_on_plane(cam, corners, 0.5 * sigma, kTrayMm, kTagMm, &half));
  ASSERT_TRUE(tag_fix_on_plane(cam, corners, 0.0, kTrayMm, kTagMm, &floor));
  EXPECT_NEAR(half.cov[0] - floor.cov[0], 0.25 * (fix.cov[0] - floor.cov[0]),
              1e-9 + 1e-6 * fix.cov[0]);
  std::mt19937 rng(11);
  std::normal_distribution<double> n(0.0, 1.0);
  const int trials = 2000;
  double sxx = 0, syy = 0, stt = 0;
  for (int i = 0; i < trials; ++i) {
    EdgeLines l = truth;
    for (std::size_t k = 0; k < 4; ++k) {
      const double o = std::sqrt(v0) * n(rng), t = std::sqrt(v1[k]) * n(rng);
      l.p[k] = {l.p[k].x - o * l.d[k].y, l.p[k].y + o * l.d[k].x};
      l.d[k] = {std::cos(t) * l.d[k].x - std::sin(t) * l.d[k].y,
                std::sin(t) * l.d[k].x + std::cos(t) * l.d[k].y};
    }
    TagFix f;
    ASSERT_TRUE(tag_fix_on_plane(cam, corners_of(l), sigma, kTrayMm, kTagMm, &f));
    sxx += std::pow(f.pose.x_mm - fix.pose.x_mm, 2);
    syy += std::pow(f.pose.y_mm - fix.pose.y_mm, 2);
    stt += std::pow(std::remainder(f.pose.theta_rad - fix.pose.theta_rad, 2 * kPi), 2);
  }
  EXPECT_NEAR(std::sqrt(sxx / trials), std::sqrt(fix.cov[0]), 0.08 * std::sqrt(fix.cov[0]));
  EXPECT_NEAR(std::sqrt(syy / trials), std::sqrt(fix.cov[4]), 0.08 * std::sqrt(fix.cov[4]));
  EXPECT_NEAR(std::sqrt(stt / trials), std::sqrt(fix.cov[8]), 0.08 * std::sqrt(fix.cov[8]));
  EXPECT_GT(fix.cov[0] * fix.cov[4] - fix.cov[1] * fix.cov[3], 0.0);
  EXPECT_NEAR(fix.cov[1], fix.cov[3], 1e-12 + 1e-9 * std::abs(fix.cov[1]));
}

// Perfect corners still give a position sigma (the edges' offset floor, about 0.0075 px each,
// half of it in each centre coordinate), and no heading sigma: an offset moves a side, not its
// direction.
TEST(TagFixGeometry, EdgeOffsetFloorGivesPositionNotHeading) {
  const site::CeilingCamera cam = test::ceiling_camera(40.0);
  const std::array<Vec2, 4> corners = projected_corners(cam, {1200.0, -700.0, 0.7});
  TagFix fix;
  ASSERT_TRUE(tag_fix_on_plane(cam, corners, 0.0, kTrayMm, kTagMm, &fix));
  const double mm_per_px = kTagMm / 40.0;
  EXPECT_NEAR(std::sqrt(fix.cov[0]), 0.0075 * mm_per_px / std::sqrt(2.0), 0.2 * 0.0075 * mm_per_px);
  EXPECT_NEAR(std::sqrt(fix.cov[4]), 0.0075 * mm_per_px / std::sqrt(2.0), 0.2 * 0.0075 * mm_per_px);
  EXPECT_LT(std::sqrt(fix.cov[8]), 1e-3 * std::sqrt(fix.cov[0]) / kTagMm);
}

// The fix's NEES (x, y, theta) through a camera believed where it is not; NaN without a fix.
double fix_nees(const site::CeilingCamera& believed, const std::array<Vec2, 4>& corners,
                const Pose2& pose) {
  TagFix f;
  if (!tag_fix_on_plane(believed, corners, 0.0, kTrayMm, kTagMm, &f)) return std::nan("");
  const Eigen::Vector3d e(f.pose.x_mm - pose.x_mm, f.pose.y_mm - pose.y_mm,
                          std::remainder(f.pose.theta_rad - pose.theta_rad, 2 * kPi));
  const Eigen::Matrix3d c =
      Eigen::Map<const Eigen::Matrix<double, 3, 3, Eigen::RowMajor>>(f.cov.data());
  return e.dot(c.ldlt().solve(e));
}

// The camera's calibrated pose sigma in the fix covariance: fixes cast through cameras moved by
// errors drawn from that sigma scatter as the covariance says (NEES of x, y, theta about 3).
TEST(TagFixGeometry, CalibrationSigmaCoversCameraPoseErrors) {
  const site::CeilingCamera truth = test::ceiling_camera(40.0);
  const Pose2 pose{1200.0, -700.0, 0.7};
  const std::array<Vec2, 4> corners = projected_corners(truth, pose);
  TagFix exact;
  ASSERT_TRUE(tag_fix_on_plane(truth, corners, 0.0, kTrayMm, kTagMm, &exact));
  // No pixel noise, an exact camera: the edges' offset floor only (hundredths of a millimetre).
  for (double v : exact.cov_camera) EXPECT_EQ(v, 0.0);
  EXPECT_LT(exact.cov[0], 1e-3);
  site::CeilingCamera stated = truth;
  stated.position_sigma_mm = {3.0, 2.0, 4.0};
  stated.angle_sigma_rad = {4e-4, 6e-4, 3e-4};
  TagFix wide;
  ASSERT_TRUE(tag_fix_on_plane(stated, corners, 0.0, kTrayMm, kTagMm, &wide));
  // 3 mm of camera x alone is 3 mm of fix x; the tilts add (5.6 m range: 0.4 mrad ~ 2.2 mm).
  EXPECT_GT(wide.cov[0], 9.0 + 2.0 * 2.0);
  EXPECT_GT(wide.cov[8], 3e-4 * 3e-4 * 0.9);
  std::mt19937 rng(5);
  std::normal_distribution<double> n(0.0, 1.0);
  const int trials = 400;
  double nees = 0.0;
  for (int t = 0; t < trials; ++t) {
    site::CeilingCamera believed = stated;
    for (std::size_t i = 0; i < 3; ++i) {
      believed.t_site_cam_mm[i] += stated.position_sigma_mm[i] * n(rng);
    }
    double yaw = 0, pitch = 0, roll = 0;
    site::camera_angles_from_rotation(truth.r_site_cam, &yaw, &pitch, &roll);
    believed.r_site_cam = site::camera_rotation_from_angles(
        yaw + stated.angle_sigma_rad[2] * n(rng), pitch + stated.angle_sigma_rad[1] * n(rng),
        roll + stated.angle_sigma_rad[0] * n(rng));
    nees += fix_nees(believed, corners, pose);
  }
  nees /= trials;
  EXPECT_GT(nees, 2.5);
  EXPECT_LT(nees, 3.5);
}

// The calibration's floor residual (pose_sigma.floor_mm) is a bias of every fix on the floor:
// added to the camera part of the covariance in x and y, not to the heading.
TEST(TagFixGeometry, FloorSigmaIsAddedToTheCameraBias) {
  site::CeilingCamera cam = test::ceiling_camera(40.0);
  const std::array<Vec2, 4> corners = projected_corners(cam, {1200.0, -700.0, 0.7});
  TagFix none, floor;
  ASSERT_TRUE(tag_fix_on_plane(cam, corners, 0.1, kTrayMm, kTagMm, &none));
  cam.floor_sigma_mm = 2.0;
  ASSERT_TRUE(tag_fix_on_plane(cam, corners, 0.1, kTrayMm, kTagMm, &floor));
  EXPECT_NEAR(floor.cov_camera[0] - none.cov_camera[0], 4.0, 1e-9);
  EXPECT_NEAR(floor.cov_camera[4] - none.cov_camera[4], 4.0, 1e-9);
  EXPECT_NEAR(floor.cov[0] - none.cov[0], 4.0, 1e-9);
  EXPECT_EQ(floor.cov_camera[8], none.cov_camera[8]);
  EXPECT_EQ(floor.cov_camera[1], none.cov_camera[1]);
}

// A calibration from tags on about one plane leaves a sideways shift and a tilt of the camera
// strongly correlated, and their effects on the plane cancel: with the correlation the fix's
// covariance is the error the correlated pose errors cause (NEES about 2: two error sources),
// without it overstated.
TEST(TagFixGeometry, CorrelatedCalibrationSigmaIsTheFloorError) {
  const site::CeilingCamera truth = test::ceiling_camera(40.0);
  const Pose2 pose{1200.0, -700.0, 0.7};
  const std::array<Vec2, 4> corners = projected_corners(truth, pose);
  const auto trace = [](const TagFix& f) { return f.cov_camera[0] + f.cov_camera[4]; };
  // The tilt (roll or pitch, by the camera's yaw) that moves the fix along x, and the sign of
  // its correlation with x that cancels: about 3 mm each on the plane.
  int angle = -1;
  double rho = 0.0, best = 1e9;
  for (int a : {0, 1}) {
    site::CeilingCamera stated = truth;
    stated.position_sigma_mm = {3.0, 0.0, 0.0};
    stated.angle_sigma_rad[static_cast<std::size_t>(a)] = 5e-4;
    TagFix independent;
    ASSERT_TRUE(tag_fix_on_plane(stated, corners, 0.0, kTrayMm, kTagMm, &independent));
    for (double r : {0.98, -0.98}) {
      stated.pose_correlation[static_cast<std::size_t>(2 + a)] = r;  // (x, roll) or (x, pitch)
      TagFix f;
      ASSERT_TRUE(tag_fix_on_plane(stated, corners, 0.0, kTrayMm, kTagMm, &f));
      const double ratio = trace(f) / trace(independent);
      if (ratio < best) best = ratio, angle = a, rho = r;
    }
  }
  EXPECT_LT(best, 0.3);  // with the correlation ignored, overstated over 3 times
  site::CeilingCamera stated = truth;
  stated.position_sigma_mm = {3.0, 0.0, 0.0};
  stated.angle_sigma_rad[static_cast<std::size_t>(angle)] = 5e-4;
  stated.pose_correlation[static_cast<std::size_t>(2 + angle)] = rho;
  std::mt19937 rng(7);
  std::normal_distribution<double> n(0.0, 1.0);
  double yaw = 0, pitch = 0, roll = 0;
  site::camera_angles_from_rotation(truth.r_site_cam, &yaw, &pitch, &roll);
  const int trials = 400;
  double nees = 0.0;
  for (int t = 0; t < trials; ++t) {
    const double a = n(rng), b = n(rng);
    const double tilt = 5e-4 * (rho * a + std::sqrt(1.0 - rho * rho) * b);
    site::CeilingCamera believed = stated;
    believed.t_site_cam_mm[0] += 3.0 * a;
    believed.r_site_cam = site::camera_rotation_from_angles(yaw, pitch + (angle == 1 ? tilt : 0.0),
                                                            roll + (angle == 0 ? tilt : 0.0));
    nees += fix_nees(believed, corners, pose);
  }
  nees /= trials;
  std::printf(
      "tilt %d, correlation %+.2f: covariance %.2f of the independent one's; NEES %.2f "
      "(2 if honest)\n",
      angle, rho, best, nees);
  EXPECT_GT(nees, 1.5);
  EXPECT_LT(nees, 2.6);
}

// A tag on a tray plane raised by dz and sloped by (gx, gy) about its centre, by the renderer's
// projection.
std::array<Vec2, 4> sloped_corners(const site::CeilingCamera& cam, Pose2 p, double gx, double gy,
                                   double dz) {
  const double h = 0.5 * kTagMm, c = std::cos(p.theta_rad), s = std::sin(p.theta_rad);
  std::vector<sim::Vec3> pts;
  for (const Vec2 q : {Vec2{h, h}, Vec2{h, -h}, Vec2{-h, -h}, Vec2{-h, h}}) {
    const double dx = c * q.x - s * q.y, dy = s * q.x + c * q.y;
    pts.push_back({p.x_mm + dx, p.y_mm + dy, kTrayMm + dz + gx * dx + gy * dy});
  }
  const std::vector<Vec2> px = sim::project_points(sim::RenderCamera::from_ceiling(cam), pts);
  return {px[0], px[1], px[2], px[3]};
}

// A tag on a tray turned by Rz(heading) Ry(pitch) Rx(roll) about its centre (the renderer's
// convention), by the renderer's projection.
std::array<Vec2, 4> tilted_corners(const site::CeilingCamera& cam, Pose2 p, double roll,
                                   double pitch) {
  const double h = 0.5 * kTagMm, c = std::cos(p.theta_rad), s = std::sin(p.theta_rad);
  const double cr = std::cos(roll), sr = std::sin(roll), cp = std::cos(pitch), sp = std::sin(pitch);
  std::vector<sim::Vec3> pts;
  for (const Vec2 q : {Vec2{h, h}, Vec2{h, -h}, Vec2{-h, -h}, Vec2{-h, h}}) {
    // Rx(roll) then Ry(pitch) of (q.x, q.y, 0).
    const double y1 = cr * q.y, z1 = sr * q.y;
    const double x2 = cp * q.x + sp * z1, z2 = -sp * q.x + cp * z1;
    pts.push_back({p.x_mm + c * x2 - s * y1, p.y_mm + s * x2 + c * y1, kTrayMm + z2});
  }
  const std::vector<Vec2> px = sim::project_points(sim::RenderCamera::from_ceiling(cam), pts);
  return {px[0], px[1], px[2], px[3]};
}

// A surveyed tilt is cast out exactly, at every heading; ignored, it turns the fix.
TEST(TagFixGeometry, SurveyedTrayTiltIsCastOut) {
  const site::CeilingCamera cam = test::ceiling_camera(40.0);
  site::FleetAgv agv;
  agv.tray_roll_rad = 1.5 * kPi / 180.0;
  agv.tray_pitch_rad = -1.0 * kPi / 180.0;
  double largest_level_deg = 0.0;
  for (const double heading : {0.0, 0.9, 2.2, -1.4, -2.9}) {
    const Pose2 pose{1900.0, -1100.0, heading};
    const std::array<Vec2, 4> c = tilted_corners(cam, pose, agv.tray_roll_rad, agv.tray_pitch_rad);
    TagFix f, level;
    ASSERT_TRUE(tag_fix_on_tray(cam, c, 0.05, agv, {}, &f));
    EXPECT_NEAR(f.pose.x_mm, pose.x_mm, 1e-3) << heading;
    EXPECT_NEAR(f.pose.y_mm, pose.y_mm, 1e-3) << heading;
    EXPECT_LT(angle_err_deg(f.pose.theta_rad, heading), 1e-4) << heading;
    ASSERT_TRUE(tag_fix_on_plane(cam, c, 0.05, kTrayMm, kTagMm, &level));
    largest_level_deg = std::max(largest_level_deg, angle_err_deg(level.pose.theta_rad, heading));
  }
  EXPECT_GT(largest_level_deg, 0.1);
  site::FleetAgv bad = agv;
  bad.tray_pitch_rad = 2.0;
  TagFix f;
  EXPECT_FALSE(tag_fix_on_tray(cam, tilted_corners(cam, {0, 0, 0}, 0, 0), 0.05, bad, {}, &f));
}

// Trays off level by the stated sigma, seen off the camera's axis: each component's squared error
// over its variance averages about 1; told nothing, the heading's is far above it.
TEST(TagFixGeometry, TraySigmaCoversTiltedAndRaisedTrays) {
  const site::CeilingCamera cam = test::ceiling_camera(40.0);
  const Pose2 pose{2000.0, -1300.0, 0.4};
  const TrayPlaneSigma sigma{1.0 * kPi / 180.0, 3.0};
  std::mt19937 rng(11);
  std::normal_distribution<double> n(0.0, 1.0);
  const int trials = 400;
  std::array<double, 3> ratio{}, ratio_untold{};
  for (int t = 0; t < trials; ++t) {
    const std::array<Vec2, 4> c =
        sloped_corners(cam, pose, std::tan(sigma.tilt_rad) * n(rng),
                       std::tan(sigma.tilt_rad) * n(rng), sigma.height_mm * n(rng));
    TagFix f, untold;
    ASSERT_TRUE(tag_fix_on_tray(cam, c, 0.02, site::FleetAgv{}, sigma, &f));
    ASSERT_TRUE(tag_fix_on_plane(cam, c, 0.02, kTrayMm, kTagMm, &untold));
    const double e[3] = {f.pose.x_mm - pose.x_mm, f.pose.y_mm - pose.y_mm,
                         std::remainder(f.pose.theta_rad - pose.theta_rad, 2 * kPi)};
    for (std::size_t i = 0; i < 3; ++i) {
      ratio[i] += e[i] * e[i] / f.cov[4 * i] / trials;
      ratio_untold[i] += e[i] * e[i] / untold.cov[4 * i] / trials;
      // The tray's part is a bias (the tracker does not average it down).
      EXPECT_GT(f.cov_camera[4 * i], 0.0);
    }
  }
  std::printf(
      "[ measured ] squared error / variance x, y, heading: %.2f %.2f %.2f (told nothing: "
      "%.1f %.1f %.1f)\n",
      ratio[0], ratio[1], ratio[2], ratio_untold[0], ratio_untold[1], ratio_untold[2]);
  for (std::size_t i = 0; i < 3; ++i) {
    EXPECT_GT(ratio[i], 0.75) << i;
    EXPECT_LT(ratio[i], 1.33) << i;
  }
  EXPECT_GT(ratio_untold[2], 10.0);
}

// The renderer tilts the tray's top with its tag: detected corners match the truth corners, the
// tilt turns the fix off the truth heading off the camera's axis, and the stated tray sigma covers
// what it turns.
TEST(TagFixGeometry, RenderedTiltedTraysStayWithinTheirSigma) {
  sim::SiteScene s = test::tag_scene(40.0, 6, 2);
  const site::CeilingCamera& cam = s.site.cameras[0];
  const double tilt = 1.0 * kPi / 180.0;
  // Half of the trays tilted in the site file (surveyed), half beyond it (the vehicle's state).
  std::vector<site::FleetAgv> surveyed = s.site.fleet;
  for (std::size_t i = 0; i < s.agvs.size(); ++i) {
    surveyed[i].tray_roll_rad = tilt * std::cos(1.1 * static_cast<double>(i));
    surveyed[i].tray_pitch_rad = tilt * std::sin(1.1 * static_cast<double>(i));
    if (i % 2 == 0) {
      s.agvs[i].tray_roll_rad = surveyed[i].tray_roll_rad;
      s.agvs[i].tray_pitch_rad = surveyed[i].tray_pitch_rad;
    } else {
      s.site.fleet[i] = surveyed[i];
    }
    s.agvs[i].v_mps = s.agvs[i].omega_radps = 0.0;
  }
  const sim::RenderResult r =
      sim::render_site_frame(s, sim::RenderCamera::from_ceiling(cam), {}, 2);
  const auto obs = TagDetector().detect(r.image, cv::Rect(0, 0, r.image.cols, r.image.rows));
  ASSERT_EQ(obs.size(), s.agvs.size());
  double largest_turn_deg = 0.0;
  for (const TagObservation& o : obs) {
    const sim::AgvTruth* t = nullptr;
    for (const auto& a : r.agvs) t = a.tag_id == o.id ? &a : t;
    ASSERT_NE(t, nullptr);
    TagFix seen, truth;
    ASSERT_TRUE(tag_fix_on_tray(cam, o.corners_px, o.corner_sigma_px, site::FleetAgv{}, {tilt, 0.0},
                                &seen));
    ASSERT_TRUE(tag_fix_on_plane(cam, t->tag_corners_px, 0.0, kTrayMm, kTagMm, &truth));
    EXPECT_LT(angle_err_deg(seen.pose.theta_rad, truth.pose.theta_rad), 0.05);
    EXPECT_LT(std::hypot(seen.pose.x_mm - truth.pose.x_mm, seen.pose.y_mm - truth.pose.y_mm), 0.5);
    const double turn = std::remainder(seen.pose.theta_rad - t->pose.theta_rad, 2 * kPi);
    largest_turn_deg = std::max(largest_turn_deg, std::abs(rad_to_deg(turn)));
    EXPECT_LT(std::abs(turn), 3.0 * std::sqrt(seen.cov[8])) << o.id;
    // Told each tray's tilt, the fix meets the tilted plane: the turn is gone.
    TagFix told;
    ASSERT_TRUE(
        tag_fix_on_tray(cam, o.corners_px, o.corner_sigma_px, surveyed[t->index], {}, &told));
    EXPECT_LT(angle_err_deg(told.pose.theta_rad, t->pose.theta_rad), 0.05) << o.id;
  }
  std::printf("[ measured ] 1 deg tilted trays: largest heading turn %.3f deg\n", largest_turn_deg);
  EXPECT_GT(largest_turn_deg, 0.05);
}

TEST(TagFixGeometry, BadInputRefused) {
  const site::CeilingCamera cam = test::ceiling_camera(50.0);
  const std::array<Vec2, 4> c = projected_corners(cam, {-300.0, 400.0, -2.0});
  TagFix fix;
  ASSERT_TRUE(tag_fix_on_plane(cam, c, 0.1, kTrayMm, kTagMm, &fix));
  // A tag printed at another size (or a wrong tray height) is refused by the size gate.
  EXPECT_FALSE(tag_fix_on_plane(cam, c, 0.1, kTrayMm, 200.0, &fix));
  EXPECT_FALSE(tag_fix_on_plane(cam, c, 0.1, 1500.0, kTagMm, &fix));
  TagFix loose;
  ASSERT_TRUE(tag_fix_on_plane(cam, c, 0.1, 1500.0, kTagMm, &loose, 0.5));
  EXPECT_LT(loose.size_error_rel, -0.15);
  EXPECT_FALSE(tag_fix_on_plane(cam, c, 0.1, 7000.0, kTagMm, &fix, 10.0));
  EXPECT_FALSE(tag_fix_on_plane(cam, c, -1.0, kTrayMm, kTagMm, &fix));
  EXPECT_FALSE(tag_fix_on_plane(cam, c, 0.1, kTrayMm, 0.0, &fix));
  EXPECT_FALSE(tag_fix_on_plane(cam, c, 0.1, kTrayMm, kTagMm, nullptr));
  ASSERT_TRUE(tag_fix_on_tray(cam, c, 0.1, site::FleetAgv{}, {0.01, 1.0}, &fix));
  EXPECT_FALSE(tag_fix_on_tray(cam, c, 0.1, site::FleetAgv{}, {-0.01, 0.0}, &fix));
  EXPECT_FALSE(tag_fix_on_tray(cam, c, 0.1, site::FleetAgv{}, {0.0, std::nan("")}, &fix));
  std::array<Vec2, 4> nan = c;
  nan[1].y = std::nan("");
  EXPECT_FALSE(tag_fix_on_plane(cam, nan, 0.1, kTrayMm, kTagMm, &fix));
  site::CeilingCamera bad = cam;
  bad.intrinsics.fx = 0.0;
  EXPECT_FALSE(tag_fix_on_plane(bad, c, 0.1, kTrayMm, kTagMm, &fix));
  Vec2 px;
  EXPECT_FALSE(site_to_pixel(bad, 0, 0, 0, &px));
  EXPECT_FALSE(pixel_to_plane(bad, {1, 1}, 0, &px));
  // Mirrored corner order (a tag seen from below) does not fit the square.
  const std::array<Vec2, 4> mirrored{c[1], c[0], c[3], c[2]};
  EXPECT_FALSE(tag_fix_on_plane(cam, mirrored, 0.1, kTrayMm, kTagMm, &fix));
}

double p95(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  return v[static_cast<std::size_t>(std::ceil(0.95 * static_cast<double>(v.size()))) - 1];
}

// Detected corners on rendered frames (blur, noise, lens) against the truth poses.
class TagFixRendered : public ::testing::TestWithParam<double> {};

TEST_P(TagFixRendered, DetectedFixesNearTruth) {
  const TagDetector det;
  std::vector<double> pos, head;
  int sigma_ok = 0, n = 0;
  for (std::uint64_t seed = 1; seed <= 2; ++seed) {
    const sim::SiteScene s = test::tag_scene(GetParam(), 6, seed);
    const site::CeilingCamera& cam = s.site.cameras[0];
    const sim::RenderResult r = sim::render_site_frame(s, sim::RenderCamera::from_ceiling(cam),
                                                       sim::realistic_site_params(), seed);
    const auto obs = det.detect(r.image, cv::Rect(0, 0, r.image.cols, r.image.rows));
    for (const TagObservation& o : obs) {
      const sim::AgvTruth* t = nullptr;
      for (const auto& a : r.agvs) {
        if (a.tag_id == o.id) t = &a;
      }
      ASSERT_NE(t, nullptr);
      TagFix fix;
      ASSERT_TRUE(tag_fix_on_plane(cam, o.corners_px, o.corner_sigma_px, kTrayMm, kTagMm, &fix));
      const double e = std::hypot(fix.pose.x_mm - t->pose.x_mm, fix.pose.y_mm - t->pose.y_mm);
      pos.push_back(e);
      head.push_back(angle_err_deg(fix.pose.theta_rad, t->pose.theta_rad));
      // Within 3 sigma of its own covariance (position, the larger axis bound).
      sigma_ok += e <= 3.0 * std::sqrt(fix.cov[0] + fix.cov[4]) ? 1 : 0;
      ++n;
    }
  }
  ASSERT_GE(n, 10);
  std::printf(
      "[ measured ] %.0f px tags, %d fixes: position p95 %.2f mm, heading p95 %.3f deg, "
      "%d within 3 sigma of their covariance\n",
      GetParam(), n, p95(pos), p95(head), sigma_ok);
  EXPECT_LT(p95(pos), 1.0);
  EXPECT_LT(p95(head), 0.2);
  EXPECT_GE(sigma_ok, n * 3 / 4);
}

INSTANTIATE_TEST_SUITE_P(Sides, TagFixRendered, ::testing::Values(40.0, 60.0));

}  // namespace
}  // namespace agv::overhead
