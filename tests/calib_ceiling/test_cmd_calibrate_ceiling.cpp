// `agvloc-desk calibrate ceiling` and `ceiling-check` end to end on rendered frames: a site file
// whose pose is 30 mm off fails the check, the calibration writes a pose that passes it, and
// every named error with its exit code.
#include <gtest/gtest.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include "agv/recording/png_io.hpp"
#include "agv/site/site_file.hpp"
#include "ceiling_world.hpp"
#include "commands.hpp"
#include "site_io.hpp"

namespace agv::desk {
namespace {

namespace fs = std::filesystem;
using namespace test;  // NOLINT: the shared scene

struct CmdRun {
  int rc = 0;
  std::string out, err;
};

CmdRun run(int (*cmd)(int, char**), std::vector<std::string> args) {
  std::vector<char*> argv;
  for (auto& a : args) argv.push_back(a.data());
  CmdRun r;
  testing::internal::CaptureStdout();
  testing::internal::CaptureStderr();
  r.rc = cmd(static_cast<int>(argv.size()), argv.data());
  r.out = testing::internal::GetCapturedStdout();
  r.err = testing::internal::GetCapturedStderr();
  return r;
}

void write_file(const fs::path& p, const std::string& text) {
  std::ofstream f(p, std::ios::binary | std::ios::trunc);
  f << text;
}

std::string survey_csv(const World& w, int first, int n) {
  std::string s = "id,x_mm,y_mm,z_mm,yaw_deg,size_mm\n";
  for (const auto& [id, t] : survey_of(w, first, n)) {
    char line[160];
    std::snprintf(line, sizeof line, "%u,%.17g,%.17g,%.17g,%.17g,%.17g\n", id, t.x_mm, t.y_mm,
                  t.z_mm, t.yaw_rad / kDeg, t.size_mm);
    s += line;
  }
  return s;
}

// A work folder with the frames (two, and one alone), surveys and site files.
class CalibrateCeilingCommand : public testing::Test {
 protected:
  static void SetUpTestSuite() {
    dir_ = fs::path(testing::TempDir()) / ("calib_ceiling_" + std::to_string(::getpid()));
    fs::remove_all(dir_);
    fs::create_directories(dir_ / "frames");
    fs::create_directories(dir_ / "one");
    fs::create_directories(dir_ / "empty");
    const World& w = world();
    std::string err;
    for (std::size_t i = 0; i < w.frames.size(); ++i) {
      const fs::path p = dir_ / "frames" / ("00000" + std::to_string(i) + ".png");
      ASSERT_TRUE(png::write(p.string(), w.frames[i], &err)) << err;
    }
    fs::copy_file(dir_ / "frames" / "000000.png", dir_ / "one" / "000000.png");
    write_file(dir_ / "survey.csv", survey_csv(w, 0, 7));
    write_file(dir_ / "survey_two.csv", survey_csv(w, 0, 2));
    write_file(dir_ / "survey_line.csv", survey_csv(w, 0, 3));
    write_file(dir_ / "site_true.yaml", site::write_site(w.site));
  }
  static void TearDownTestSuite() { fs::remove_all(dir_); }

  // The true site with the camera moved by dx_mm.
  static std::string site_off(double dx_mm) {
    site::Site s = world().site;
    s.cameras[0].t_site_cam_mm[0] += dx_mm;
    const fs::path p = dir_ / "site_off.yaml";
    write_file(p, site::write_site(s));
    return p.string();
  }
  static std::string at(const char* name) { return (dir_ / name).string(); }
  static std::vector<std::string> args(const char* sub, const std::string& site,
                                       const std::string& frames, const std::string& survey) {
    return {sub, "--site", site, "--camera", "cam-1", "--frames", frames, "--survey", survey};
  }
  static fs::path dir_;
};
fs::path CalibrateCeilingCommand::dir_;

TEST_F(CalibrateCeilingCommand, CheckFailsOff30MmAndPassesAfterTheCalibrationWrites) {
  const std::string site = site_off(30.0);
  CmdRun r =
      run(calibrate_ceiling_check, args("ceiling-check", site, at("frames"), at("survey.csv")));
  EXPECT_EQ(r.rc, 1) << r.out << r.err;
  EXPECT_NE(r.out.find("FAIL"), std::string::npos) << r.out;
  std::printf("%s", r.out.substr(r.out.find("reprojection RMS")).c_str());

  auto cal = args("ceiling", site, at("frames"), at("survey.csv"));
  cal.push_back("--write");
  r = run(calibrate_ceiling, cal);
  ASSERT_EQ(r.rc, 0) << r.out << r.err;
  std::printf("%s", r.out.c_str());
  EXPECT_NE(r.out.find("sigma"), std::string::npos);
  EXPECT_NE(r.out.find("floor_mm"), std::string::npos);

  site::Site back;
  std::string err;
  ASSERT_TRUE(load_site(site, &back, &err)) << err;
  const auto& t = back.cameras[0].t_site_cam_mm;
  const ccal::CameraPose truth = true_pose();
  EXPECT_NEAR(t[0], truth.x_mm, 5.0);
  EXPECT_NEAR(t[1], truth.y_mm, 5.0);
  EXPECT_NEAR(t[2], truth.z_mm, 10.0);
  EXPECT_EQ(back.fleet.size(), 7u);  // the rest of the site is kept
  // The pose's sigma goes with it, for the overhead tracker's fixes.
  for (double s : back.cameras[0].position_sigma_mm) EXPECT_GT(s, 0.0);
  for (double s : back.cameras[0].angle_sigma_rad) EXPECT_GT(s, 0.0);
  // And their correlation (a shift and a tilt of a camera looking down go together).
  double strongest = 0.0;
  for (double c : back.cameras[0].pose_correlation) strongest = std::max(strongest, std::abs(c));
  EXPECT_GT(strongest, 0.5);
  EXPECT_LT(back.cameras[0].position_sigma_mm[0], 5.0);
  // And the tags' floor residual beyond the pose (a millimetre or less on these frames).
  EXPECT_GT(back.cameras[0].floor_sigma_mm, 0.0);
  EXPECT_LT(back.cameras[0].floor_sigma_mm, 2.0);

  r = run(calibrate_ceiling_check, args("ceiling-check", site, at("frames"), at("survey.csv")));
  EXPECT_EQ(r.rc, 0) << r.out << r.err;
  EXPECT_NE(r.out.find("PASS"), std::string::npos) << r.out;
}

TEST_F(CalibrateCeilingCommand, StartsFromTheSiteFilesPoseWhenAsked) {
  auto a = args("ceiling", site_off(50.0), at("one"), at("survey.csv"));
  a.push_back("--start-from-site");
  const CmdRun r = run(calibrate_ceiling, a);
  EXPECT_EQ(r.rc, 0) << r.out << r.err;
  EXPECT_NE(r.out.find("7 tags, 28 corners in 1 frames"), std::string::npos) << r.out;
}

TEST_F(CalibrateCeilingCommand, NamedErrors) {
  const std::string site = at("site_true.yaml");
  auto expect = [](const CmdRun& r, int rc, const char* name) {
    EXPECT_EQ(r.rc, rc) << r.out << r.err;
    EXPECT_NE(r.err.find(std::string("error ") + name), std::string::npos) << r.err;
  };
  auto a = args("ceiling", site, at("one"), at("survey.csv"));
  a[4] = "cam-9";
  expect(run(calibrate_ceiling, a), 2, "unknown-camera");
  expect(run(calibrate_ceiling, args("ceiling", site, at("empty"), at("survey.csv"))), 2,
         "unreadable-frames");
  fs::create_directories(dir_ / "bad");
  write_file(dir_ / "bad" / "000000.png", "not a png");
  expect(run(calibrate_ceiling, args("ceiling", site, at("bad"), at("survey.csv"))), 2,
         "unreadable-frames");
  fs::create_directories(dir_ / "small");
  std::string err;
  ASSERT_TRUE(png::write((dir_ / "small" / "a.png").string(), cv::Mat(10, 10, CV_8UC1), &err));
  expect(run(calibrate_ceiling, args("ceiling", site, at("small"), at("survey.csv"))), 2,
         "unreadable-frames");
  expect(run(calibrate_ceiling, args("ceiling", site, at("one"), at("survey_two.csv"))), 1,
         "too-few-tags");
  expect(run(calibrate_ceiling, args("ceiling", site, at("one"), at("survey_line.csv"))), 1,
         "degenerate-geometry");
  write_file(dir_ / "survey_bad.csv", "id,x_mm\n");
  expect(run(calibrate_ceiling, args("ceiling", site, at("one"), at("survey_bad.csv"))), 2,
         "bad-survey");
  a = args("ceiling", site, at("one"), at("survey.csv"));
  a.resize(7);
  expect(run(calibrate_ceiling, a), 2, "no-survey");
  // Careless input: a survey that is a folder, a frames folder holding only a FIFO, a NaN.
  expect(run(calibrate_ceiling, args("ceiling", site, at("one"), at("frames"))), 2, "bad-survey");
  fs::create_directories(dir_ / "fifo");
  ASSERT_EQ(::mkfifo((dir_ / "fifo" / "000000.png").c_str(), 0600), 0);
  expect(run(calibrate_ceiling, args("ceiling", site, at("fifo"), at("survey.csv"))), 2,
         "unreadable-frames");
  a = args("ceiling", site, at("one"), at("survey.csv"));
  a.push_back("--robust-px");
  a.push_back("nan");
  EXPECT_NE(run(calibrate_ceiling, a).rc, 0);
  // The check with one surveyed tag in view.
  write_file(dir_ / "survey_one.csv", survey_csv(world(), 4, 1));
  expect(run(calibrate_ceiling_check, args("ceiling-check", site, at("one"), at("survey_one.csv"))),
         1, "too-few-tags");
}

TEST_F(CalibrateCeilingCommand, FloorMapTagsAsTheSurvey) {
  // Trays 1 mm up: the tags lie on the floor where the site's floor map puts them.
  const World& w = floor_world();
  std::string err;
  fs::create_directories(dir_ / "floor");
  ASSERT_TRUE(png::write((dir_ / "floor" / "000000.png").string(), w.frames[0], &err)) << err;
  std::string map = "id,x_mm,y_mm,heading_deg\n";
  for (std::size_t i = 0; i < w.site.fleet.size(); ++i) {
    const Pose2& p = w.scene.agvs[i].pose;
    char line[128];
    std::snprintf(line, sizeof line, "%u,%.6f,%.6f,%.6f\n", w.site.fleet[i].tag_id, p.x_mm, p.y_mm,
                  p.theta_rad / kDeg);
    map += line;
  }
  write_file(dir_ / "floor_map.csv", map);
  site::Site s = w.site;
  s.floor_map_file = "floor_map.csv";
  ASSERT_TRUE(parse_landmark_map(map, &s.floor_map, &err)) << err;
  s.cameras[0].t_site_cam_mm[1] += 40.0;
  write_file(dir_ / "site_floor.yaml", site::write_site(s));
  const std::vector<std::string> a = {
      "ceiling",  "--site",    at("site_floor.yaml"), "--camera", "cam-1",
      "--frames", at("floor"), "--floor-tag-size-mm", "200",      "--write"};
  const CmdRun r = run(calibrate_ceiling, a);
  ASSERT_EQ(r.rc, 0) << r.out << r.err;
  site::Site back;
  ASSERT_TRUE(load_site(at("site_floor.yaml"), &back, &err)) << err;
  EXPECT_NEAR(back.cameras[0].t_site_cam_mm[0], true_pose().x_mm, 5.0);
  EXPECT_NEAR(back.cameras[0].t_site_cam_mm[1], true_pose().y_mm, 5.0);
  EXPECT_NEAR(back.cameras[0].t_site_cam_mm[2], true_pose().z_mm, 10.0);
  EXPECT_EQ(back.floor_map.entries.size(), 7u);  // the floor map is still named
  // A site without a floor map cannot be the survey.
  const std::vector<std::string> b = {
      "ceiling",  "--site",    at("site_true.yaml"),  "--camera", "cam-1",
      "--frames", at("floor"), "--floor-tag-size-mm", "200"};
  const CmdRun none = run(calibrate_ceiling, b);
  EXPECT_EQ(none.rc, 2);
  EXPECT_NE(none.err.find("error no-survey"), std::string::npos) << none.err;
}

}  // namespace
}  // namespace agv::desk
