// Simulated frames: the landmark's border lands where the camera model says (to 0.1 px),
// rendering is deterministic for a seed, and the floor texture agrees between frames.
#include <gtest/gtest.h>

#include <cmath>
#include <functional>
#include <string>
#include <vector>

#include "agv/sim/render.hpp"

using namespace agv;
using namespace agv::sim;

namespace {

Scene one_landmark_scene(Pose2 world_pose, double texture_amplitude) {
  LandmarkMap map;
  map.entries[5] = {5, world_pose};
  Scene s;
  std::string err;
  EXPECT_TRUE(make_scene(map, LandmarkGeometry{}, PayloadMode::kFull, &s, &err)) << err;
  s.floor.amplitude = texture_amplitude;
  return s;
}

struct EdgeCheck {
  double max_err_px = 0.0;
  int points = 0;
  std::vector<std::vector<Vec2>> measured;  // per outer edge: measured crossing points (px)
};

// Total-least-squares line through points: returns point on line and unit direction.
void fit_line(const std::vector<Vec2>& pts, Vec2* c, Vec2* d) {
  double mx = 0, my = 0;
  for (const Vec2& p : pts) {
    mx += p.x;
    my += p.y;
  }
  mx /= pts.size();
  my /= pts.size();
  double sxx = 0, sxy = 0, syy = 0;
  for (const Vec2& p : pts) {
    sxx += (p.x - mx) * (p.x - mx);
    sxy += (p.x - mx) * (p.y - my);
    syy += (p.y - my) * (p.y - my);
  }
  const double th = 0.5 * std::atan2(2 * sxy, sxx - syy);
  *c = {mx, my};
  *d = {std::cos(th), std::sin(th)};
}

Vec2 intersect(Vec2 c1, Vec2 d1, Vec2 c2, Vec2 d2) {
  const double det = d1.x * (-d2.y) - d1.y * (-d2.x);
  const double t = ((c2.x - c1.x) * (-d2.y) - (c2.y - c1.y) * (-d2.x)) / det;
  return {c1.x + t * d1.x, c1.y + t * d1.y};
}

// Measures where the outer border edges cross pixel rows (or columns, for edges closer to
// horizontal) from the area between the flat floor grey F and the ink grey B, and compares each
// crossing with the projection of the true edge through `model`.
EdgeCheck check_outer_edges(const cv::Mat& img, const Scene& scene, const CameraModel& model,
                            const Pose2& vehicle_pose) {
  EdgeCheck res;
  const double F = scene.floor.mean, B = scene.ink_black;
  const Pose2 v_from_l = compose(inverse(vehicle_pose), scene.landmarks[0].world_pose);
  const auto corners = scene.geometry.outer_corners_landmark_mm();
  Vec2 centre_px;
  model.vehicle_to_pixel(transform(v_from_l, {0, 0}), &centre_px);
  auto proj = [&](Vec2 p_l) {
    Vec2 px;
    model.vehicle_to_pixel(transform(v_from_l, p_l), &px);
    return px;
  };
  res.measured.resize(4);
  for (int e = 0; e < 4; ++e) {
    const Vec2 a = corners[static_cast<size_t>(e)], b = corners[static_cast<size_t>((e + 1) % 4)];
    const Vec2 pa = proj(a), pb = proj(b);
    const bool rows = std::abs(pb.y - pa.y) > std::abs(pb.x - pa.x);
    // Scan coordinate: rows for steep edges, columns otherwise (by swapping roles).
    const double s0 = rows ? std::min(pa.y, pb.y) : std::min(pa.x, pb.x);
    const double s1 = rows ? std::max(pa.y, pb.y) : std::max(pa.x, pb.x);
    const double margin = 0.15 * (s1 - s0);
    for (int s = static_cast<int>(std::ceil(s0 + margin)); s <= static_cast<int>(s1 - margin);
         ++s) {
      // True crossing: bisection along the edge in landmark coordinates.
      double lo = 0.0, hi = 1.0;
      auto scan_of = [&](double t) {
        const Vec2 p = proj({a.x + t * (b.x - a.x), a.y + t * (b.y - a.y)});
        return rows ? p.y : p.x;
      };
      const bool inc = scan_of(1.0) > scan_of(0.0);
      for (int it = 0; it < 60; ++it) {
        const double mid = 0.5 * (lo + hi);
        if ((scan_of(mid) < s) == inc)
          lo = mid;
        else
          hi = mid;
      }
      const Vec2 tp = proj({a.x + lo * (b.x - a.x), a.y + lo * (b.y - a.y)});
      const double truth = rows ? tp.x : tp.y;
      const bool floor_low = rows ? centre_px.x > truth : centre_px.y > truth;
      const int c = static_cast<int>(std::lround(truth));
      const int lo_i = c - 7, hi_i = c + 7;
      double floor_len = 0.0;
      for (int i = lo_i; i <= hi_i; ++i) {
        const double g = rows ? img.at<std::uint8_t>(s, i) : img.at<std::uint8_t>(i, s);
        floor_len += (g - B) / (F - B);
      }
      const double measured = floor_low ? (lo_i - 0.5) + floor_len : (hi_i + 0.5) - floor_len;
      res.max_err_px = std::max(res.max_err_px, std::abs(measured - truth));
      res.measured[static_cast<size_t>(e)].push_back(rows ? Vec2{measured, static_cast<double>(s)}
                                                          : Vec2{static_cast<double>(s), measured});
      ++res.points;
    }
  }
  return res;
}

}  // namespace

TEST(RenderFrame, BorderEdgesWhereCameraModelSaysNoDistortion) {
  const Scene scene = one_landmark_scene({1000.0, 2000.0, deg_to_rad(20.0)}, 0.0);
  const CameraModel cam = CameraModel::default_640x480();
  const Pose2 vehicle{1008.0, 1995.0, deg_to_rad(-7.0)};
  std::mt19937_64 rng(1);
  const cv::Mat img = render_frame(scene, cam, vehicle, RenderOptions{}, rng);
  ASSERT_EQ(img.type(), CV_8UC1);
  ASSERT_EQ(img.cols, 640);
  ASSERT_EQ(img.rows, 480);
  const EdgeCheck r = check_outer_edges(img, scene, cam, vehicle);
  EXPECT_GT(r.points, 400);
  EXPECT_LT(r.max_err_px, 0.1);
  // Corners: intersections of lines fitted to the measured edge points of adjacent edges,
  // against the camera model's projection of the border corners.
  const Pose2 v_from_l = compose(inverse(vehicle), scene.landmarks[0].world_pose);
  const auto corners = scene.geometry.outer_corners_landmark_mm();
  for (size_t k = 0; k < 4; ++k) {
    // Corner k is shared by edge k-1 (ending at it) and edge k (starting at it).
    Vec2 c1, d1, c2, d2;
    fit_line(r.measured[(k + 3) % 4], &c1, &d1);
    fit_line(r.measured[k], &c2, &d2);
    const Vec2 got = intersect(c1, d1, c2, d2);
    Vec2 want;
    ASSERT_TRUE(cam.vehicle_to_pixel(transform(v_from_l, corners[k]), &want));
    EXPECT_NEAR(got.x, want.x, 0.1) << "corner " << k;
    EXPECT_NEAR(got.y, want.y, 0.1) << "corner " << k;
  }
  // The check is sensitive: a 0.3 px principal point error is detected.
  CameraModel shifted = cam;
  shifted.intrinsics.cx += 0.3;
  EXPECT_GT(check_outer_edges(img, scene, shifted, vehicle).max_err_px, 0.2);
}

TEST(RenderFrame, BorderEdgesWhereCameraModelSaysWithDistortionAndMount) {
  const Scene scene = one_landmark_scene({-500.0, 300.0, deg_to_rad(-135.0)}, 0.0);
  CameraModel cam = CameraModel::default_640x480();
  cam.intrinsics.k1 = -0.25;
  cam.intrinsics.k2 = 0.08;
  cam.intrinsics.p1 = 0.001;
  cam.intrinsics.p2 = -0.0008;
  cam.mount = {40.0, -10.0, deg_to_rad(4.0), 200.0};
  // Landmark off-centre so distortion bends its edges noticeably.
  const Pose2 vehicle{-540.0, 330.0, deg_to_rad(30.0)};
  std::mt19937_64 rng(1);
  const cv::Mat img = render_frame(scene, cam, vehicle, RenderOptions{}, rng);
  const EdgeCheck r = check_outer_edges(img, scene, cam, vehicle);
  EXPECT_GT(r.points, 300);
  EXPECT_LT(r.max_err_px, 0.1);
  // Ignoring the distortion would put edges off by more than the tolerance.
  CameraModel pinhole = cam;
  pinhole.intrinsics.k1 = pinhole.intrinsics.k2 = pinhole.intrinsics.p1 = pinhole.intrinsics.p2 = 0;
  EXPECT_GT(check_outer_edges(img, scene, pinhole, vehicle).max_err_px, 0.5);
}

TEST(RenderFrame, DeterministicForSeedAndTextureStableAcrossFrames) {
  const Scene scene = one_landmark_scene({0.0, 0.0, 0.0}, 30.0);
  const CameraModel cam = CameraModel::default_640x480();
  RenderOptions o = realistic_options();
  o.speed_mps = 0.5;
  std::mt19937_64 r1(42), r2(42), r3(43);
  const cv::Mat a = render_frame(scene, cam, {10, 5, 0.1}, o, r1);
  const cv::Mat b = render_frame(scene, cam, {10, 5, 0.1}, o, r2);
  const cv::Mat c = render_frame(scene, cam, {10, 5, 0.1}, o, r3);
  EXPECT_EQ(cv::norm(a, b, cv::NORM_INF), 0.0);
  EXPECT_GT(cv::norm(a, c, cv::NORM_INF), 0.0);
  // A pure translation by a whole number of pixels along image rows shifts the texture image.
  const Scene floor_only = [] {
    Scene s;
    s.floor.amplitude = 30.0;
    return s;
  }();
  std::mt19937_64 rng(1);
  const double mmpp = cam.mm_per_px();
  const cv::Mat f0 = render_frame(floor_only, cam, {0, 0, 0}, RenderOptions{}, rng);
  const cv::Mat f1 = render_frame(floor_only, cam, {10 * mmpp, 0, 0}, RenderOptions{}, rng);
  // Moving forward 10 px: the floor seen at row y now appears at row y + 10.
  EXPECT_LE(cv::norm(f0(cv::Rect(0, 0, 640, 470)), f1(cv::Rect(0, 10, 640, 470)), cv::NORM_INF),
            1.0);
  cv::Scalar mean, sd;
  cv::meanStdDev(f0, mean, sd);
  EXPECT_GT(sd[0], 5.0);  // textured, not flat
}

TEST(RenderFrame, VisibleLandmarks) {
  const Scene scene = one_landmark_scene({0.0, 0.0, 0.0}, 0.0);
  const FrameRenderer r(scene, CameraModel::default_640x480());
  EXPECT_EQ(r.visible_landmarks({0, 0, 0}).size(), 1u);
  EXPECT_TRUE(r.visible_landmarks({500, 0, 0}).empty());
}
