// agvloc-desk sim-board -> agvloc-desk calibrate intrinsics end to end: the written snippet
// loads as a configuration; too few views exit 1, name the minimum and write nothing.
#include <gtest/gtest.h>

#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>

#include "calib_intrinsics.hpp"
#include "config.hpp"
#include "desk_run.hpp"

namespace {

namespace fs = std::filesystem;

using Out = agv::test::DeskOut;

Out run(const std::string& args) { return agv::test::run_desk(args); }

std::string board_flags() {
  return agv::desk::calib::have_charuco() ? "--board charuco" : "--board chessboard";
}

TEST(CalibCli, SimBoardThenCalibrateWritesALoadableSnippet) {
  const fs::path dir = fs::path(testing::TempDir()) / "calib_cli_ok";
  fs::remove_all(dir);
  const Out sim = run("sim-board --out " + (dir / "views").string() + " " + board_flags() +
                      " --views 12 --blurred 1 --seed 4");
  ASSERT_EQ(sim.code, 0) << sim.text;
  const std::string yaml = (dir / "camera.yaml").string();
  const std::string svg = (dir / "coverage.svg").string();
  const Out cal = run("calibrate intrinsics --images " + (dir / "views").string() + " " +
                      board_flags() + " --min-views 10 --out " + yaml + " --coverage " + svg +
                      " --truth " + (dir / "views" / "truth.yaml").string());
  ASSERT_EQ(cal.code, 0) << cal.text;
  std::printf("%s", cal.text.c_str());
  // The blurred view (index 13 * 1 / 2 = 6) is named with the reason.
  EXPECT_NE(cal.text.find("view_006.png"), std::string::npos);
  EXPECT_NE(cal.text.find("rejected: blurred: edge blur"), std::string::npos) << cal.text;
  EXPECT_NE(cal.text.find("RMS reprojection error"), std::string::npos);
  EXPECT_NE(cal.text.find("recovered vs true"), std::string::npos);
  agv::config::Config cfg, truth;
  std::vector<std::string> errors;
  ASSERT_TRUE(agv::config::load_config(yaml, &cfg, &errors)) << errors.front();
  ASSERT_TRUE(agv::config::load_config((dir / "views" / "truth.yaml").string(), &truth, &errors));
  const auto& e = cfg.camera_model.intrinsics;
  const auto& t = truth.camera_model.intrinsics;
  EXPECT_EQ(e.width_px, t.width_px);
  EXPECT_EQ(e.height_px, t.height_px);
  EXPECT_NEAR(e.fx, t.fx, 0.002 * t.fx);  // 12 views: a looser bound than the 30-view target
  EXPECT_NEAR(e.fy, t.fy, 0.002 * t.fy);
  EXPECT_NEAR(e.cx, t.cx, 1.0);
  EXPECT_NEAR(e.cy, t.cy, 1.0);
  std::ifstream f(svg);
  std::stringstream ss;
  ss << f.rdbuf();
  EXPECT_NE(ss.str().find("<svg"), std::string::npos);
  EXPECT_NE(ss.str().find("<circle"), std::string::npos);
}

TEST(CalibCli, TooFewViewsExitsOneNamesTheMinimumAndWritesNothing) {
  const fs::path dir = fs::path(testing::TempDir()) / "calib_cli_few";
  fs::remove_all(dir);
  const Out sim = run("sim-board --out " + (dir / "views").string() + " " + board_flags() +
                      " --views 5 --blurred 1 --seed 5 --bow-mm 0.4");
  ASSERT_EQ(sim.code, 0) << sim.text;
  std::ifstream truth(dir / "views" / "truth.yaml");
  std::stringstream ts;
  ts << truth.rdbuf();
  EXPECT_NE(ts.str().find("# Board bowed at its centre: 0.4 mm"), std::string::npos) << ts.str();
  const std::string yaml = (dir / "camera.yaml").string();
  const Out cal = run("calibrate intrinsics --images " + (dir / "views").string() + " " +
                      board_flags() + " --out " + yaml);
  EXPECT_EQ(cal.code, 1) << cal.text;
  EXPECT_NE(cal.text.find("only 5 usable view(s) of 6, at least 10 needed (--min-views)"),
            std::string::npos)
      << cal.text;
  EXPECT_FALSE(fs::exists(yaml));
}

TEST(CalibCli, UsageErrorsAreNamed) {
  const fs::path dir = fs::path(testing::TempDir()) / "calib_cli_empty";
  fs::remove_all(dir);
  fs::create_directories(dir);
  // A chessboard, so that builds without OpenCV's aruco module (arm64 cross) reach the checks.
  Out o = run("calibrate intrinsics --board chessboard --images " + dir.string());
  EXPECT_EQ(o.code, 2);
  EXPECT_NE(o.text.find("no .png images"), std::string::npos) << o.text;
  o = run("calibrate intrinsics --board chessboard --images " + (dir / "missing").string());
  EXPECT_EQ(o.code, 2);
  EXPECT_NE(o.text.find("not a directory"), std::string::npos) << o.text;
  o = run("sim-board --out " + (dir / "v").string() + " --bow-mm 25");
  EXPECT_EQ(o.code, 2);
  EXPECT_NE(o.text.find("--bow-mm"), std::string::npos) << o.text;
  o = run("calibrate nonsense");
  EXPECT_EQ(o.code, 2);
  EXPECT_NE(o.text.find("unknown subcommand 'nonsense'"), std::string::npos) << o.text;
  EXPECT_NE(o.text.find("intrinsics"), std::string::npos) << o.text;
}

}  // namespace
