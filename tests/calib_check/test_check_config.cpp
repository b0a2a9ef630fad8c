// --check-config refuses configurations that can never localize, naming the
// key, and names fusion's relations by their configuration keys (not the struct's _ns fields).
#include <gtest/gtest.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include "agv/config/config.hpp"
#include "config.hpp"

// agvloc's `run` (firmware/src/commands.hpp; the desk's commands.hpp comes first on this
// test's include path).
namespace agv::cmd {
int run(int argc, char** argv);
}

namespace {

using agv::config::Config;

const std::string kIntrinsics = "intrinsics: {fx: 769.23, fy: 769.23, cx: 319.5, cy: 239.5}\n";

std::string errors_of(const std::string& yaml) {
  Config cfg;
  std::vector<std::string> errors;
  if (agv::config::parse_config(kIntrinsics + yaml, "", &cfg, &errors)) return "accepted";
  std::string all;
  for (const auto& e : errors) all += e + "\n";
  return all;
}

TEST(CheckConfig, CanInterfaceMustBeALinuxInterfaceName) {
  EXPECT_EQ(errors_of("can: {interface: vcan0}\n"), "accepted");
  EXPECT_EQ(errors_of("can: {interface: abcdefghijklmno}\n"), "accepted");  // 15
  EXPECT_NE(errors_of("can: {interface: abcdefghijklmnop}\n").find("can.interface: 16 characters"),
            std::string::npos);
  EXPECT_NE(errors_of("can: {interface: " + std::string(100000, 'x') + "}\n")
                .find("can.interface: 100000 characters"),
            std::string::npos);
  EXPECT_NE(errors_of("can: {interface: \"can\\0x\"}\n").find("can.interface: contains"),
            std::string::npos);
  EXPECT_NE(errors_of("can: {interface: \"a/b\"}\n").find("can.interface: contains"),
            std::string::npos);
  EXPECT_NE(errors_of("can: {interface: \"\"}\n").find("can.interface: 0 characters"),
            std::string::npos);
}

TEST(CheckConfig, ReplayFixDelayBeyondTheFusionLimitIsRefused) {
  EXPECT_EQ(errors_of("replay: {fix_delay_ms: 500}\n"), "accepted");
  const std::string e = errors_of("replay: {fix_delay_ms: 600}\nfusion: {max_fix_delay_ms: 500}\n");
  EXPECT_NE(e.find("replay.fix_delay_ms: value 600 exceeds fusion.max_fix_delay_ms (500)"),
            std::string::npos)
      << e;
}

TEST(CheckConfig, OdomGapNamedByItsKey) {
  const std::string e = errors_of("fusion: {odom_period_ms: 20, odom_gap_ms: 10}\n");
  EXPECT_NE(e.find("fusion.odom_gap_ms: value 10 must be at least fusion.odom_period_ms (20)"),
            std::string::npos)
      << e;
  EXPECT_EQ(e.find("_ns"), std::string::npos) << e;
}

TEST(CheckConfig, TagFamilyNeedsAMapWithTagIds) {
  Config cfg;
  cfg.vision.family = agv::LandmarkFamily::kTag36h11;
  std::vector<std::string> errors;
  EXPECT_FALSE(agv::config::check_can_localize(cfg, nullptr, &errors));
  ASSERT_EQ(errors.size(), 1u);
  EXPECT_NE(errors[0].find("tag36h11 needs landmark.map"), std::string::npos) << errors[0];

  agv::LandmarkMap map;
  map.entries[5] = {5, {}};
  map.entries[586] = {586, {}};
  errors.clear();
  EXPECT_TRUE(agv::config::check_can_localize(cfg, &map, &errors));
  map.entries[587] = {587, {}};
  map.entries[1000] = {1000, {}};
  EXPECT_FALSE(agv::config::check_can_localize(cfg, &map, &errors));
  ASSERT_EQ(errors.size(), 1u);
  EXPECT_NE(errors[0].find("2 id(s) above 586 (587, 1000)"), std::string::npos) << errors[0];

  // The QR family carries its pose: no map needed, any map id.
  cfg.vision.family = agv::LandmarkFamily::kQr;
  errors.clear();
  EXPECT_TRUE(agv::config::check_can_localize(cfg, nullptr, &errors));
  EXPECT_TRUE(agv::config::check_can_localize(cfg, &map, &errors));
}

// Id 0 is the first tag every generator prints: the map format takes it (it once refused it)
// and the tag family may use it; a QR payload cannot carry it, so the QR family refuses it by name.
TEST(CheckConfig, MapIdZeroIsATagIdOnly) {
  agv::LandmarkMap map;
  std::string err;
  ASSERT_TRUE(
      agv::parse_landmark_map("id,x_mm,y_mm,heading_deg\n0,1000,-2000,90\n7,0,0,0\n", &map, &err))
      << err;
  ASSERT_EQ(map.entries.count(0), 1u);
  EXPECT_EQ(map.find(0)->pose.x_mm, 1000.0);
  EXPECT_FALSE(agv::parse_landmark_map("id,x_mm,y_mm,heading_deg\n-1,0,0,0\n", &map, &err));
  EXPECT_NE(err.find("0..65535"), std::string::npos) << err;

  Config cfg;
  cfg.vision.family = agv::LandmarkFamily::kTag36h11;
  std::vector<std::string> errors;
  EXPECT_TRUE(agv::config::check_can_localize(cfg, &map, &errors));
  EXPECT_TRUE(errors.empty());
  cfg.vision.family = agv::LandmarkFamily::kQr;
  cfg.map_file = "map.csv";
  EXPECT_FALSE(agv::config::check_can_localize(cfg, &map, &errors));
  ASSERT_EQ(errors.size(), 1u);
  EXPECT_NE(errors[0].find("landmark.map map.csv: id 0, which no QR landmark carries"),
            std::string::npos)
      << errors[0];
}

struct CheckRun {
  int rc;
  std::string out, err;
};

CheckRun check_config(const std::string& yaml, const std::string& map_csv) {
  const auto dir =
      std::filesystem::temp_directory_path() / ("agv_test_checkcfg_" + std::to_string(::getpid()));
  std::filesystem::create_directories(dir);
  if (!map_csv.empty()) std::ofstream(dir / "map.csv", std::ios::trunc) << map_csv;
  const std::string path = (dir / "vehicle.yaml").string();
  std::ofstream(path, std::ios::trunc) << yaml;
  std::vector<std::string> args = {"run", "--config", path, "--check-config"};
  std::vector<char*> argv;
  for (auto& a : args) argv.push_back(a.data());
  testing::internal::CaptureStdout();
  testing::internal::CaptureStderr();
  const int rc = agv::cmd::run(static_cast<int>(argv.size()), argv.data());
  CheckRun r{rc, testing::internal::GetCapturedStdout(), testing::internal::GetCapturedStderr()};
  std::filesystem::remove_all(dir);
  return r;
}

// --check-config said only "is valid"; it now says what it checked, so a wrong
// camera, family, map or bus is visible before the service starts.
TEST(CheckConfig, SuccessPrintsWhatWasChecked) {
  const std::string cam = "camera: {driver: v4l2, id: /dev/video7, width: 1280, height: 800}\n";
  const std::string map = "id,x_mm,y_mm,heading_deg\n3,0,0,0\n9,1000,0,90\n12,2000,0,0\n";
  CheckRun r = check_config(kIntrinsics + cam +
                                "landmark: {family: tag36h11, map: map.csv}\n"
                                "can: {interface: can1, odometry: {mode: wheels}}\n"
                                "imu: {source: none}\n",
                            map);
  ASSERT_EQ(r.rc, 0) << r.err;
  EXPECT_NE(r.out.find("is valid; checked:\n"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("  camera: v4l2 id \"/dev/video7\", 1280x800 px at 30 fps"),
            std::string::npos)
      << r.out;
  EXPECT_NE(r.out.find("  intrinsics: fx 769.23, fy 769.23, cx 319.5, cy 239.5 px"),
            std::string::npos)
      << r.out;
  EXPECT_NE(r.out.find("  landmark: family tag36h11, size_mm 60; map "), std::string::npos)
      << r.out;
  EXPECT_NE(r.out.find("map.csv: 3 landmarks (ids 3..12)\n"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("  CAN: can1, base_id 0x300 (standard ids), odometry wheels on 0x310 (E2E "
                       "protected), track_width_mm 500\n"),
            std::string::npos)
      << r.out;
  EXPECT_NE(r.out.find("  imu: source none: wheel odometry only\n"), std::string::npos) << r.out;

  r = check_config(kIntrinsics + cam + "can: {gyro: {enabled: true}}\n", "");
  ASSERT_EQ(r.rc, 0) << r.err;
  EXPECT_NE(r.out.find("  landmark: family qr, size_mm 60; no map (poses from the printed codes)"),
            std::string::npos)
      << r.out;
  EXPECT_NE(r.out.find("  CAN: can0, base_id 0x300 (standard ids), odometry v_omega on 0x311"),
            std::string::npos)
      << r.out;
  EXPECT_NE(r.out.find("  imu: source can, AGV_Gyro on 0x312\n"), std::string::npos) << r.out;

  // Errors as before: no summary.
  r = check_config(kIntrinsics + cam + "landmark: {family: tag36h11}\n", "");
  EXPECT_EQ(r.rc, 2);
  EXPECT_EQ(r.out.find("checked:"), std::string::npos) << r.out;
  EXPECT_NE(r.err.find("tag36h11 needs landmark.map"), std::string::npos) << r.err;
}

}  // namespace
