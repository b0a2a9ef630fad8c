// calibrate vehicle on a drive that gives no fix names the likely cause as `agvloc replay` does
// ("a family mismatch gives exit 0 and 0 fixes with no hint"; calibrate vehicle said
// "wrong map, landmark.family (qr) not the printed family, or no mapped landmark in view" whatever
// the frames gave). A short rendered tag36h11 drive: the vehicle standing over tag 7.
#include <gtest/gtest.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include "../support/tag_recording.hpp"
#include "agv/recording/recording.hpp"
#include "commands.hpp"

namespace fs = std::filesystem;
using namespace agv;

namespace {

// A tag36h11 recording over tag 7 (tests/support/tag_recording.hpp) with the family recorded
// as `meta_family`.
fs::path write_tag_drive(const std::string& name, const std::string& meta_family,
                         const CameraModel& truth_camera, const std::string& map_csv) {
  const fs::path d =
      fs::temp_directory_path() / ("agv_test_calib_nofix_" + std::to_string(::getpid()) + name);
  fs::remove_all(d);
  fs::create_directories(d);
  recording::Meta m;
  m.camera = CameraModel::default_640x480();
  m.landmark_family = meta_family;
  std::string err;
  EXPECT_TRUE(testsupport::write_tag_recording(d, m, truth_camera, map_csv, &err)) << err;
  return d;
}

struct CalibRun {
  int rc;
  std::string err;
};

CalibRun calibrate_drive(const fs::path& d, const std::string& config_yaml) {
  std::vector<std::string> args = {
      "vehicle", d.string(), "--map", (d / "map.csv").string(), "--out", (d / "out").string()};
  if (!config_yaml.empty()) {
    std::ofstream(d / "c.yaml", std::ios::trunc) << config_yaml;
    args.push_back("--config");
    args.push_back((d / "c.yaml").string());
  }
  std::vector<char*> argv;
  for (auto& a : args) argv.push_back(a.data());
  testing::internal::CaptureStderr();
  const int rc = desk::calibrate_vehicle(static_cast<int>(argv.size()), argv.data());
  return {rc, testing::internal::GetCapturedStderr()};
}

}  // namespace

// A tag drive calibrated as QR: the family, and where it came from.
TEST(CalibVehicleNoFix, FamilyMismatchNamesTheFamilyAndItsSource) {
  const fs::path d = write_tag_drive("family", "tag36h11", CameraModel::default_640x480(),
                                     "id,x_mm,y_mm,heading_deg\n7,2000.0,1000.0,-90\n");
  // The intrinsics are the recording's (CameraModel::default_640x480).
  const CalibRun r = calibrate_drive(d,
                                     "intrinsics: {fx: 769.23076923076917, fy: 769.23076923076917, "
                                     "cx: 319.5, cy: 239.5}\nlandmark:\n  family: qr\n");
  EXPECT_EQ(r.rc, 1) << r.err;
  EXPECT_NE(r.err.find("no frame of 5 gave a usable fix"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("likely cause: the family: is landmark.family (qr, from --config) the "
                       "family printed on the floor?"),
            std::string::npos)
      << r.err;
  fs::remove_all(d);
}

// meta.yaml's family is used without --config (as replay does), and a map without the tag read
// names the map and the id.
TEST(CalibVehicleNoFix, MapWithoutTheTagNamesTheMapAndTheId) {
  const fs::path d = write_tag_drive("map", "tag36h11", CameraModel::default_640x480(),
                                     "id,x_mm,y_mm,heading_deg\n8,2000.0,1000.0,-90\n");
  const CalibRun r = calibrate_drive(d, "");
  EXPECT_EQ(r.rc, 1) << r.err;
  EXPECT_NE(r.err.find("likely cause: the map: landmarks 7 were read but are not in the map"),
            std::string::npos)
      << r.err;
  fs::remove_all(d);
}

// The camera 12 mm higher than configured (once blamed on the map): the height it implies,
// and that it is set by hand before calibrating.
TEST(CalibVehicleNoFix, HeightOffNamesTheImpliedHeight) {
  CameraModel higher = CameraModel::default_640x480();
  higher.mount.height_mm += 12.0;
  const fs::path d = write_tag_drive("height", "tag36h11", higher,
                                     "id,x_mm,y_mm,heading_deg\n7,2000.0,1000.0,-90\n");
  const CalibRun r = calibrate_drive(d, "");
  EXPECT_EQ(r.rc, 1) << r.err;
  EXPECT_NE(r.err.find("likely cause: the camera height or the print size"), std::string::npos)
      << r.err;
  EXPECT_NE(r.err.find("the camera is about 212 mm above the floor, not mounting.height_mm 200 "
                       "(set mounting.height_mm in --config"),
            std::string::npos)
      << r.err;
  EXPECT_EQ(r.err.find("wrong map"), std::string::npos) << r.err;
  fs::remove_all(d);
}
