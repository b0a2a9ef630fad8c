// agvloc-desk calibrate check on simulated frames (realistic degradation: defocus, noise,
// illumination gradient) of a parked vehicle: the frames are rendered with a true mounting, the
// check runs with a configuration that is wrong in one known way and must name that cause and
// its magnitude; a correct configuration passes; bad input gives exit 2.
#include <gtest/gtest.h>
#include <unistd.h>

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <random>

#include "../support/desk_command.hpp"
#include "agv/recording/png_io.hpp"
#include "agv/recording/recording.hpp"
#include "agv/sim/render.hpp"
#include "calib_check.hpp"
#include "commands.hpp"

namespace fs = std::filesystem;
using namespace agv;
using desk::calib::Cause;

namespace {

// Nominal mounting: camera 250 mm ahead of the axle, centred, 200 mm high.
CameraModel nominal() {
  CameraModel c = CameraModel::default_640x480();
  c.mount.offset_x_mm = 250.0;
  c.mount.offset_y_mm = 0.0;
  c.mount.yaw_rad = 0.0;
  c.mount.height_mm = 200.0;
  return c;
}

// Frames of one landmark (full payload, id 7) at `landmark_in_vehicle` seen by `truth` from the
// vehicle parked at `vehicle_in_world`.
std::vector<cv::Mat> render(const CameraModel& truth, const Pose2& landmark_in_vehicle, int n,
                            std::uint64_t seed, sim::RenderOptions ro = sim::realistic_options(),
                            const Pose2& vehicle_in_world = {}, double print_size_mm = 60.0) {
  LandmarkMap map;
  map.entries[7] = {7, compose(vehicle_in_world, landmark_in_vehicle)};
  sim::Scene scene;
  std::string err;
  LandmarkGeometry printed;
  printed.size_mm = print_size_mm;
  EXPECT_TRUE(sim::make_scene(map, printed, sim::PayloadMode::kFull, &scene, &err)) << err;
  scene.floor.seed = seed;
  ro.speed_mps = 0.0;  // parked
  ro.yaw_rate_radps = 0.0;
  const sim::FrameRenderer r(scene, truth);
  std::mt19937_64 rng(seed);
  std::vector<cv::Mat> out;
  for (int i = 0; i < n; ++i) out.push_back(r.render(vehicle_in_world, ro, rng));
  return out;
}

struct Placement {
  Pose2 taped;
  std::vector<cv::Mat> frames;
};

bool check(const CameraModel& config, const std::vector<Placement>& ps, desk::calib::CheckResult* r,
           std::string* err, const desk::calib::Tolerances& tol = {},
           double printed_size_mm = 60.0) {
  std::vector<desk::calib::PlacementInput> in(ps.size());
  for (size_t i = 0; i < ps.size(); ++i) {
    in[i].taped = ps[i].taped;
    for (size_t k = 0; k < ps[i].frames.size(); ++k) {
      in[i].frames.push_back({"frame" + std::to_string(k), &ps[i].frames[k]});
    }
  }
  return desk::calib::run_check(config, vision::VisionConfig{}, printed_size_mm, nullptr, in, tol,
                                r, err);
}

bool failed(const desk::calib::CheckResult& r, Cause c) {
  for (const auto& f : r.findings) {
    if (f.cause == c && !f.ok) return true;
  }
  return false;
}

std::string failures(const desk::calib::CheckResult& r) {
  std::string s;
  for (const auto& f : r.findings) {
    if (!f.ok) s += std::string(desk::calib::to_string(f.cause)) + "; ";
  }
  return s;
}

// Recovered-vs-true table line (simulated frames).
void table(const char* name, const CameraModel& truth, const desk::calib::CheckResult& r) {
  std::printf(
      "[simulated] %-10s true: off %.2f,%.2f yaw %.3f h %.2f | check: off %.2f,%.2f yaw %.3f "
      "h %.2f | err: off %.3f,%.3f mm yaw %.4f deg h %.3f mm | FAIL: %s\n",
      name, truth.mount.offset_x_mm, truth.mount.offset_y_mm, rad_to_deg(truth.mount.yaw_rad),
      truth.mount.height_mm, r.offset_x_mm, r.offset_y_mm, r.yaw_deg, r.height_mm,
      r.offset_x_mm - truth.mount.offset_x_mm, r.offset_y_mm - truth.mount.offset_y_mm,
      r.yaw_deg - rad_to_deg(truth.mount.yaw_rad), r.height_mm - truth.mount.height_mm,
      failures(r).c_str());
}

// The landmark taped under the camera, turned 30 deg.
const Pose2 kUnderCamera{252.0, 3.0, deg_to_rad(30.0)};

void expect_recovered(const CameraModel& truth, const desk::calib::CheckResult& r) {
  EXPECT_NEAR(r.offset_x_mm, truth.mount.offset_x_mm, 0.2);
  EXPECT_NEAR(r.offset_y_mm, truth.mount.offset_y_mm, 0.2);
  EXPECT_NEAR(r.yaw_deg, rad_to_deg(truth.mount.yaw_rad), 0.05);
  ASSERT_TRUE(r.height_known);
  EXPECT_NEAR(r.height_mm, truth.mount.height_mm, 0.3);
}

}  // namespace

TEST(CalibCheck, CorrectConfigurationPasses) {
  const CameraModel truth = nominal();
  desk::calib::CheckResult r;
  std::string err;
  ASSERT_TRUE(check(truth, {{kUnderCamera, render(truth, kUnderCamera, 5, 1)}}, &r, &err)) << err;
  std::fputs(desk::calib::format_report(truth, r).c_str(), stdout);
  table("correct", truth, r);
  EXPECT_TRUE(r.within_tolerance()) << failures(r);
  expect_recovered(truth, r);
  ASSERT_EQ(r.placements.size(), 1u);
  EXPECT_EQ(r.placements[0].frames_ok, 5);
  EXPECT_EQ(r.placements[0].landmark_id, 7u);
}

// The check is desk work: it measures with every pixel row, whatever edge_row_step the vehicle's
// configuration has (the same fix as a localizer at step 1).
TEST(CalibCheck, MeasuresWithEveryPixelRow) {
  const CameraModel truth = nominal();
  const std::vector<cv::Mat> frames = render(truth, kUnderCamera, 1, 3);
  std::vector<desk::calib::PlacementInput> in(1);
  in[0].taped = kUnderCamera;
  in[0].frames.push_back({"frame0", &frames[0]});
  vision::VisionConfig vehicle;
  vehicle.edge_row_step = 4;
  desk::calib::CheckResult r;
  std::string err;
  ASSERT_TRUE(desk::calib::run_check(truth, vehicle, 60.0, nullptr, in, {}, &r, &err)) << err;
  ASSERT_EQ(r.placements.size(), 1u);
  ASSERT_EQ(r.placements[0].frames.size(), 1u);
  vision::VisionConfig every_row;
  every_row.edge_row_step = 1;
  LandmarkGeometry geom;
  geom.size_mm = 60.0;
  vision::LandmarkLocalizer loc(every_row, truth, geom, nullptr);
  vision::LandmarkFix fix;
  ASSERT_EQ(loc.process(frames[0], &fix), vision::FixStatus::kOk);
  EXPECT_EQ(r.placements[0].frames[0].fix.edge_points_used, fix.edge_points_used);
  EXPECT_EQ(r.placements[0].frames[0].fix.e_x_mm, fix.e_x_mm);
}

TEST(CalibCheck, WrongOffsetNamesTheOffset) {
  CameraModel truth = nominal();
  truth.mount.offset_x_mm = 254.0;
  truth.mount.offset_y_mm = -3.0;
  desk::calib::CheckResult r;
  std::string err;
  ASSERT_TRUE(check(nominal(), {{kUnderCamera, render(truth, kUnderCamera, 3, 2)}}, &r, &err))
      << err;
  table("offset", truth, r);
  EXPECT_FALSE(r.within_tolerance());
  EXPECT_TRUE(failed(r, Cause::kOffset));
  EXPECT_FALSE(failed(r, Cause::kYaw));
  EXPECT_FALSE(failed(r, Cause::kHeight));
  EXPECT_FALSE(failed(r, Cause::kDistortion));
  expect_recovered(truth, r);
}

TEST(CalibCheck, WrongYawNamesTheYaw) {
  CameraModel truth = nominal();
  truth.mount.yaw_rad = deg_to_rad(1.5);
  desk::calib::CheckResult r;
  std::string err;
  ASSERT_TRUE(check(nominal(), {{kUnderCamera, render(truth, kUnderCamera, 3, 3)}}, &r, &err))
      << err;
  table("yaw", truth, r);
  EXPECT_TRUE(failed(r, Cause::kYaw));
  EXPECT_FALSE(failed(r, Cause::kOffset));
  EXPECT_FALSE(failed(r, Cause::kHeight));
  expect_recovered(truth, r);
}

TEST(CalibCheck, WrongHeightNamesTheHeight) {
  CameraModel truth = nominal();
  truth.mount.height_mm = 205.0;
  // Off-centre placement: the scale error also moves the landmark, which must not be read as an
  // offset.
  const Pose2 taped{280.0, 30.0, deg_to_rad(-10.0)};
  desk::calib::CheckResult r;
  std::string err;
  ASSERT_TRUE(check(nominal(), {{taped, render(truth, taped, 3, 4)}}, &r, &err)) << err;
  table("height", truth, r);
  EXPECT_TRUE(failed(r, Cause::kHeight));
  EXPECT_FALSE(failed(r, Cause::kOffset));
  EXPECT_FALSE(failed(r, Cause::kYaw));
  expect_recovered(truth, r);
  // The landmark looks 2.5 % too small (200/205).
  EXPECT_NEAR(r.placements[0].scale, 200.0 / 205.0, 0.001);
}

TEST(CalibCheck, AllThreeAtOnce) {
  CameraModel truth = nominal();
  truth.mount.offset_x_mm = 243.0;
  truth.mount.offset_y_mm = 6.0;
  truth.mount.yaw_rad = deg_to_rad(-2.0);
  truth.mount.height_mm = 196.0;
  const Pose2 taped{230.0, -20.0, deg_to_rad(100.0)};
  desk::calib::CheckResult r;
  std::string err;
  ASSERT_TRUE(check(nominal(), {{taped, render(truth, taped, 3, 5)}}, &r, &err)) << err;
  table("all three", truth, r);
  EXPECT_TRUE(failed(r, Cause::kOffset));
  EXPECT_TRUE(failed(r, Cause::kYaw));
  EXPECT_TRUE(failed(r, Cause::kHeight));
  expect_recovered(truth, r);
}

TEST(CalibCheck, WrongDistortionIsPositionDependent) {
  // The lens has barrel distortion the configuration does not know: the centre placement alone
  // looks almost right, the placements towards the image corners disagree.
  CameraModel truth = nominal();
  truth.intrinsics.k1 = -0.25;
  const std::vector<Pose2> taped = {
      {250.0, 0.0, 0.0}, {277.0, 48.0, deg_to_rad(90.0)}, {223.0, -48.0, deg_to_rad(-90.0)}};
  std::vector<Placement> ps;
  for (size_t i = 0; i < taped.size(); ++i)
    ps.push_back({taped[i], render(truth, taped[i], 2, 6 + i)});
  desk::calib::CheckResult r;
  std::string err;
  ASSERT_TRUE(check(nominal(), ps, &r, &err)) << err;
  std::fputs(desk::calib::format_report(nominal(), r).c_str(), stdout);
  table("k1 -0.25", truth, r);
  EXPECT_TRUE(failed(r, Cause::kDistortion));
  EXPECT_TRUE(r.lens_suspect);
  EXPECT_FALSE(failed(r, Cause::kFocus));
  // With the right k1 the same frames pass.
  desk::calib::CheckResult ok;
  ASSERT_TRUE(check(truth, ps, &ok, &err)) << err;
  table("k1 known", truth, ok);
  EXPECT_TRUE(ok.within_tolerance()) << failures(ok);
  EXPECT_FALSE(ok.lens_suspect);
}

TEST(CalibCheck, BlurredFramesPointToFocus) {
  // Out of focus (defocus sigma 2 px instead of 0.8) and noisy (read noise 10 instead of 2 grey
  // levels): the landmark is still found, but its edges scatter about the fitted square.
  const CameraModel truth = nominal();
  sim::RenderOptions ro = sim::realistic_options();
  ro.defocus_sigma_px = 2.0;
  ro.read_noise_sigma = 10.0;
  desk::calib::CheckResult r;
  std::string err;
  ASSERT_TRUE(check(truth, {{kUnderCamera, render(truth, kUnderCamera, 4, 9, ro)}}, &r, &err))
      << err;
  table("blurred", truth, r);
  EXPECT_TRUE(failed(r, Cause::kFocus)) << failures(r);
  EXPECT_FALSE(failed(r, Cause::kYaw));
  EXPECT_FALSE(failed(r, Cause::kOffset));
  EXPECT_FALSE(failed(r, Cause::kHeight));
  EXPECT_GT(r.placements[0].residual_rms_mm, 0.1);
}

TEST(CalibCheck, SpreadOverFramesIsReported) {
  // The landmark (or the vehicle) moved by 0.15 mm between the frames of one placement.
  const CameraModel truth = nominal();
  std::vector<cv::Mat> frames;
  for (int i = 0; i < 4; ++i) {
    const Pose2 p{kUnderCamera.x_mm + 0.15 * (i % 2), kUnderCamera.y_mm, kUnderCamera.theta_rad};
    frames.push_back(render(truth, p, 1, 20 + static_cast<std::uint64_t>(i))[0]);
  }
  desk::calib::CheckResult r;
  std::string err;
  ASSERT_TRUE(check(truth, {{kUnderCamera, frames}}, &r, &err)) << err;
  EXPECT_TRUE(failed(r, Cause::kFocus)) << failures(r);
  EXPECT_NEAR(r.placements[0].spread_mm, 0.15 * std::sqrt(4.0 / 3.0) / 2.0, 0.02);
  EXPECT_FALSE(failed(r, Cause::kOffset));
}

TEST(CalibCheck, PrintScaleLooksLikeHeightUntilMeasured) {
  // The printer scaled the landmark by +1 % (60.6 mm): with the nominal size the check reads a
  // camera 1 % too low; told the caliper-measured size, it passes.
  const CameraModel truth = nominal();
  const auto frames = render(truth, kUnderCamera, 2, 14, sim::realistic_options(), {}, 60.6);
  desk::calib::CheckResult r;
  std::string err;
  ASSERT_TRUE(check(truth, {{kUnderCamera, frames}}, &r, &err)) << err;
  table("print 60.6", truth, r);
  EXPECT_TRUE(failed(r, Cause::kHeight));
  EXPECT_NEAR(r.height_mm, 200.0 / 1.01, 0.3);
  EXPECT_NEAR(r.placements[0].outer_side_mm, 60.6, 0.05);
  EXPECT_NEAR(r.placements[0].border_width_mm, 6.06, 0.02);
  ASSERT_TRUE(check(truth, {{kUnderCamera, frames}}, &r, &err, {}, 60.6)) << err;
  EXPECT_TRUE(r.within_tolerance()) << failures(r);
  EXPECT_NEAR(r.height_mm, 200.0, 0.3);
}

TEST(CalibCheck, VehicleTapedInTheWorldUsesTheMap) {
  // The vehicle's world pose was taped instead; the landmark's comes from the map.
  const CameraModel truth = nominal();
  const Pose2 vehicle_in_world{1000.0, 2000.0, deg_to_rad(90.0)};
  LandmarkMap map;
  map.entries[7] = {7, compose(vehicle_in_world, kUnderCamera)};
  const auto frames =
      render(truth, kUnderCamera, 2, 13, sim::realistic_options(), vehicle_in_world);
  std::vector<desk::calib::PlacementInput> in(1);
  in[0].taped_is_vehicle_in_world = true;
  in[0].taped = vehicle_in_world;
  for (const auto& f : frames) in[0].frames.push_back({"f", &f});
  desk::calib::CheckResult r;
  std::string err;
  ASSERT_TRUE(desk::calib::run_check(truth, vision::VisionConfig{}, 60.0, &map, in, {}, &r, &err))
      << err;
  EXPECT_NEAR(r.placements[0].taped_landmark_in_vehicle.x_mm, kUnderCamera.x_mm, 1e-9);
  EXPECT_NEAR(r.placements[0].taped_landmark_in_vehicle.y_mm, kUnderCamera.y_mm, 1e-9);
  EXPECT_TRUE(r.within_tolerance()) << failures(r);
  // The vehicle taped 2 mm further along world +y (= vehicle +x): the landmark appears 2 mm
  // behind the taped place.
  in[0].taped.y_mm += 2.0;
  ASSERT_TRUE(desk::calib::run_check(truth, vision::VisionConfig{}, 60.0, &map, in, {}, &r, &err))
      << err;
  EXPECT_NEAR(r.placements[0].dx_mm, 2.0, 0.05);
  EXPECT_TRUE(failed(r, Cause::kOffset));
  // Landmark not in the map (the vision stage already refuses it), or no map: bad input.
  LandmarkMap other;
  other.entries[8] = {8, Pose2{}};
  EXPECT_FALSE(
      desk::calib::run_check(truth, vision::VisionConfig{}, 60.0, &other, in, {}, &r, &err));
  EXPECT_NE(err.find("landmark not in the map"), std::string::npos) << err;
  EXPECT_FALSE(
      desk::calib::run_check(truth, vision::VisionConfig{}, 60.0, nullptr, in, {}, &r, &err));
  EXPECT_NE(err.find("none given"), std::string::npos) << err;
}

TEST(CalibCheck, NoLandmarkIsBadInput) {
  const CameraModel truth = nominal();
  // The landmark is 300 mm beside the camera's field of view.
  const Pose2 far{250.0, 300.0, 0.0};
  desk::calib::CheckResult r;
  std::string err;
  EXPECT_FALSE(check(truth, {{far, render(truth, far, 2, 10)}}, &r, &err));
  EXPECT_NE(err.find("no landmark fix"), std::string::npos) << err;
  EXPECT_FALSE(check(truth, {{far, {}}}, &r, &err));
  EXPECT_NE(err.find("no frames"), std::string::npos) << err;
  // Wrong frame size for the configured camera.
  std::vector<cv::Mat> small = {cv::Mat(240, 320, CV_8UC1, cv::Scalar(128))};
  EXPECT_FALSE(check(truth, {{far, small}}, &r, &err));
  EXPECT_NE(err.find("320x240"), std::string::npos) << err;
}

// ------------------------------------------------------------------------------------------------
// The command: files in, exit code out.

namespace {

fs::path tmpdir(const std::string& name) {
  const fs::path d = fs::temp_directory_path() /
                     ("agv_test_calibcheck_" + std::to_string(::getpid()) + "_" + name);
  fs::remove_all(d);
  fs::create_directories(d);
  return d;
}

void write_config(const fs::path& path, const CameraModel& c) {
  std::ofstream f(path);
  f << "intrinsics:\n  fx: " << c.intrinsics.fx << "\n  fy: " << c.intrinsics.fy
    << "\n  cx: " << c.intrinsics.cx << "\n  cy: " << c.intrinsics.cy << "\n"
    << "mounting:\n  offset_x_mm: " << c.mount.offset_x_mm
    << "\n  offset_y_mm: " << c.mount.offset_y_mm << "\n  yaw_deg: " << rad_to_deg(c.mount.yaw_rad)
    << "\n  height_mm: " << c.mount.height_mm << "\n";
}

int run(std::vector<std::string> args) {
  return testsupport::run_command(desk::calibrate_check, "check", std::move(args));
}

}  // namespace

TEST(CalibCheckCommand, ExitCodes) {
  const fs::path d = tmpdir("cmd");
  CameraModel truth = nominal();
  truth.mount.height_mm = 204.0;
  const auto frames = render(truth, kUnderCamera, 2, 11);
  std::string err;
  std::vector<std::string> pngs;
  for (size_t i = 0; i < frames.size(); ++i) {
    pngs.push_back((d / ("f" + std::to_string(i) + ".png")).string());
    ASSERT_TRUE(png::write(pngs.back(), frames[i], &err)) << err;
  }
  write_config(d / "right.yaml", truth);
  write_config(d / "wrong.yaml", nominal());
  const std::string pose = "252,3,30";
  auto args = [&](const std::string& cfg) {
    std::vector<std::string> a = {"--config", (d / cfg).string(), "--pose", pose};
    a.insert(a.end(), pngs.begin(), pngs.end());
    return a;
  };
  EXPECT_EQ(run(args("right.yaml")), 0);
  EXPECT_EQ(run(args("wrong.yaml")), 1);
  // Bad input: missing config, unreadable frame, no pose, frame without a landmark.
  EXPECT_EQ(run(args("missing.yaml")), 2);
  {
    std::ofstream(d / "broken.png") << "not a png";
    EXPECT_EQ(
        run({"--config", (d / "right.yaml").string(), "--pose", pose, (d / "broken.png").string()}),
        2);
  }
  EXPECT_EQ(run({"--config", (d / "right.yaml").string(), pngs[0]}), 2);
  const auto empty = render(truth, {250.0, 400.0, 0.0}, 1, 12);
  ASSERT_TRUE(png::write((d / "empty.png").string(), empty[0], &err)) << err;
  EXPECT_EQ(
      run({"--config", (d / "right.yaml").string(), "--pose", pose, (d / "empty.png").string()}),
      2);
  // A recording directory (as agvloc record writes it) instead of PNG files.
  {
    const fs::path rec = d / "park1";
    recording::Meta meta;
    meta.camera = truth;
    ASSERT_TRUE(recording::write_meta(rec.string(), meta, &err)) << err;
    std::vector<recording::FrameRow> rows;
    for (size_t i = 0; i < frames.size(); ++i) {
      const std::string name = "frames/" + std::to_string(i) + ".png";
      ASSERT_TRUE(recording::write_frame_png(rec.string(), name, frames[i], &err)) << err;
      rows.push_back({1'000'000'000LL + static_cast<std::int64_t>(i) * 33'000'000LL, name});
    }
    ASSERT_TRUE(recording::write_frames_csv(rec.string(), rows, &err)) << err;
    ASSERT_TRUE(recording::write_odom_csv(
        rec.string(), {{1'000'000'000LL, 0.0, 0.0}, {1'100'000'000LL, 0.0, 0.0}}, &err))
        << err;
    EXPECT_EQ(run({"--config", (d / "right.yaml").string(), "--pose", pose, rec.string()}), 0);
    EXPECT_EQ(run({"--config", (d / "wrong.yaml").string(), "--pose", pose, rec.string()}), 1);
    EXPECT_EQ(run({"--config", (d / "right.yaml").string(), "--pose", pose, d.string()}), 2);
  }
  // Several placements from a CSV (relative paths); world-taped pose without a map is refused.
  {
    std::ofstream f(d / "placements.csv");
    f << "frame,x_mm,y_mm,heading_deg\nf0.png,252,3,30\nf1.png,252,3,30\n";
  }
  EXPECT_EQ(run({"--config", (d / "right.yaml").string(), "--placements",
                 (d / "placements.csv").string()}),
            0);
  EXPECT_EQ(run({"--config", (d / "right.yaml").string(), "--pose", "0,0,0", "--pose-is",
                 "vehicle-in-world", pngs[0]}),
            2);
  fs::remove_all(d);
}

namespace {

// QR landmarks checked with a tag36h11 configuration: no fix, and the error names the family
// (a family mismatch gave 0 fixes with no hint).
TEST(CalibCheck, FamilyMismatchNamesTheFamily) {
  const CameraModel truth = nominal();
  const std::vector<cv::Mat> frames = render(truth, kUnderCamera, 1, 3);
  std::vector<desk::calib::PlacementInput> in(1);
  in[0].taped = kUnderCamera;
  in[0].frames.push_back({"frame0", &frames[0]});
  vision::VisionConfig tags;
  tags.family = LandmarkFamily::kTag36h11;
  desk::calib::CheckResult r;
  std::string err;
  EXPECT_FALSE(desk::calib::run_check(truth, tags, 60.0, nullptr, in, {}, &r, &err));
  EXPECT_NE(err.find("landmark.family (tag36h11) the family printed?"), std::string::npos) << err;
}

}  // namespace
