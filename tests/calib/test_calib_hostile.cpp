// calibrate intrinsics on degenerate view sets: messages that say what is wrong.
#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <opencv2/calib3d.hpp>
#include <random>
#include <string>

#include "calib_intrinsics.hpp"

namespace {

using namespace agv::desk::calib;

// Distinct views (shift_px apart), so none is taken for a copy of another.
View fake_view(const std::string& name, cv::Size size, int corners, float shift_px) {
  View v;
  v.name = name;
  v.size = size;
  v.detected = true;
  for (int i = 0; i < corners; ++i) {
    v.ids.push_back(i);
    v.image_points.emplace_back(10.0f + 7.0f * static_cast<float>(i), 20.0f + shift_px);
    v.object_points.emplace_back(10.0f * static_cast<float>(i), 0.0f, 0.0f);
  }
  return v;
}

// A mixed-size folder said "usable 0" with every view of the first size marked "used".
TEST(CalibHostile, MixedSizesUseNoViewAndCountBoth) {
  std::vector<View> views;
  for (int i = 0; i < 3; ++i)
    views.push_back(
        fake_view("a" + std::to_string(i), {640, 480}, 10, 10.0f * static_cast<float>(i)));
  views.push_back(fake_view("b0", {1280, 800}, 10, 50.0f));
  Options o;
  o.min_views = 3;
  BoardSpec spec;
  spec.type = BoardType::kChessboard;
  const Result r = calibrate(views, spec, o);
  EXPECT_FALSE(r.ok);
  EXPECT_EQ(r.usable, 0);
  for (const auto& v : r.views) EXPECT_FALSE(v.used) << v.name;
  EXPECT_NE(r.error.find("3 at 640x480, 1 at other sizes (first: b0 1280x800)"), std::string::npos)
      << r.error;
  EXPECT_EQ(report_text(r).find(" used\n"), std::string::npos) << report_text(r);
}

// OpenCV's standard deviation of a degenerate problem is NaN: printed "cy 245.4 +- -nan".
TEST(CalibHostile, UndeterminedStdDevIsNamedNotNan) {
  Result r;
  r.usable = 12;
  r.rms_px = 117.7;
  r.corners = 100;
  r.stddev[3] = -std::numeric_limits<double>::quiet_NaN();
  const std::string text = report_text(r);
  EXPECT_EQ(text.find("nan"), std::string::npos) << text;
  EXPECT_NE(text.find("+- (undetermined)"), std::string::npos) << text;
}

// An 11 x 8 board description of a 9 x 7 print: the corner ids index the wrong board points, the
// RMS is pixels (117.7 px in the reported case) and the error now names the board options.
TEST(CalibHostile, WrongBoardDescriptionIsNamed) {
  BoardSpec printed, described;
  printed.type = described.type = BoardType::kChessboard;
  printed.squares_x = 9;
  printed.squares_y = 7;
  const cv::Matx33d k(770, 0, 320, 0, 770, 240, 0, 0, 1);
  std::mt19937 rng(5);
  std::uniform_real_distribution<double> tilt(-0.5, 0.5);
  std::vector<View> views;
  for (int n = 0; n < 12; ++n) {
    View v;
    v.name = "view_" + std::to_string(n);
    v.size = {640, 480};
    v.detected = true;
    std::vector<cv::Point3f> obj;
    for (int id = 0; id < 8 * 6; ++id) {
      cv::Point3f p;
      ASSERT_TRUE(board_corner(printed, id, &p));
      obj.push_back(p);
      cv::Point3f wrong;
      ASSERT_TRUE(board_corner(described, id, &wrong));
      v.ids.push_back(id);
      v.object_points.push_back(wrong);
    }
    const cv::Vec3d rvec(tilt(rng), tilt(rng), 0.2 * tilt(rng)), tvec(-45, -35, 200);
    cv::projectPoints(obj, rvec, tvec, k, cv::noArray(), v.image_points);
    views.push_back(v);
  }
  const Result r = calibrate(views, described, Options{});
  EXPECT_FALSE(r.ok);
  EXPECT_GT(r.rms_px, 5.0);
  EXPECT_NE(r.error.find("--squares-x/--squares-y (11 x 8)"), std::string::npos) << r.error;
}

}  // namespace
