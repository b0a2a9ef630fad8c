// Site renderer (algo/src/sim/site_render_*.cpp): projection against OpenCV, the rendered image
// against the projection, occlusion (parcels over tags, racks over wall landmarks), decoding of
// a rendered tray tag by libapriltag, motion blur and determinism.
#include <apriltag/apriltag.h>
#include <apriltag/tag36h11.h>
#include <gtest/gtest.h>

#include <cmath>
#include <opencv2/calib3d.hpp>
#include <vector>

#include "agv/sim/site_render.hpp"

namespace agv::sim {
namespace {

CameraIntrinsics test_intrinsics(int w = 640, int h = 360, double f = 700.0) {
  CameraIntrinsics k;
  k.width_px = w;
  k.height_px = h;
  k.fx = f;
  k.fy = f * 1.01;
  k.cx = 0.5 * (w - 1) + 3.0;
  k.cy = 0.5 * (h - 1) - 2.0;
  k.k1 = -0.12;
  k.k2 = 0.03;
  k.p1 = 0.0008;
  k.p2 = -0.0006;
  k.k3 = -0.004;
  return k;
}

// A ceiling camera 6 m up, tilted a little, seen as a "vehicle" camera at the site origin.
RenderCamera ceiling_camera(const CameraIntrinsics& k, double tilt_rad = 0.1) {
  VehicleCameraMount m;
  m.z_mm = 6000.0;
  m.yaw_rad = 0.3;
  m.pitch_rad = kPi / 2 - tilt_rad;
  return RenderCamera::on_vehicle(k, {0.0, 0.0, 0.0}, m);
}

site::FleetAgv fleet_agv(const std::string& id, std::uint32_t tag) {
  site::FleetAgv a;
  a.id = id;
  a.tag_id = tag;
  return a;
}

SiteScene one_agv_scene(Pose2 pose) {
  SiteScene s;
  s.site.outline.vertices_mm = {{-10000, -10000}, {10000, -10000}, {10000, 10000}, {-10000, 10000}};
  s.site.fleet.push_back(fleet_agv("agv1", 7));
  s.agvs.push_back({pose, 0.0, 0.0});
  s.floor.amplitude = 0.0;  // a flat floor: exact grey values in the tests
  return s;
}

SiteRenderParams clean_params() { return SiteRenderParams{}; }

std::vector<Vec2> opencv_project(const RenderCamera& cam, const std::vector<Vec3>& pts) {
  const auto& r = cam.r_site_cam;
  // OpenCV wants camera <- site: R^T and -R^T t.
  cv::Matx33d rc(r[0], r[3], r[6], r[1], r[4], r[7], r[2], r[5], r[8]);
  cv::Vec3d t(cam.t_site_cam_mm[0], cam.t_site_cam_mm[1], cam.t_site_cam_mm[2]);
  cv::Vec3d tc = -(rc * t);
  cv::Vec3d rvec;
  cv::Rodrigues(rc, rvec);
  const CameraIntrinsics& k = cam.intrinsics;
  cv::Matx33d km(k.fx, 0, k.cx, 0, k.fy, k.cy, 0, 0, 1);
  std::vector<double> dist{k.k1, k.k2, k.p1, k.p2, k.k3};
  std::vector<cv::Point3d> in;
  for (const Vec3& p : pts) in.emplace_back(p.x, p.y, p.z);
  std::vector<cv::Point2d> out;
  cv::projectPoints(in, rvec, tc, km, dist, out);
  std::vector<Vec2> res;
  for (const auto& p : out) res.push_back({p.x, p.y});
  return res;
}

int grey_at(const cv::Mat& img, Vec2 px) {
  return img.at<std::uint8_t>(static_cast<int>(std::lround(px.y)),
                              static_cast<int>(std::lround(px.x)));
}

// A tray-page point of vehicle `pose` (page u right = vehicle -y, v down = vehicle -x).
Vec3 tray_page_point(const Pose2& pose, double tray_h, double u, double v) {
  const Vec2 p = transform(pose, {-v, -u});
  return {p.x, p.y, tray_h};
}

TEST(SiteRender, ProjectionMatchesOpenCv) {
  const CameraIntrinsics k = test_intrinsics();
  const RenderCamera cam = ceiling_camera(k);
  SiteScene s = one_agv_scene({400.0, -300.0, 0.7});
  s.site.fleet.push_back(fleet_agv("agv2", 8));
  s.agvs.push_back({{-900.0, 500.0, -2.0}, 0.0, 0.0});
  s.site.wall_landmarks.push_back({3, site::LandmarkFamily::kTag36h11, 1500, 200, 1200, 2.5, 150});
  s.parcels.push_back({1, 0.0, 150.0, 0.2, 200.0, 180.0, 250.0, 120.0});
  s.clutter.push_back({ClutterKind::kPallet, -200.0, -1200.0, 0.4, 1200, 800, 150, 150});
  const RenderResult r = render_site_frame(s, cam, clean_params(), 1);
  ASSERT_EQ(r.agvs.size(), 2u);
  std::vector<Vec3> pts;
  std::vector<Vec2> ours;
  for (size_t i = 0; i < r.agvs.size(); ++i) {
    const AgvTruth& t = r.agvs[i];
    ASSERT_TRUE(t.projected);
    const double h = 80.0, tl = 300.0, tw = 200.0, th = 400.0;
    const double tag_uv[4][2] = {{-h, -h}, {h, -h}, {h, h}, {-h, h}};
    const double tray_uv[4][2] = {{-tw, -tl}, {tw, -tl}, {tw, tl}, {-tw, tl}};
    for (int c = 0; c < 4; ++c) {
      pts.push_back(tray_page_point(s.agvs[i].pose, th, tag_uv[c][0], tag_uv[c][1]));
      ours.push_back(t.tag_corners_px[static_cast<size_t>(c)]);
      pts.push_back(tray_page_point(s.agvs[i].pose, th, tray_uv[c][0], tray_uv[c][1]));
      ours.push_back(t.tray_corners_px[static_cast<size_t>(c)]);
    }
  }
  ASSERT_EQ(r.wall_landmarks.size(), 1u);
  const double c = std::cos(2.5), sn = std::sin(2.5);
  for (int q = 0; q < 4; ++q) {
    const double u = q == 0 || q == 3 ? -75.0 : 75.0, v = q < 2 ? -75.0 : 75.0;
    // Page right (-sin, cos, 0), page down -z, 1 mm proud of the face.
    pts.push_back({1500 + c - sn * u, 200 + sn + c * u, 1200 - v});
    ours.push_back(r.wall_landmarks[0].corners_px[static_cast<size_t>(q)]);
  }
  for (const BoxTruth& b : r.parcels) {
    ASSERT_TRUE(b.projected);
    pts.push_back(b.centre_site);
    ours.push_back(b.centre_px);
  }
  for (const BoxTruth& b : r.clutter) {
    ASSERT_TRUE(b.projected);
    pts.push_back(b.centre_site);
    ours.push_back(b.centre_px);
    EXPECT_NEAR(b.centre_site.x, -200.0, 1e-6);
    EXPECT_NEAR(b.centre_site.z, 150.0, 1e-9);
  }
  const std::vector<Vec2> ref = opencv_project(cam, pts);
  const std::vector<Vec2> direct = project_points(cam, pts);
  for (size_t i = 0; i < pts.size(); ++i) {
    EXPECT_NEAR(ours[i].x, ref[i].x, 0.01) << i;
    EXPECT_NEAR(ours[i].y, ref[i].y, 0.01) << i;
    EXPECT_NEAR(direct[i].x, ref[i].x, 0.01) << i;
    EXPECT_NEAR(direct[i].y, ref[i].y, 0.01) << i;
  }
}

TEST(SiteRender, PointsBehindTheCameraAreRefused) {
  const RenderCamera cam = ceiling_camera(test_intrinsics());
  std::vector<std::uint8_t> ok;
  const std::vector<Vec2> px = project_points(cam, {{0, 0, 7000}, {0, 0, 0}}, &ok);
  EXPECT_EQ(ok[0], 0);
  EXPECT_TRUE(std::isnan(px[0].x));
  EXPECT_EQ(ok[1], 1);
}

// The image agrees with the projection: the tag's black border and its white margin are where
// the (distorted) projection puts them, in a corner of the image where distortion is strong.
TEST(SiteRender, ImageMatchesProjection) {
  const CameraIntrinsics k = test_intrinsics();
  const RenderCamera cam = ceiling_camera(k, 0.0);
  // Near the top-left image corner, where the lens bends lines most.
  const Pose2 pose{286.0, 1948.0, 0.4};
  SiteScene s = one_agv_scene(pose);
  const RenderResult r = render_site_frame(s, cam, clean_params(), 1);
  ASSERT_TRUE(r.agvs[0].projected);
  const double h = 80.0, module = 20.0, margin = 40.0;
  const double shade = 1.0;
  int checked = 0;
  for (int side = 0; side < 4; ++side) {
    const double sx = side == 0 ? -1 : side == 1 ? 1 : 0, sy = side == 2 ? -1 : side == 3 ? 1 : 0;
    const Vec3 black =
        tray_page_point(pose, 400.0, sx * (h - 0.5 * module), sy * (h - 0.5 * module));
    const Vec3 white =
        tray_page_point(pose, 400.0, sx * (h + 0.5 * margin), sy * (h + 0.5 * margin));
    const std::vector<Vec2> px = project_points(cam, {black, white});
    if (px[0].x < 2 || px[0].y < 2 || px[0].x > k.width_px - 3 || px[0].y > k.height_px - 3) {
      continue;
    }
    EXPECT_NEAR(grey_at(r.image, px[0]), s.ink_black * shade, 1.0) << side;
    EXPECT_NEAR(grey_at(r.image, px[1]), s.paper_white * shade, 1.0) << side;
    ++checked;
  }
  EXPECT_EQ(checked, 4);
  EXPECT_NEAR(r.agvs[0].tag_visible_fraction, 1.0, 1e-12);
}

TEST(SiteRender, ParcelHidesTheTag) {
  const CameraIntrinsics k = test_intrinsics();
  const RenderCamera cam = ceiling_camera(k, 0.0);
  const Pose2 pose{300.0, 200.0, 0.2};
  SiteScene s = one_agv_scene(pose);
  // Covers the whole tray.
  s.parcels.push_back({0, 0.0, 0.0, 0.0, 700.0, 500.0, 300.0, 163.0});
  const RenderResult r = render_site_frame(s, cam, clean_params(), 1);
  EXPECT_EQ(r.agvs[0].tag_visible_fraction, 0.0);
  const std::vector<Vec2> centre = project_points(cam, {{pose.x_mm, pose.y_mm, 700.0}});
  EXPECT_EQ(grey_at(r.image, centre[0]), 163);
  // The tag's corners (under the parcel) show the parcel too.
  for (const Vec2& c : r.agvs[0].tag_corners_px) EXPECT_EQ(grey_at(r.image, c), 163);

  // Half the tag covered: about half visible.
  s.parcels[0] = {0, 160.0, 0.0, 0.0, 320.0, 500.0, 100.0, 163.0};
  const RenderResult half = render_site_frame(s, cam, clean_params(), 1);
  EXPECT_GT(half.agvs[0].tag_visible_fraction, 0.35);
  EXPECT_LT(half.agvs[0].tag_visible_fraction, 0.65);
}

// A vehicle camera looking along a row at a landmark on a rack: visible, then hidden by a rack
// placed in between.
TEST(SiteRender, RackHidesWallLandmark) {
  CameraIntrinsics k = test_intrinsics(320, 240, 300.0);
  SiteScene s = one_agv_scene({-5000.0, -5000.0, 0.0});  // the fleet vehicle out of the way
  site::Obstacle rack;
  rack.id = "r1";
  rack.outline.vertices_mm = {{3000, -500}, {3800, -500}, {3800, 500}, {3000, 500}};
  rack.height_mm = 2500.0;
  s.site.obstacles.push_back(rack);
  // On the rack's -x face, facing the vehicle.
  s.site.wall_landmarks.push_back({11, site::LandmarkFamily::kTag36h11, 3000, 0, 1000, kPi, 200});
  VehicleCameraMount m;
  m.z_mm = 1000.0;
  const RenderCamera cam = RenderCamera::on_vehicle(k, {0.0, 0.0, 0.0}, m);
  const RenderResult seen = render_site_frame(s, cam, clean_params(), 1);
  ASSERT_TRUE(seen.wall_landmarks[0].projected);
  EXPECT_NEAR(seen.wall_landmarks[0].visible_fraction, 1.0, 1e-12);
  // The landmark is in front of the camera, centred: its border is dark.
  const Vec2 c0 = seen.wall_landmarks[0].corners_px[0];
  const Vec2 c2 = seen.wall_landmarks[0].corners_px[2];
  EXPECT_NEAR(0.5 * (c0.x + c2.x), k.cx, 2.0);
  const Vec2 border{0.9 * c0.x + 0.1 * c2.x, 0.5 * (c0.y + c2.y)};
  EXPECT_LT(grey_at(seen.image, border), 40);

  site::Obstacle block = rack;
  block.id = "r2";
  block.outline.vertices_mm = {{1500, -400}, {1700, -400}, {1700, 400}, {1500, 400}};
  s.site.obstacles.push_back(block);
  const RenderResult hidden = render_site_frame(s, cam, clean_params(), 1);
  EXPECT_EQ(hidden.wall_landmarks[0].visible_fraction, 0.0);
  EXPECT_GT(grey_at(hidden.image, border), 60);  // the nearer rack's face

  // Seen from behind (the camera behind the rack's print side), the print is not visible.
  s.site.obstacles.pop_back();
  s.site.obstacles.clear();
  const RenderCamera behind = RenderCamera::on_vehicle(k, {6000.0, 0.0, kPi}, m);
  const RenderResult back = render_site_frame(s, behind, clean_params(), 1);
  EXPECT_EQ(back.wall_landmarks[0].visible_fraction, 0.0);
}

TEST(SiteRender, TrayTagDecodesAtSixMetres) {
  // 640x360 with a narrow lens: the 160 mm tag spans about 30 px, a module about 4 px.
  const CameraIntrinsics k = test_intrinsics(640, 360, 1100.0);
  const RenderCamera cam = ceiling_camera(k, 0.05);
  SiteScene s = one_agv_scene({200.0, 150.0, 0.6});
  s.site.fleet[0].tag_id = 123;
  s.floor.amplitude = 40.0;
  SiteRenderParams p = realistic_site_params();
  const RenderResult r = render_site_frame(s, cam, p, 5);
  apriltag_family_t* fam = tag36h11_create();
  apriltag_detector_t* det = apriltag_detector_create();
  apriltag_detector_add_family(det, fam);
  det->quad_decimate = 1.0f;
  det->nthreads = 1;
  cv::Mat img = r.image.clone();
  image_u8_t view{img.cols, img.rows, static_cast<std::int32_t>(img.step), img.data};
  zarray_t* dets = apriltag_detector_detect(det, &view);
  bool found = false;
  for (int i = 0; i < zarray_size(dets); ++i) {
    apriltag_detection_t* d = nullptr;
    zarray_get(dets, i, &d);
    if (d->id != 123) continue;
    found = true;
    // Its centre lies within a pixel of the truth's corner mean.
    Vec2 m{0, 0};
    for (const Vec2& c : r.agvs[0].tag_corners_px) m = {m.x + 0.25 * c.x, m.y + 0.25 * c.y};
    EXPECT_NEAR(d->c[0], m.x, 1.0);
    EXPECT_NEAR(d->c[1], m.y, 1.0);
  }
  apriltag_detections_destroy(dets);
  apriltag_detector_destroy(det);
  tag36h11_destroy(fam);
  EXPECT_TRUE(found);
}

TEST(SiteRender, MotionBlurOnlyOnMovingVehicles) {
  const CameraIntrinsics k = test_intrinsics(320, 240, 350.0);
  const RenderCamera cam = ceiling_camera(k, 0.0);
  SiteScene s = one_agv_scene({0.0, 0.0, 0.0});
  s.floor.amplitude = 40.0;
  s.agvs[0].v_mps = 2.0;
  SiteRenderParams p;
  const RenderResult sharp = render_site_frame(s, cam, p, 1);
  p.exposure_s = 0.02;  // 40 mm of travel, several pixels
  const RenderResult blurred = render_site_frame(s, cam, p, 1);
  cv::Mat diff;
  cv::absdiff(sharp.image, blurred.image, diff);
  // Changes only near the vehicle; the floor elsewhere is untouched.
  const cv::Rect far(0, 0, 40, 40);
  EXPECT_EQ(cv::countNonZero(diff(far)), 0);
  EXPECT_GT(cv::countNonZero(diff), 50);
  // A stopped vehicle renders the same with or without an exposure.
  s.agvs[0].v_mps = 0.0;
  const RenderResult still = render_site_frame(s, cam, p, 1);
  EXPECT_EQ(cv::countNonZero(still.image != sharp.image), 0);
}

TEST(SiteRender, DeterministicPerSeed) {
  const CameraIntrinsics k = test_intrinsics(320, 240, 350.0);
  const RenderCamera cam = ceiling_camera(k);
  SiteScene s = one_agv_scene({100.0, 0.0, 1.0});
  s.site.fleet.push_back(fleet_agv("agv2", 9));
  s.agvs.push_back({{-800.0, 300.0, 0.0}, 1.0, 0.3});
  add_random_parcels(&s, 1.0, 4);
  add_random_clutter(&s, 2, 1, 4);
  const SiteRenderParams p = realistic_site_params();
  const SiteFrameRenderer renderer(k);
  const cv::Mat a = renderer.render(s, cam, p, 9).image;
  const cv::Mat b = renderer.render(s, cam, p, 9).image;
  const cv::Mat c = renderer.render(s, cam, p, 10).image;
  ASSERT_FALSE(a.empty());
  EXPECT_EQ(cv::countNonZero(a != b), 0);
  EXPECT_GT(cv::countNonZero(a != c), 0);
  SiteScene s2 = s;
  add_random_parcels(&s2, 1.0, 4);
  add_random_clutter(&s2, 2, 1, 4);
  ASSERT_EQ(s2.parcels.size(), s.parcels.size());
  for (size_t i = 0; i < s.parcels.size(); ++i) EXPECT_EQ(s2.parcels[i].grey, s.parcels[i].grey);
  EXPECT_EQ(s.clutter.size(), 3u);
}

TEST(SiteRender, RandomPlacementsAreFree) {
  site::Site site;
  site.outline.vertices_mm = {{0, 0}, {10000, 0}, {10000, 8000}, {0, 8000}};
  site::Obstacle o;
  o.outline.vertices_mm = {{3000, 0}, {4000, 0}, {4000, 6000}, {3000, 6000}};
  site.obstacles.push_back(o);
  const std::vector<Pose2> poses = random_free_poses(site, 8, 400.0, 3);
  ASSERT_EQ(poses.size(), 8u);
  for (size_t i = 0; i < poses.size(); ++i) {
    const Pose2& p = poses[i];
    EXPECT_TRUE(p.x_mm > 500 && p.x_mm < 9500 && p.y_mm > 500 && p.y_mm < 7500);
    EXPECT_FALSE(p.x_mm > 2500 && p.x_mm < 4500 && p.y_mm < 6500);
    for (size_t j = 0; j < i; ++j) {
      EXPECT_GE(std::hypot(p.x_mm - poses[j].x_mm, p.y_mm - poses[j].y_mm), 1000.0);
    }
  }
}

TEST(SiteRender, RefusesMismatchedInput) {
  const CameraIntrinsics k = test_intrinsics(320, 240, 350.0);
  SiteScene s = one_agv_scene({0.0, 0.0, 0.0});
  const SiteFrameRenderer renderer(k);
  const RenderCamera other = ceiling_camera(test_intrinsics(640, 360));
  EXPECT_TRUE(renderer.render(s, other, clean_params(), 1).image.empty());
  s.agvs.clear();
  EXPECT_TRUE(renderer.render(s, ceiling_camera(k), clean_params(), 1).image.empty());
  CameraIntrinsics zero = k;
  zero.width_px = 0;
  EXPECT_TRUE(render_site_frame(s, ceiling_camera(zero), clean_params(), 1).image.empty());
}

}  // namespace
}  // namespace agv::sim
