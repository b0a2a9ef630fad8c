// agvloc-desk calibrate check on careless input: a printed size outside the
// configuration's range is refused before the vision stage (inf reached the corner template as
// INT_MIN pixels: segfault), and frames are decoded one at a time (all 1000 frames of a
// recording were kept: 322 MB).
#include <gtest/gtest.h>

#include <limits>
#include <opencv2/core.hpp>
#include <string>
#include <vector>

#include "calib_check.hpp"

using namespace agv;

namespace {

cv::Mat blank() { return cv::Mat(480, 640, CV_8UC1, cv::Scalar(180)); }

TEST(CalibCheckInput, PrintedSizeOutsideTheKeyRangeIsAnError) {
  const cv::Mat frame = blank();
  std::vector<desk::calib::PlacementInput> in(1);
  in[0].frames.push_back({"f", &frame, {}});
  for (double size : {std::numeric_limits<double>::infinity(), 1e308, 1e15, 1e12, 5.0,
                      std::numeric_limits<double>::quiet_NaN()}) {
    desk::calib::CheckResult r;
    std::string err;
    EXPECT_FALSE(desk::calib::run_check(CameraModel::default_640x480(), vision::VisionConfig{},
                                        size, nullptr, in, {}, &r, &err))
        << size;
    EXPECT_NE(err.find("must be in 10..1000 mm (landmark.size_mm)"), std::string::npos)
        << size << ": " << err;
  }
}

// When frame k is loaded, the check holds no reference to frame k - 1 any more.
TEST(CalibCheckInput, FramesAreStreamedOneAtATime) {
  constexpr int kFrames = 6;
  cv::Mat last;  // the test's own reference to the previous frame
  int loads = 0, still_held = 0;
  std::vector<desk::calib::PlacementInput> in(1);
  for (int i = 0; i < kFrames; ++i) {
    desk::calib::FrameInput f;
    f.name = "frame" + std::to_string(i);
    f.load = [&](cv::Mat* img, std::string*) {
      if (!last.empty() && last.u->refcount > 1) ++still_held;
      *img = blank();
      last = *img;
      ++loads;
      return true;
    };
    in[0].frames.push_back(f);
  }
  desk::calib::CheckResult r;
  std::string err;
  // Blank frames: no fix, so an error, but only after every frame was looked at.
  EXPECT_FALSE(desk::calib::run_check(CameraModel::default_640x480(), vision::VisionConfig{}, 60.0,
                                      nullptr, in, {}, &r, &err));
  EXPECT_NE(err.find("no landmark fix in any of its 6 frame(s)"), std::string::npos) << err;
  EXPECT_EQ(loads, kFrames);
  EXPECT_EQ(still_held, 0);
}

// A frame that cannot be read names itself and stops the check.
TEST(CalibCheckInput, UnreadableFrameIsNamed) {
  std::vector<desk::calib::PlacementInput> in(1);
  desk::calib::FrameInput f;
  f.name = "gone.png";
  f.load = [](cv::Mat*, std::string* e) {
    *e = "cannot read frame: gone.png: not found";
    return false;
  };
  in[0].frames.push_back(f);
  desk::calib::CheckResult r;
  std::string err;
  EXPECT_FALSE(desk::calib::run_check(CameraModel::default_640x480(), vision::VisionConfig{}, 60.0,
                                      nullptr, in, {}, &r, &err));
  EXPECT_EQ(err, "cannot read frame: gone.png: not found");
}

}  // namespace

// The --placements CSV reader (fuzz_placements): rows group by pose in order of first appearance;
// a NUL byte (accepted before, the frame path cut at the NUL: "c\0\01.png" read as frame "c") or a
// control character in a path is an error naming the line, as are a bad header, a short row and
// a non-finite pose.
TEST(CalibCheckInput, PlacementsCsvIsParsedStrictly) {
  using agv::desk::calib::PlacementRows;
  std::vector<PlacementRows> rows;
  std::string err;
  ASSERT_TRUE(agv::desk::calib::parse_placements_csv(
      "# "
      "taped\r\nframe,x_mm,y_mm,heading_deg\r\na.png,300,0,0\r\nrec,250,-60,90\r\nb.png,300,0,0\n",
      "p.csv", &rows, &err))
      << err;
  ASSERT_EQ(rows.size(), 2u);
  EXPECT_EQ(rows[0].frames, (std::vector<std::string>{"a.png", "b.png"}));
  EXPECT_EQ(rows[1].frames, (std::vector<std::string>{"rec"}));
  EXPECT_DOUBLE_EQ(rows[1].taped.y_mm, -60.0);
  const std::string header = "frame,x_mm,y_mm,heading_deg\n";
  const std::string nul_path = header + std::string("c\0\0", 3) + "1.png,304,0,0\n";
  EXPECT_FALSE(agv::desk::calib::parse_placements_csv(nul_path, "p.csv", &rows, &err));
  EXPECT_EQ(err, "p.csv:2: NUL byte (not a text file?)");
  EXPECT_FALSE(agv::desk::calib::parse_placements_csv(
      header + std::string("c.png,304,0,0\0junk\n", 19), "p.csv", &rows, &err));
  EXPECT_EQ(err, "p.csv:2: NUL byte (not a text file?)");
  // A CR inside a line (not its end) was kept in the path.
  EXPECT_FALSE(agv::desk::calib::parse_placements_csv(header + "/a\rb.png,58,-60,90.5\n", "p.csv",
                                                      &rows, &err));
  EXPECT_EQ(err, "p.csv:2: control character in the frame path");
  EXPECT_FALSE(agv::desk::calib::parse_placements_csv("frame,x,y,h\n", "p.csv", &rows, &err));
  EXPECT_EQ(err, "p.csv:1: header must be frame,x_mm,y_mm,heading_deg");
  EXPECT_FALSE(
      agv::desk::calib::parse_placements_csv(header + "c.png,1,2\n", "p.csv", &rows, &err));
  EXPECT_EQ(err, "p.csv:2: expected FRAME,X,Y,DEG");
  EXPECT_FALSE(
      agv::desk::calib::parse_placements_csv(header + "c.png,inf,0,0\n", "p.csv", &rows, &err));
  EXPECT_FALSE(agv::desk::calib::parse_placements_csv(header, "p.csv", &rows, &err));
  EXPECT_EQ(err, "p.csv: no rows");
}
