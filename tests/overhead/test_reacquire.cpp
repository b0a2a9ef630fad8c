// Re-acquisition of vehicles lost while their tags were hidden (algo/src/overhead/reacquire.cpp,
// camera_frame_reacquire.cpp): which box goes to which lost vehicle, the half turn from the last
// heading or from travel, the sweep's tiles, and on rendered frames with the committed model a
// covered vehicle's lost track restarted at its true pose, never from an ambiguous box.
#include <gtest/gtest.h>

#include <cmath>
#include <fstream>
#include <iterator>
#include <memory>
#include <string>
#include <vector>

#include "agv/overhead/camera_frame.hpp"
#include "agv/overhead/reacquire.hpp"
#include "tray_scene.hpp"

namespace agv::overhead {
namespace {

constexpr std::int64_t kSecond = 1'000'000'000;

site::FleetAgv vehicle() { return site::FleetAgv{}; }  // 600 x 400 mm tray

PlaneTray box_at(double x, double y, double axis_rad, double score = 0.9) {
  PlaneTray t;
  t.centre_mm = {x, y};
  t.axis_rad = axis_rad;
  t.length_mm = 600.0;
  t.width_mm = 400.0;
  t.score = score;
  return t;
}

LostVehicle lost_at(std::size_t agv, double x, double y, double theta, std::int64_t t_ns) {
  return {agv, {x, y, theta}, 10.0, 0.01, t_ns};
}

TEST(Reacquire, OneBoxInOneDiskIsAssigned) {
  const std::vector<site::FleetAgv> fleet(3, vehicle());
  ReacquireParams p;
  p.max_speed_mps = 1.0;
  const std::int64_t t = 2 * kSecond;  // disks of 2030 mm
  const auto out = assign_boxes({box_at(1500, 0, 0)}, {lost_at(1, 0, 0, 0, 0)}, {}, fleet, t, p);
  ASSERT_EQ(out.size(), 1u);
  EXPECT_EQ(out[0].outcome, ReacquireOutcome::kAssigned);
  EXPECT_EQ(out[0].agv, 1u);
  // Out of reach, or explained by a vehicle read or tracked there, or not a tray of its size.
  EXPECT_EQ(
      assign_boxes({box_at(2500, 0, 0)}, {lost_at(1, 0, 0, 0, 0)}, {}, fleet, t, p)[0].outcome,
      ReacquireOutcome::kNoCandidate);
  EXPECT_EQ(
      assign_boxes({box_at(1500, 0, 0)}, {lost_at(1, 0, 0, 0, 0)}, {{1600, 100}}, fleet, t, p)[0]
          .outcome,
      ReacquireOutcome::kExplained);
  PlaneTray small = box_at(1500, 0, 0);
  small.length_mm = 400.0;
  EXPECT_EQ(assign_boxes({small}, {lost_at(1, 0, 0, 0, 0)}, {}, fleet, t, p)[0].outcome,
            ReacquireOutcome::kNoCandidate);
}

TEST(Reacquire, TwoCandidatesAreNeverGuessed) {
  const std::vector<site::FleetAgv> fleet(3, vehicle());
  ReacquireParams p;
  p.max_speed_mps = 1.0;
  const std::int64_t t = 2 * kSecond;
  // Two lost vehicles that could both be there.
  auto out = assign_boxes({box_at(1000, 0, 0)},
                          {lost_at(0, 0, 0, 0, 0), lost_at(2, 1500, 500, 0, 0)}, {}, fleet, t, p);
  EXPECT_EQ(out[0].outcome, ReacquireOutcome::kAmbiguous);
  // One lost vehicle, two boxes it could be.
  out = assign_boxes({box_at(1000, 0, 0), box_at(-1000, 0, 0)}, {lost_at(0, 0, 0, 0, 0)}, {}, fleet,
                     t, p);
  EXPECT_EQ(out[0].outcome, ReacquireOutcome::kAmbiguous);
  EXPECT_EQ(out[1].outcome, ReacquireOutcome::kAmbiguous);
  // The second box explained by a tracked vehicle: the first is unique again.
  out = assign_boxes({box_at(1000, 0, 0), box_at(-1000, 0, 0)}, {lost_at(0, 0, 0, 0, 0)},
                     {{-1000, 0}}, fleet, t, p);
  EXPECT_EQ(out[0].outcome, ReacquireOutcome::kAssigned);
  EXPECT_EQ(out[1].outcome, ReacquireOutcome::kExplained);
}

TEST(Reacquire, HalfTurnFromTheLastHeadingOrFromTravel) {
  const site::FleetAgv a = vehicle();
  ReacquireParams p;
  p.max_turn_rate_radps = 0.5;
  const LostVehicle v = lost_at(0, 0, 0, 3.0, 0);  // facing -x, nearly
  const PlaneTray b = box_at(300, 0, 0.05);        // long axis near x
  double theta = 0.0;
  // 1 s: it cannot have turned a quarter: the axis direction nearer 3.0 rad.
  ASSERT_TRUE(resolve_heading(b, v, kSecond, false, {}, 0, a, p, &theta));
  EXPECT_NEAR(std::abs(wrap_angle_rad(theta - (0.05 + kPi))), 0.0, 1e-9);
  // 5 s: it could have; no earlier box: unknown.
  EXPECT_FALSE(resolve_heading(b, v, 5 * kSecond, false, {}, 0, a, p, &theta));
  // An earlier box 400 mm behind along the axis (moving +x): forward means heading +x.
  ASSERT_TRUE(
      resolve_heading(b, v, 5 * kSecond, true, box_at(-100, -20, 0.05), 4 * kSecond, a, p, &theta));
  EXPECT_NEAR(theta, 0.05, 1e-9);
  // Moved sideways, too little, too long ago, or a fleet that reverses: unknown.
  EXPECT_FALSE(
      resolve_heading(b, v, 5 * kSecond, true, box_at(300, -400, 0.05), 4 * kSecond, a, p, &theta));
  EXPECT_FALSE(
      resolve_heading(b, v, 5 * kSecond, true, box_at(250, 0, 0.05), 4 * kSecond, a, p, &theta));
  EXPECT_FALSE(
      resolve_heading(b, v, 5 * kSecond, true, box_at(-100, 0, 0.05), 2 * kSecond, a, p, &theta));
  p.forward_only = false;
  EXPECT_FALSE(
      resolve_heading(b, v, 5 * kSecond, true, box_at(-100, 0, 0.05), 4 * kSecond, a, p, &theta));
}

TEST(Reacquire, SweepTilesHoldEveryTrayInView) {
  const site::CeilingCamera cam =
      tray_obb::make_camera(1280, 720, 900.0, 6000.0, 0.3, 0.05, -0.03, -0.05);
  const double window = 2048.0, tray = 600.0, h = 400.0;
  const std::vector<Vec2> tiles = sweep_tiles(cam, h, window, tray);
  ASSERT_FALSE(tiles.empty());
  for (int v = 0; v < 720; v += 40) {
    for (int u = 0; u < 1280; u += 40) {
      Vec2 p;
      ASSERT_TRUE(pixel_to_plane(cam, {double(u), double(v)}, h, &p));
      bool held = false;
      for (const Vec2& c : tiles) {
        held = held || (std::abs(p.x - c.x) <= 0.5 * (window - tray) + 1e-6 &&
                        std::abs(p.y - c.y) <= 0.5 * (window - tray) + 1e-6);
      }
      EXPECT_TRUE(held) << u << "," << v;
    }
  }
}

TEST(Reacquire, ParametersAreChecked) {
  EXPECT_EQ(validate(ReacquireParams{}), "");
  ReacquireParams p;
  p.max_speed_mps = 0.0;
  EXPECT_NE(validate(p).find("max_speed_mps"), std::string::npos);
  p = {};
  p.sweep_every_frames = 0;
  EXPECT_NE(validate(p).find("sweep_every_frames"), std::string::npos);
  p = {};
  p.max_travel_angle_rad = 2.0;
  EXPECT_NE(validate(p).find("max_travel_angle_rad"), std::string::npos);
}

// Rendered: the committed model, a 6 m camera, every tag under a parcel.
std::shared_ptr<TrayNet> committed_net() {
  std::ifstream f(AGV_SOURCE_DIR "/models/tray_obb.onnx", std::ios::binary);
  const std::string m((std::istreambuf_iterator<char>(f)), std::istreambuf_iterator<char>());
  auto net = std::make_shared<TrayNet>();
  std::string e;
  if (!net->load(m.data(), m.size(), &e)) return nullptr;
  return net;
}

struct Scene {
  tray_obb::SceneDraw d;
  std::size_t agv = 0;  // a vehicle whose tray is wholly in the frame, others cleared
};

Scene one_vehicle_scene() {
  tray_obb::SceneOptions o;
  o.width_px = 960;
  o.height_px = 540;
  o.fixed_height_mm = 6000.0;
  o.fixed_native_mm_per_px = 4.0;
  o.all_covered = true;
  Scene s;
  s.d = tray_obb::draw_scene(31, tray_obb::Split::kTrain, o);
  s.d.scene.agvs.resize(2);  // the second far out of view
  s.d.scene.site.fleet.resize(2);
  s.d.scene.clutter.clear();
  Vec2 c;
  EXPECT_TRUE(pixel_to_plane(s.d.cam, {480, 270}, o.tray_height_mm, &c));
  s.d.scene.agvs[0].pose = {c.x, c.y, 0.4};
  s.d.scene.agvs[1].pose = {c.x + 30000.0, c.y, 0.0};
  std::vector<sim::Parcel> kept;
  for (const sim::Parcel& p : s.d.scene.parcels) {
    if (p.agv == 0) kept.push_back(p);
  }
  s.d.scene.parcels = kept;
  return s;
}

cv::Mat render(const Scene& s, int seed) {
  return sim::render_site_frame(s.d.scene, sim::RenderCamera::from_ceiling(s.d.cam), s.d.render,
                                seed)
      .image;
}

// Three fixes at the vehicle's pose then silence: at t0 its track is lost.
void lose_track(FleetTracker* tracker, std::size_t agv, const Pose2& pose, std::int64_t t_fix) {
  TagFix f;
  f.pose = pose;
  f.cov = {25, 0, 0, 0, 25, 0, 0, 0, 1e-4};
  for (int k = 0; k < 3; ++k) tracker->add_fix(agv, t_fix + k * 50'000'000LL, f);
}

TEST(ReacquireRendered, LostCoveredVehicleRestartsAtItsPose) {
  const std::shared_ptr<TrayNet> net = committed_net();
  if (!net) GTEST_SKIP() << "no model loaded (OpenCV without dnn)";
  Scene s = one_vehicle_scene();
  const Pose2 truth = s.d.scene.agvs[0].pose;
  CameraFrameProcessor proc(s.d.scene.site.cameras, s.d.scene.site.fleet, {}, {});
  ReacquireParams rp;
  rp.sweep_every_frames = 1;
  proc.set_reacquire(net, rp);
  ASSERT_TRUE(proc.reacquiring());
  FleetTracker tracker(2);
  // Lost 4 s ago, 80 mm and 0.1 rad from where it is now.
  const std::int64_t t0 = 10 * kSecond;
  lose_track(&tracker, 0, {truth.x_mm - 80, truth.y_mm + 20, truth.theta_rad - 0.1},
             t0 - 4 * kSecond);
  // The processor knows a lost vehicle from a frame in which its track was valid.
  std::string e;
  ASSERT_TRUE(proc.process(0, t0 - 4 * kSecond + 150'000'000, render(s, 1), &tracker, nullptr, &e))
      << e;
  tracker.update_states(t0);
  ASSERT_EQ(tracker.output(0, t0).state, TrackState::kLost);
  // 4 s at 1 rad/s: the half turn is open; the first sweep waits for travel.
  ASSERT_TRUE(proc.process(0, t0, render(s, 2), &tracker, nullptr, &e)) << e;
  EXPECT_GE(proc.counters().reacquire_sweeps, 1u);
  EXPECT_EQ(proc.counters().reacquired, 0u);
  EXPECT_EQ(proc.counters().reacquire_heading_unknown, 1u);
  // Half a second later it has driven 250 mm forward: travel gives the heading.
  s.d.scene.agvs[0].pose = {truth.x_mm + 250 * std::cos(truth.theta_rad),
                            truth.y_mm + 250 * std::sin(truth.theta_rad), truth.theta_rad};
  const std::int64_t t1 = t0 + 500'000'000;
  ASSERT_TRUE(proc.process(0, t1, render(s, 3), &tracker, nullptr, &e)) << e;
  EXPECT_EQ(proc.counters().reacquired, 1u);
  const TrackOutput o = tracker.output(0, t1);
  EXPECT_EQ(o.state, TrackState::kTentative);
  const Pose2& now = s.d.scene.agvs[0].pose;
  EXPECT_LT(std::hypot(o.pose.x_mm - now.x_mm, o.pose.y_mm - now.y_mm), 40.0);
  EXPECT_LT(std::abs(wrap_angle_rad(o.pose.theta_rad - now.theta_rad)), 0.2);
  // The tray boxes of the next frames confirm it.
  for (int k = 1; k <= 3; ++k) {
    const std::int64_t t = t1 + k * 100'000'000LL;
    ASSERT_TRUE(proc.process(0, t, render(s, 3 + k), &tracker, nullptr, &e)) << e;
    tracker.update_states(t);
  }
  EXPECT_EQ(tracker.output(0, t1 + 300'000'000).state, TrackState::kConfirmed);
}

TEST(ReacquireRendered, TwoLostVehiclesThatCouldBeTheBoxGetNothing) {
  const std::shared_ptr<TrayNet> net = committed_net();
  if (!net) GTEST_SKIP() << "no model loaded (OpenCV without dnn)";
  Scene s = one_vehicle_scene();
  const Pose2 truth = s.d.scene.agvs[0].pose;
  CameraFrameProcessor proc(s.d.scene.site.cameras, s.d.scene.site.fleet, {}, {});
  ReacquireParams rp;
  rp.sweep_every_frames = 1;
  rp.max_turn_rate_radps = 0.05;  // the last heading resolves the half turn
  proc.set_reacquire(net, rp);
  FleetTracker tracker(2);
  const std::int64_t t0 = 10 * kSecond;
  lose_track(&tracker, 0, truth, t0 - 4 * kSecond);
  lose_track(&tracker, 1, {truth.x_mm + 900, truth.y_mm, truth.theta_rad}, t0 - 4 * kSecond);
  std::string e;
  ASSERT_TRUE(proc.process(0, t0 - 4 * kSecond + 150'000'000, render(s, 1), &tracker, nullptr, &e))
      << e;
  tracker.update_states(t0);
  ASSERT_TRUE(proc.process(0, t0, render(s, 2), &tracker, nullptr, &e)) << e;
  EXPECT_EQ(proc.counters().reacquired, 0u);
  EXPECT_GE(proc.counters().reacquire_ambiguous, 1u);
  EXPECT_EQ(tracker.output(0, t0).state, TrackState::kLost);
  EXPECT_EQ(tracker.output(1, t0).state, TrackState::kLost);
}

}  // namespace
}  // namespace agv::overhead
