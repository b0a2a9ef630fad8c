// `agvloc-desk report` reading the replay's CSV files and evaluating them against truth.
#include <gtest/gtest.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>

#include "report.hpp"

namespace fs = std::filesystem;
using namespace agv;

namespace {

fs::path temp_file(const std::string& name, const std::string& text) {
  const fs::path d = fs::temp_directory_path() / ("agv_report_" + std::to_string(::getpid()));
  fs::create_directories(d);
  std::ofstream(d / name, std::ios::binary) << text;
  return d / name;
}

const char* kPosesHeader =
    "t_ns,valid,health,x_mm,y_mm,theta_deg,v_mps,omega_radps,sigma_x_mm,sigma_y_mm,"
    "sigma_theta_deg,time_since_fix_ms,faults,rejections\n";

}  // namespace

TEST(Report, ReadsPosesCsvAsReplayWritesIt) {
  const auto p = temp_file("poses.csv", std::string(kPosesHeader) +
                                            "10000000000,1,1,100.5000,-2.2500,90.00000,0.5,0,1,1,"
                                            "0.1,42.5,0,0\n"
                                            "9007199254740993,0,0,0,0,0,0,0,0,0,0,-1.0,0,0\n");
  std::vector<desk::PoseRow> rows;
  std::string err;
  ASSERT_TRUE(desk::read_poses_csv(p.string(), &rows, &err)) << err;
  ASSERT_EQ(rows.size(), 2u);
  EXPECT_EQ(rows[0].t_ns, 10'000'000'000);
  EXPECT_TRUE(rows[0].valid);
  EXPECT_DOUBLE_EQ(rows[0].pose.x_mm, 100.5);
  EXPECT_DOUBLE_EQ(rows[0].pose.y_mm, -2.25);
  EXPECT_NEAR(rows[0].pose.theta_rad, M_PI / 2, 1e-12);
  EXPECT_EQ(rows[0].time_since_fix_ns, 42'500'000);
  EXPECT_EQ(rows[0].health, 1);
  EXPECT_DOUBLE_EQ(rows[0].sigma_x_mm, 1.0);
  EXPECT_NEAR(rows[0].sigma_theta_rad, 0.1 * M_PI / 180.0, 1e-12);
  // Integer times above 2^53 stay exact (not parsed through a double).
  EXPECT_EQ(rows[1].t_ns, 9'007'199'254'740'993);
  EXPECT_FALSE(rows[1].valid);
  EXPECT_EQ(rows[1].time_since_fix_ns, -1);
}

TEST(Report, RejectsMalformedFiles) {
  std::vector<desk::PoseRow> rows;
  std::string err;
  EXPECT_FALSE(desk::read_poses_csv(temp_file("h.csv", "t,valid\n1,1\n").string(), &rows, &err));
  EXPECT_NE(err.find("header"), std::string::npos) << err;
  EXPECT_FALSE(desk::read_poses_csv(
      temp_file("short.csv", std::string(kPosesHeader) + "1,1,1,0,0\n").string(), &rows, &err));
  EXPECT_NE(err.find("short.csv:2"), std::string::npos) << err;
  EXPECT_FALSE(desk::read_poses_csv(
      temp_file("nan.csv", std::string(kPosesHeader) + "1,1,1,nan,0,0,0,0,0,0,0,1,0,0\n").string(),
      &rows, &err));
  // A time since fix beyond int64 nanoseconds was read as a large negative time (fuzz_report_csv).
  EXPECT_FALSE(desk::read_poses_csv(
      temp_file("since.csv", std::string(kPosesHeader) + "1,1,0,0,0,0,0,0,0,0,0,1e300,0,0\n")
          .string(),
      &rows, &err));
  EXPECT_NE(err.find("since.csv:2: malformed row"), std::string::npos) << err;
  EXPECT_FALSE(desk::read_poses_csv("/nonexistent/poses.csv", &rows, &err));
}

TEST(Report, KeepsOnlyOkFixes) {
  const auto p =
      temp_file("fixes.csv",
                "t_ns,status,landmark_id,e_x_mm,e_y_mm,e_phi_deg,x_mm,y_mm,theta_deg,sigma_x_mm,"
                "sigma_y_mm,sigma_theta_deg,vision_ms\n"
                "100,ok,3,1,2,3,1000.0000,2000.0000,-90.00000,1,1,0.1,4.2\n"
                "200,no_landmark,0,0,0,0,0,0,0,0,0,0,1.0\n");
  std::vector<desk::FixRow> rows;
  std::string err;
  ASSERT_TRUE(desk::read_fixes_csv(p.string(), &rows, &err)) << err;
  ASSERT_EQ(rows.size(), 1u);
  EXPECT_EQ(rows[0].t_exposure_ns, 100);
  EXPECT_DOUBLE_EQ(rows[0].vehicle_in_world.y_mm, 2000.0);
}

TEST(Report, EvaluatesAgainstInterpolatedTruth) {
  recording::Recording rec;
  rec.has_truth = true;
  rec.truth = {{0, 0.0, 0.0, 0.0}, {1'000'000'000, 1000.0, 0.0, 0.0}};
  // At 0.5 s the truth is x = 500: one tick 3 mm off right after a fix, one 10 mm off later.
  std::vector<desk::PoseRow> ticks = {
      {500'000'000, true, {503.0, 0.0, 0.0}, 10'000'000},
      {600'000'000, true, {610.0, 0.0, 0.0}, 300'000'000},
      {700'000'000, false, {}, -1},
  };
  std::vector<desk::FixRow> fixes = {{250'000'000, {250.0, 4.0, 0.0}}};
  const desk::AccuracySummary a = desk::evaluate(rec, ticks, fixes, nullptr);
  EXPECT_EQ(a.fixes.n, 1u);
  EXPECT_DOUBLE_EQ(a.fixes.pos_max_mm, 4.0);
  EXPECT_EQ(a.at_landmark.n, 1u);
  EXPECT_DOUBLE_EQ(a.at_landmark.pos_max_mm, 3.0);
  EXPECT_EQ(a.between.n, 1u);
  EXPECT_DOUBLE_EQ(a.between.pos_max_mm, 10.0);
  EXPECT_EQ(a.all.n, 2u);
  EXPECT_EQ(a.ticks_invalid, 1u);
}
