// agvloc-desk render-site end to end on the example site: one recording folder per camera that
// the replay reader accepts, truth that matches the images, and bad input refused with exit 2.
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <map>
#include <opencv2/core.hpp>
#include <sstream>
#include <string>
#include <vector>

#include "../support/desk_command.hpp"
#include "agv/recording/recording.hpp"
#include "commands.hpp"

namespace agv::desk {
namespace {

namespace fs = std::filesystem;

const std::string kSite = AGV_SOURCE_DIR "/tools/maps/example_site.yaml";

int run(std::vector<std::string> args, std::string* err = nullptr) {
  testing::internal::CaptureStderr();
  testing::internal::CaptureStdout();
  const int rc = testsupport::run_command(render_site_command, "render-site", std::move(args));
  testing::internal::GetCapturedStdout();
  const std::string e = testing::internal::GetCapturedStderr();
  if (err) *err = e;
  return rc;
}

struct TruthRow {
  std::string t, object, id;
  double c[8];
  double visible;
};

std::vector<TruthRow> read_truth(const fs::path& file) {
  std::ifstream f(file);
  std::string line;
  std::getline(f, line);
  EXPECT_EQ(line.rfind("t_ns,object,id,", 0), 0u) << file;
  std::vector<TruthRow> rows;
  while (std::getline(f, line)) {
    std::stringstream ss(line);
    std::vector<std::string> cells;
    std::string cell;
    while (std::getline(ss, cell, ',')) cells.push_back(cell);
    EXPECT_EQ(cells.size(), 15u) << line;
    if (cells.size() != 15) continue;
    TruthRow r{cells[0], cells[1], cells[2], {}, std::stod(cells[14])};
    for (int i = 0; i < 8; ++i) r.c[i] = std::stod(cells[6 + i]);
    rows.push_back(r);
  }
  return rows;
}

class RenderCommand : public testing::Test {
 protected:
  static void SetUpTestSuite() {
    dir_ = fs::temp_directory_path() / ("agv_render_command_" + std::to_string(::getpid()));
    fs::remove_all(dir_);
    std::string err;
    rc_ = run({"--site", kSite, "--out", dir_.string(), "--scale", "0.25", "--frames", "3",
               "--vehicle-camera", "agv-2", "--mount", "300,0,1000,0,0,0", "--clutter", "4",
               "--parcel-fraction", "1"},
              &err);
    err_ = err;
  }
  static void TearDownTestSuite() { fs::remove_all(dir_); }
  static fs::path dir_;
  static int rc_;
  static std::string err_;
};
fs::path RenderCommand::dir_;
int RenderCommand::rc_ = -1;
std::string RenderCommand::err_;

TEST_F(RenderCommand, OneReadableRecordingPerCamera) {
  ASSERT_EQ(rc_, 0) << err_;
  for (const char* name : {"ceiling-west", "ceiling-east", "agv-2-forward"}) {
    const fs::path d = dir_ / name;
    for (const char* f : {"meta.yaml", "camera.yaml", "frames.csv", "odom.csv", "site_truth.csv"}) {
      EXPECT_TRUE(fs::is_regular_file(d / f)) << d / f;
    }
    recording::Recording rec;
    std::string err;
    ASSERT_TRUE(recording::read_recording(d.string(), &rec, &err)) << err;
    ASSERT_EQ(rec.frames.size(), 3u) << name;
    EXPECT_EQ(rec.meta.camera.intrinsics.width_px, 320) << name;
    EXPECT_EQ(rec.meta.camera.intrinsics.height_px, 200) << name;
    cv::Mat image;
    ASSERT_TRUE(recording::load_frame(rec, 2, &image, &err)) << err;
    EXPECT_EQ(image.cols, 320);

    // Every frame has a row for each of the 3 vehicles and 7 wall landmarks, at frame times.
    const std::vector<TruthRow> truth = read_truth(d / "site_truth.csv");
    std::map<std::string, int> agvs, walls;
    for (const TruthRow& r : truth) {
      if (r.object == "agv") ++agvs[r.t];
      if (r.object == "wall_landmark") ++walls[r.t];
    }
    ASSERT_EQ(agvs.size(), 3u) << name;
    for (const auto& f : rec.frames) {
      EXPECT_EQ(agvs[std::to_string(f.t_ns)], 3) << name;
      EXPECT_EQ(walls[std::to_string(f.t_ns)], 7) << name;
    }
    EXPECT_EQ(truth.size() % 3, 0u);
  }
  // The vehicle camera's folder has the vehicle's own motion for the same span.
  recording::Recording rec;
  std::string err;
  ASSERT_TRUE(recording::read_recording((dir_ / "agv-2-forward").string(), &rec, &err)) << err;
  ASSERT_TRUE(rec.has_truth);
  EXPECT_GE(rec.odom.size(), 20u);
  EXPECT_LE(rec.truth.front().t_ns, rec.frames.front().t_ns);
  EXPECT_GE(rec.truth.back().t_ns, rec.frames.back().t_ns);
  EXPECT_TRUE(fs::is_regular_file(dir_ / "agv-2-forward" / "camera_poses.csv"));
}

TEST_F(RenderCommand, VisibleTagCornersLieInTheImage) {
  ASSERT_EQ(rc_, 0) << err_;
  int visible = 0;
  for (const char* name : {"ceiling-west", "ceiling-east", "agv-2-forward"}) {
    for (const TruthRow& r : read_truth(dir_ / name / "site_truth.csv")) {
      if ((r.object != "agv" && r.object != "wall_landmark") || !(r.visible > 0.0)) continue;
      ++visible;
      for (int i = 0; i < 4; ++i) {
        EXPECT_GE(r.c[2 * i], -0.5) << name << " " << r.id;
        EXPECT_LE(r.c[2 * i], 319.5) << name << " " << r.id;
        EXPECT_GE(r.c[2 * i + 1], -0.5) << name << " " << r.id;
        EXPECT_LE(r.c[2 * i + 1], 199.5) << name << " " << r.id;
      }
    }
  }
  EXPECT_GT(visible, 0) << "no tag in view in any frame: the check above checked nothing";
}

TEST_F(RenderCommand, SameSeedSameTruth) {
  ASSERT_EQ(rc_, 0) << err_;
  const fs::path again = dir_.string() + "_again";
  fs::remove_all(again);
  ASSERT_EQ(run({"--site", kSite, "--out", again.string(), "--scale", "0.25", "--frames", "3",
                 "--camera", "ceiling-east", "--clutter", "4", "--parcel-fraction", "1"}),
            0);
  auto text = [](const fs::path& p) {
    std::ifstream f(p);
    return std::string(std::istreambuf_iterator<char>(f), {});
  };
  EXPECT_EQ(text(again / "ceiling-east" / "site_truth.csv"),
            text(dir_ / "ceiling-east" / "site_truth.csv"));
  EXPECT_FALSE(fs::exists(again / "ceiling-west"));
  fs::remove_all(again);
}

TEST_F(RenderCommand, BadInputExitsTwoWithTheReason) {
  ASSERT_EQ(rc_, 0) << err_;
  const std::string fresh = (dir_.string() + "_bad");
  fs::remove_all(fresh);
  std::string err;
  EXPECT_EQ(run({"--site", kSite, "--out", fresh, "--camera", "ceiling-north"}, &err), 2);
  EXPECT_NE(err.find("no camera 'ceiling-north'"), std::string::npos) << err;
  EXPECT_NE(err.find("ceiling-west, ceiling-east"), std::string::npos) << err;
  EXPECT_EQ(run({"--site", kSite, "--out", fresh, "--vehicle-camera", "agv-9"}, &err), 2);
  EXPECT_NE(err.find("no AGV 'agv-9'"), std::string::npos) << err;
  EXPECT_EQ(run({"--site", kSite, "--out", fresh, "--vehicle-camera", "agv-1", "--mount",
                 "300,0,1000,0,0"},
                &err),
            2);
  EXPECT_NE(err.find("--mount '300,0,1000,0,0'"), std::string::npos) << err;
  EXPECT_EQ(run({"--site", kSite, "--out", fresh, "--vehicle-camera", "agv-1", "--mount",
                 "300,0,abc,0,0,0"},
                &err),
            2);
  EXPECT_EQ(run({"--site", kSite, "--out", fresh, "--vehicle-camera", "agv-1", "--intrinsics",
                 "320,200,100,100,160,100"},
                &err),
            2);
  EXPECT_NE(err.find("--intrinsics"), std::string::npos) << err;
  EXPECT_FALSE(fs::exists(fresh)) << "nothing written for bad input";
  EXPECT_EQ(run({"--site", kSite, "--out", dir_.string(), "--scale", "0.25"}, &err), 2);
  EXPECT_NE(err.find("is not empty"), std::string::npos) << err;
  EXPECT_EQ(run({"--site", AGV_SOURCE_DIR "/tests/site/data/no_such.yaml", "--out", fresh}, &err),
            2);
}

}  // namespace
}  // namespace agv::desk
