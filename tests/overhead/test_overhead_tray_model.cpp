// agvloc-overhead's tray.method learned at start (overhead/src/core.cpp): a model file that is
// missing, corrupt or made for another window is named on stderr and the tracker runs on tags
// alone, saying so in its summary; the committed model is taken.
#include <gtest/gtest.h>

#include <fstream>
#include <string>
#include <vector>

#include "config.hpp"
#include "core.hpp"
#include "diag.hpp"
#include "inputs.hpp"
#include "two_camera_site.hpp"

namespace agv::overhead_app {
namespace {

struct Started {
  std::string err, summary;
};

// Builds the tracker with tray.method learned and the given model file, and finishes it at once.
Started start_with(const std::string& model_path) {
  OverheadConfig cfg;
  cfg.tray_method = "learned";
  cfg.tray_model_path = model_path;
  const site::Site site = test::two_camera_site();
  testing::internal::CaptureStderr();
  TrackerCore core(cfg, site);
  Started s;
  s.err = testing::internal::GetCapturedStderr();
  testing::internal::CaptureStdout();
  std::string error;
  EXPECT_TRUE(core.finish("test", site.cameras.size(), &error)) << error;
  s.summary = testing::internal::GetCapturedStdout();
  return s;
}

constexpr const char* kTagsAlone = "tray.method learned unavailable: tracking on tags alone";

TEST(OverheadTrayModel, MissingFileIsNamedAndTagsAlone) {
  const Started s = start_with("/nonexistent/tray.onnx");
  EXPECT_NE(s.err.find("tray.model_path '/nonexistent/tray.onnx': cannot be read"),
            std::string::npos)
      << s.err;
  EXPECT_NE(s.err.find(kTagsAlone), std::string::npos) << s.err;
  EXPECT_NE(s.summary.find("tray boxes (off: model unusable)"), std::string::npos) << s.summary;
  EXPECT_NE(start_with("").err.find("tray.model_path is empty"), std::string::npos);
}

TEST(OverheadTrayModel, CorruptOrWrongSizeModelIsNamedAndTagsAlone) {
  const std::string path = testing::TempDir() + "corrupt_tray.onnx";
  std::ofstream(path, std::ios::binary) << "not a model at all";
  const Started c = start_with(path);
  EXPECT_NE(c.err.find("tray.model_path '" + path + "': tray model: "), std::string::npos) << c.err;
  EXPECT_NE(c.err.find(kTagsAlone), std::string::npos);
  const Started w = start_with(AGV_SOURCE_DIR "/tests/overhead/data/tray_obb_128.onnx");
  EXPECT_NE(w.err.find("input is 1 x 1 x 128 x 128, expected 1 x 1 x 256 x 256"), std::string::npos)
      << w.err;
  EXPECT_NE(w.summary.find("tray boxes (off: model unusable)"), std::string::npos);
}

TEST(OverheadTrayModel, CommittedModelIsTaken) {
  const Started s = start_with(AGV_SOURCE_DIR "/models/tray_obb.onnx");
  if (s.err.find("no dnn module") != std::string::npos) GTEST_SKIP() << "OpenCV without dnn";
  EXPECT_EQ(s.err, "");
  EXPECT_NE(s.summary.find("tray boxes (learned)"), std::string::npos) << s.summary;
  // The default is the classical fit, with no model read.
  OverheadConfig cfg;
  const site::Site site = test::two_camera_site();
  testing::internal::CaptureStderr();
  TrackerCore core(cfg, site);
  EXPECT_EQ(testing::internal::GetCapturedStderr(), "");
}

// The diagnostics view carries the tray boxes with every refusal reason from the start (0 until
// one comes), so that a dashboard's series exist before the first covered tag; none with
// tray.enabled false.
TEST(OverheadTrayModel, DiagViewHasEveryRefusalReasonFromTheStart) {
  const site::Site site = test::two_camera_site();
  OverheadConfig cfg;
  TrackerCore core(cfg, site);
  DiagView v;
  core.fill_tray_diag(&v);
  ASSERT_TRUE(v.has_tray);
  for (const char* reason : {"bad_input", "uncertain_prediction", "out_of_view", "no_outline",
                             "sides_hidden", "size_mismatch", "ambiguous_heading"}) {
    ASSERT_EQ(v.tray.refused.count(reason), 1u) << reason;
    EXPECT_EQ(v.tray.refused.at(reason), 0u) << reason;
  }
  EXPECT_EQ(v.tray.refused.size(), 7u);
  EXPECT_EQ(v.tray.applied, 0u);
  cfg.tray_fit = false;
  TrackerCore off(cfg, site);
  DiagView w;
  off.fill_tray_diag(&w);
  EXPECT_FALSE(w.has_tray);
}

}  // namespace
}  // namespace agv::overhead_app
