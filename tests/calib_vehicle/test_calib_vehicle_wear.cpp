// Vehicle calibration on worn landmarks: robust corners from edge points with a
// scuff and a scratch, reported sigmas that cover the error when one landmark is worn, and the
// per-landmark residual table and warning.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <random>

#include "agv/sim/render.hpp"
#include "calib_drive.hpp"

using namespace agv;
using namespace agv::desk::vcal;

namespace {

constexpr double kFx = 769.23076923076917;

// Edge points of a landmark seen straight down from 200 mm: landmark mm / 200 = normalised.
struct SyntheticEdges {
  BorderEdges edges;
  std::array<Vec2, 8> truth;  // normalised corners
};

SyntheticEdges synthetic_edges(unsigned seed) {
  SyntheticEdges s;
  const Vec2 c{0.013, -0.021};
  const double th = deg_to_rad(20.0), ct = std::cos(th), st = std::sin(th);
  auto to_n = [&](Vec2 l) {
    return Vec2{c.x + (ct * l.x - st * l.y) / 200.0, c.y + (st * l.x + ct * l.y) / 200.0};
  };
  const auto lc = landmark_corners(30.0, 24.0);
  for (size_t i = 0; i < 8; ++i) s.truth[i] = to_n(lc[i]);
  std::mt19937 rng(seed);
  std::normal_distribution<double> noise(0.0, 0.03 / kFx);  // 0.03 px
  for (size_t k = 0; k < 2; ++k) {
    const double h = k == 0 ? 30.0 : 24.0;
    for (size_t side = 0; side < 4; ++side) {
      // Points every 0.2 mm (about 1 px) along the edge, short of the corners.
      for (double t = -0.8 * h; t <= 0.8 * h; t += 0.2) {
        const Vec2 l = side == 0   ? Vec2{h, t}
                       : side == 1 ? Vec2{t, h}
                       : side == 2 ? Vec2{-h, t}
                                   : Vec2{t, -h};
        Vec2 p = to_n(l);
        p = {p.x + noise(rng), p.y + noise(rng)};
        s.edges.xn[k][side].push_back(p);
      }
    }
  }
  return s;
}

// Moves the points of one edge with along-edge index in [from, to) by d_px along the landmark's
// axis at axis_deg (0: its x axis, 90: its y axis; the landmark is turned by 20 deg).
void displace(std::vector<Vec2>* pts, size_t from, size_t to, double d_px, double axis_deg) {
  const double a = deg_to_rad(20.0 + axis_deg);
  for (size_t i = from; i < to && i < pts->size(); ++i) {
    (*pts)[i].x += d_px * std::cos(a) / kFx;
    (*pts)[i].y += d_px * std::sin(a) / kFx;
  }
}

}  // namespace

TEST(CalibVehicleWear, RobustCornersIgnoreAScuffAndAScratch) {
  SyntheticEdges s = synthetic_edges(3);
  // A scuff: a fifth of the outer edge of side 0 rubbed off 1.2 px deep. A scratch crossing the
  // inner edge of side 1: a sixth of its points 2.5 px off.
  auto& outer0 = s.edges.xn[0][0];
  displace(&outer0, outer0.size() / 5, 2 * outer0.size() / 5, -1.2, 0.0);
  auto& inner1 = s.edges.xn[1][1];
  displace(&inner1, inner1.size() / 2, inner1.size() / 2 + inner1.size() / 6, 2.5, 90.0);
  CornerObservation o;
  ASSERT_TRUE(corners_from_edges(s.edges, kFx, &o));
  double worst = 0.0;
  for (size_t i = 0; i < 8; ++i) {
    ASSERT_TRUE(o.valid[i]) << i;
    const double e = std::hypot(o.xn[i].x - s.truth[i].x, o.xn[i].y - s.truth[i].y) * kFx;
    std::printf("corner %zu: error %.4f px\n", i, e);
    worst = std::max(worst, e);
  }
  // The plain line fit with 3-sigma rejection (calibrate vehicle's clean-floor fit) puts
  // four of these corners 0.13-0.66 px off (measured on these points); the robust fit keeps
  // every corner at the noise level of a clean edge (0.013 px at most).
  EXPECT_LT(worst, 0.03);
}

TEST(CalibVehicleWear, TooFewEdgePointsGiveNoCorner) {
  SyntheticEdges s = synthetic_edges(4);
  s.edges.xn[0][0].resize(4);  // outer side 0: corners 0 and 3 lost
  s.edges.xn[1][0].clear();    // inner side 0: corners 4 and 7 lost
  CornerObservation o;
  ASSERT_TRUE(corners_from_edges(s.edges, kFx, &o));
  EXPECT_FALSE(o.valid[0] || o.valid[3] || o.valid[4] || o.valid[7]);
  EXPECT_TRUE(o.valid[1] && o.valid[2] && o.valid[5] && o.valid[6]);
}

TEST(CalibVehicleWear, StandingOutIsRelativeToTheOthersAndAbsolute) {
  Options opt;
  auto run = [&](std::vector<double> rms) {
    std::vector<LandmarkReport> l;
    for (size_t i = 0; i < rms.size(); ++i) {
      LandmarkReport r;
      r.landmark_id = static_cast<std::uint32_t>(i + 1);
      r.rms_after_px = rms[i];
      l.push_back(r);
    }
    std::vector<std::string> w;
    flag_standing_out(opt, &l, &w);
    std::string flagged;
    for (const auto& r : l) flagged += r.stands_out ? "x" : ".";
    EXPECT_EQ(w.size(), static_cast<size_t>(std::count(flagged.begin(), flagged.end(), 'x')));
    return flagged;
  };
  EXPECT_EQ(run({0.12, 0.80, 0.10}), ".x.");  // one worn among clean ones
  EXPECT_EQ(run({0.12, 0.90}), ".x");         // two landmarks: against the other one
  EXPECT_EQ(run({0.02, 0.05, 0.02}), "...");  // 2.5x, but below the floor: noise
  EXPECT_EQ(run({0.60, 0.60, 0.60}), "xxx");  // all worn: the absolute limit
  EXPECT_EQ(run({0.3}), ".");
}

TEST(CalibVehicleWear, ResidualTableNamesTheWornLandmark) {
  calibtest::DriveTruth t;
  t.p.mount = CameraModel::default_640x480().mount;
  t.p.mount.offset_x_mm = 5.0;
  t.p.mount.height_mm = 202.0;
  t.p.speed_scale = 1.02;
  t.p.time_offset_s = 0.015;
  t.duration_s = 45;
  t.worn = {2};
  t.wear_mm = 0.05;
  t.wear_noise_px = 0.5;
  const calibtest::Drive d = calibtest::make_calibration_drive(t);
  Options opt;
  opt.fx_px = kFx;
  opt.pixel_sigma_px = 0.05;
  Result r;
  std::string err;
  ASSERT_TRUE(calibtest::calibrate_from_nominal(d, opt, &r, &err)) << err;
  const std::string table = landmark_table(r);
  std::printf("%s", table.c_str());
  ASSERT_EQ(r.landmarks.size(), 3u);
  for (const LandmarkReport& l : r.landmarks) {
    EXPECT_EQ(l.stands_out, l.landmark_id == 2) << l.landmark_id;
    EXPECT_GT(l.frames, 0);
    EXPECT_GT(l.passes, 0);
  }
  // The worn landmark's frames were given its own, larger noise.
  EXPECT_GT(r.landmarks[1].sigma_px, 0.3);
  EXPECT_LT(r.landmarks[0].sigma_px, 0.06);
  int named = 0;
  for (const std::string& w : r.warnings) {
    std::printf("warning: %s\n", w.c_str());
    named += w.rfind("landmark 2: corner residual", 0) == 0 ? 1 : 0;
    EXPECT_EQ(w.find("landmark 1:"), std::string::npos);
    EXPECT_EQ(w.find("landmark 3:"), std::string::npos);
  }
  EXPECT_EQ(named, 1);
  const size_t row = table.find("\n       2 ");
  ASSERT_NE(row, std::string::npos) << table;
  EXPECT_NE(table.substr(row + 1, table.find('\n', row + 1) - row - 1).find("<- stands out"),
            std::string::npos);
}

// The simulator's wear lands on the chosen landmarks only (the worn calibration drives of
// eval_worn_calibration.py): a frame of landmark 1 with only landmark 2 worn is the clean frame.
TEST(CalibVehicleWear, SimulatorWearsOnlyTheChosenLandmarks) {
  sim::Scene scene;
  std::string err;
  ASSERT_TRUE(sim::make_scene(sim::default_landmark_grid(), LandmarkGeometry{},
                              sim::PayloadMode::kFull, &scene, &err))
      << err;
  scene.floor.amplitude = 0.0;
  const CameraModel cam = CameraModel::default_640x480();
  sim::FrameRenderer renderer(scene, cam);
  const Pose2 over_1{3.0, -2.0, 0.3};  // landmark 1 is at the world origin
  auto render = [&](const sim::RenderOptions& o) {
    std::mt19937_64 rng(1);
    return renderer.render(over_1, o, rng);
  };
  const cv::Mat clean = render(sim::RenderOptions{});
  sim::RenderOptions worn;
  worn.scratches_per_landmark = 2;
  worn.dirt_spots_per_landmark = 2;
  worn.edge_scuffs_per_landmark = 4;
  worn.ink_variation = 0.3;
  worn.occluder_border_fraction = 0.05;
  worn.worn_ids = {2};
  EXPECT_EQ(cv::norm(render(worn), clean, cv::NORM_INF), 0.0);
  worn.worn_ids = {1};
  EXPECT_GT(cv::norm(render(worn), clean, cv::NORM_L1), 1e4);
  // Scuffs alone move the border's edges: pixels on it change.
  sim::RenderOptions scuffed;
  scuffed.edge_scuffs_per_landmark = 4;
  const cv::Mat s = render(scuffed);
  EXPECT_GT(cv::countNonZero(s != clean), 20);
}
