// agvloc-overhead's configuration (key table, checker, guide), its MQTT message and CSV rows, and
// its input checks (overhead/src, docs/guide/overhead.md).
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <sstream>
#include <string>
#include <vector>

#include "config.hpp"
#include "inputs.hpp"
#include "outputs.hpp"
#include "visualization.hpp"

namespace agv::overhead_app {
namespace {

namespace fs = std::filesystem;

std::vector<std::string> errors_of(const std::string& text) {
  OverheadConfig cfg;
  std::vector<std::string> errors;
  EXPECT_FALSE(parse_config(text, &cfg, &errors)) << text;
  return errors;
}

// Exactly one error, and it contains every part.
void expect_error(const std::string& text, const std::vector<std::string>& parts) {
  const std::vector<std::string> e = errors_of(text);
  ASSERT_EQ(e.size(), 1u) << text;
  for (const std::string& p : parts) EXPECT_NE(e[0].find(p), std::string::npos) << e[0];
}

std::string read_text(const fs::path& p) {
  std::ifstream f(p);
  std::stringstream s;
  s << f.rdbuf();
  return s.str();
}

TEST(OverheadConfig, TableDefaultsAreTheLibraryDefaults) {
  const OverheadConfig defaults;
  for (const Key& k : config_keys()) {
    EXPECT_EQ(format_value(k.get(defaults)), format_value(k.def)) << k.name;
    EXPECT_FALSE(k.doc.empty()) << k.name;
  }
  const overhead::TrackerParams t;
  EXPECT_EQ(defaults.tracker.gate_chi2, t.gate_chi2);
  EXPECT_EQ(defaults.output_rate_hz, 30.0);
  EXPECT_EQ(defaults.mqtt.interface_name, "agvloc-overhead");
}

TEST(OverheadConfig, EveryKeyIsReadAndStoredWhereTheTableSays) {
  for (const Key& k : config_keys()) {
    Value v = k.def;
    if (k.type == KeyType::kNumber) v = k.hi;
    if (k.type == KeyType::kInteger) v = static_cast<std::int64_t>(k.hi);
    if (k.type == KeyType::kBool) v = !std::get<bool>(k.def);
    if (k.type == KeyType::kString) v = std::string("x-1");
    if (k.type == KeyType::kChoice) v = k.choices.front();
    const std::string leaf = k.name.substr(k.name.rfind('.') + 1);
    std::string text, indent;
    std::size_t pos = 0;
    for (std::size_t dot; (dot = k.name.find('.', pos)) != std::string::npos; pos = dot + 1) {
      text += indent + k.name.substr(pos, dot - pos) + ":\n";
      indent += "  ";
    }
    text += indent + leaf + ": " + format_value(v) + "\n";
    if (k.name == "orders.subscribe") text += "tracker:\n  route_prior: true\n";  // needs it
    OverheadConfig cfg;
    std::vector<std::string> errors;
    ASSERT_TRUE(parse_config(text, &cfg, &errors)) << text << (errors.empty() ? "" : errors[0]);
    EXPECT_EQ(format_value(k.get(cfg)), format_value(v)) << k.name;
  }
}

TEST(OverheadConfig, EveryCameraKeyIsReadAndStoredPerCamera) {
  const CameraSettings defaults;
  for (const CameraKey& k : camera_keys()) {
    EXPECT_EQ(format_value(k.get(defaults)), format_value(k.def)) << k.name;
    Value v = k.def;
    if (k.type == KeyType::kNumber) v = k.hi;
    if (k.type == KeyType::kInteger) v = static_cast<std::int64_t>(k.hi);
    if (k.type == KeyType::kString) v = std::string("/dev/video9");
    if (k.type == KeyType::kChoice) v = k.choices.back();
    OverheadConfig cfg;
    std::vector<std::string> errors;
    ASSERT_TRUE(parse_config("cameras:\n  cam-b:\n    " + k.name + ": " + format_value(v) + "\n",
                             &cfg, &errors))
        << k.name << (errors.empty() ? "" : errors[0]);
    ASSERT_EQ(cfg.cameras.size(), 1u);
    EXPECT_EQ(format_value(k.get(cfg.cameras.at("cam-b"))), format_value(v)) << k.name;
  }
}

TEST(OverheadConfig, EmptyTextAndTheShippedFileAreValid) {
  OverheadConfig cfg;
  std::vector<std::string> errors;
  EXPECT_TRUE(parse_config("", &cfg, &errors));
  EXPECT_TRUE(parse_config("# only a comment\n", &cfg, &errors));
  EXPECT_TRUE(load_config(AGV_SOURCE_DIR "/overhead/config/agvloc-overhead.yaml", &cfg, &errors))
      << (errors.empty() ? "" : errors[0]);
  EXPECT_EQ(cfg.output_rate_hz, 30.0);
}

TEST(OverheadConfig, ValuesAndCameraLatencies) {
  OverheadConfig cfg;
  std::vector<std::string> errors;
  ASSERT_TRUE(
      parse_config("tracker:\n  gate_chi2: 20\n  confirm_fixes: 5\noutput:\n  rate_hz: 60\n"
                   "  mqtt: {enabled: true, port: 1884}\ncameras:\n  cam-a:\n"
                   "    latency_ms: 35.5\n",
                   &cfg, &errors));
  EXPECT_EQ(cfg.tracker.gate_chi2, 20.0);
  EXPECT_EQ(cfg.tracker.confirm_fixes, 5);
  EXPECT_EQ(cfg.output_rate_hz, 60.0);
  EXPECT_TRUE(cfg.mqtt.enabled);
  EXPECT_EQ(cfg.mqtt.port, 1884);
  ASSERT_EQ(cfg.cameras.count("cam-a"), 1u);
  EXPECT_EQ(cfg.cameras.at("cam-a").latency_ms, 35.5);
  EXPECT_EQ(cfg.cameras.at("cam-a").driver, "v4l2");
}

TEST(OverheadConfig, ErrorsNameTheKeyAndTheLine) {
  expect_error("tracker:\n  gate_chi:\n    5\n", {"line 3", "tracker.gate_chi", "unknown key"});
  expect_error("output:\n  rate_hz: 30\n  rate_hz: 40\n",
               {"line 3", "output.rate_hz", "duplicate key (first at line 2)"});
  expect_error("output:\n  rate_hz: 0.5\n", {"line 2", "output.rate_hz", "outside", "1..200"});
  expect_error("output:\n  rate_hz: 300\n", {"output.rate_hz", "outside"});
  expect_error("output:\n  rate_hz: fast\n", {"line 2", "output.rate_hz", "expected a number"});
  expect_error("output:\n  rate_hz: .nan\n", {"output.rate_hz", "expected a number"});
  expect_error("tracker:\n  history: 2.5\n", {"tracker.history", "expected an integer"});
  expect_error("output:\n  mqtt:\n    enabled: yes\n",
               {"line 3", "output.mqtt.enabled", "true or false"});
  expect_error("output:\n  mqtt:\n    version: 1.3.0\n",
               {"output.mqtt.version", "not one of", "2.1.0"});
  expect_error("output:\n  mqtt:\n    interface_name: a/b\n",
               {"output.mqtt.interface_name", "topic level"});
  expect_error("orders:\n  subscribe: true\n", {"orders.subscribe", "tracker.route_prior"});
  expect_error("orders:\n  interface_name: uagv/#\n", {"orders.interface_name", "'#'"});
  expect_error("tracker:\n  route:\n    cross_track_sigma_mm: 0\n",
               {"tracker.route.cross_track_sigma_mm", "1..5000"});
  expect_error("cameras:\n  cam-a:\n    latency_ms: 5000\n",
               {"line 3", "cameras.cam-a.latency_ms", "0..1000"});
  expect_error("cameras:\n  cam-a:\n    driver: gige\n",
               {"line 3", "cameras.cam-a.driver", "not one of: v4l2, libcamera"});
  expect_error("cameras:\n  cam-a: 5\n", {"line 2", "cameras.cam-a", "unknown key"});
  expect_error("cameras:\n  cam-a:\n    exposure_ms: 5\n",
               {"cameras.cam-a.exposure_ms", "unknown"});
  expect_error("tracker: [1, 2]\n", {"line 1", "tracker", "list"});
  expect_error("tracker:\n  gate_chi2: [1\n", {"line", "YAML syntax error"});
  expect_error("- a\n", {"top level"});
}

TEST(OverheadConfig, EveryErrorOfTheFileIsReported) {
  EXPECT_EQ(
      errors_of("tracker:\n  nope: 1\nsearch:\n  area_cols: 0\noutput:\n  rate_hz: x\n").size(),
      3u);
}

TEST(OverheadConfig, MissingOrNonRegularFileIsRefused) {
  OverheadConfig cfg;
  std::vector<std::string> errors;
  EXPECT_FALSE(load_config("/nonexistent/agvloc-overhead.yaml", &cfg, &errors));
  ASSERT_EQ(errors.size(), 1u);
  EXPECT_NE(errors[0].find("/nonexistent/agvloc-overhead.yaml"), std::string::npos) << errors[0];
  errors.clear();
  EXPECT_FALSE(load_config("/dev/zero", &cfg, &errors));
  ASSERT_EQ(errors.size(), 1u);
}

// docs/guide/overhead.md carries the key table between its markers, as config-doc prints it.
TEST(OverheadConfig, GuideKeyTableIsTheGeneratedOne) {
  const std::string doc = read_text(AGV_SOURCE_DIR "/docs/guide/overhead.md");
  const std::string begin = "<!-- keys: begin -->\n", end = "<!-- keys: end -->";
  const std::size_t b = doc.find(begin), e = doc.find(end);
  ASSERT_NE(b, std::string::npos);
  ASSERT_NE(e, std::string::npos);
  ASSERT_LT(b, e);
  EXPECT_EQ(doc.substr(b + begin.size(), e - b - begin.size()), config_keys_doc())
      << "regenerate with `agvloc-overhead config-doc` between the markers";
}

overhead::TrackOutput track(overhead::TrackState s, double sigma_mm) {
  overhead::TrackOutput t;
  t.agv = 1;
  t.state = s;
  t.t_ns = 12'000'000'000;
  t.pose = {2500.0, -1250.0, 0.5};
  t.v_mps = 0.8;
  t.omega_radps = -0.1;
  t.sigma_xy_mm = sigma_mm;
  t.sigma_theta_rad = 0.01;
  return t;
}

TEST(OverheadMqtt, VisualizationPerVehicle) {
  MqttOutput cfg;
  cfg.manufacturer = "acme";
  const vda5050::Identity id = identity_of(cfg, "hall-1", "agv-7");
  EXPECT_EQ(vda5050::topic(id, "visualization"), "agvloc-overhead/v2/acme/agv-7/visualization");
  const auto j = nlohmann::json::parse(visualization_json(
      id, 4, 1'795'810'219'123'456'789, track(overhead::TrackState::kConfirmed, 2.0)));
  EXPECT_EQ(j["headerId"], 4);
  EXPECT_EQ(j["serialNumber"], "agv-7");
  EXPECT_EQ(j["manufacturer"], "acme");
  EXPECT_EQ(j["timestamp"], "2026-11-27T20:10:19.123Z");
  const auto& p = j["agvPosition"];
  EXPECT_DOUBLE_EQ(p["x"].get<double>(), 2.5);
  EXPECT_DOUBLE_EQ(p["y"].get<double>(), -1.25);
  EXPECT_DOUBLE_EQ(p["theta"].get<double>(), 0.5);
  EXPECT_EQ(p["mapId"], "hall-1");
  EXPECT_EQ(p["positionInitialized"], true);
  EXPECT_NEAR(p["localizationScore"].get<double>(), 1.0 - 6.0 / 100.0, 1e-9);
  EXPECT_NEAR(p["deviationRange"].get<double>(), 0.006, 1e-12);
  EXPECT_DOUBLE_EQ(j["velocity"]["vx"].get<double>(), 0.8);
  EXPECT_DOUBLE_EQ(j["velocity"]["omega"].get<double>(), -0.1);
}

TEST(OverheadMqtt, CoastingIsCappedAndLostIsNotInitialized) {
  EXPECT_DOUBLE_EQ(position_of(track(overhead::TrackState::kCoasting, 1.0)).localization_score,
                   vda5050::kDeadReckoningScoreCap);
  for (auto s : {overhead::TrackState::kLost, overhead::TrackState::kTentative}) {
    const vda5050::Position p = position_of(track(s, 1.0));
    EXPECT_FALSE(p.initialized);
    EXPECT_EQ(p.localization_score, 0.0);
  }
  EXPECT_EQ(position_of(track(overhead::TrackState::kConfirmed, 40.0)).localization_score, 0.0);
}

std::size_t fields(const std::string& row) {
  return static_cast<std::size_t>(std::count(row.begin(), row.end(), ',')) + 1;
}

TEST(OverheadCsv, RowsHaveTheHeadersColumns) {
  const std::string t = track_row("agv-1", track(overhead::TrackState::kCoasting, 3.0));
  EXPECT_EQ(fields(t), fields(kTracksHeader));
  EXPECT_EQ(
      t, "12000000000,agv-1,2500.000,-1250.000,0.500000,0.8000,-0.10000,3.000,0.010000,coasting");
  site::Site s;
  s.cameras.resize(1);
  s.cameras[0].id = "cam-a";
  s.fleet.resize(1);
  s.fleet[0].id = "agv-1";
  overhead::Detection d;
  d.t_ns = 5;
  d.tag.id = 300;
  EXPECT_EQ(
      detection_row(s, d),
      "cam-a,5,300,,,,,0.000,0.000,0.000,0.000,0.000,0.000,0.000,0.000,0,0,0,full,unknown_id");
  d.in_fleet = true;
  d.has_fix = true;
  d.fix.pose = {1.0, 2.0, 0.25};
  d.result = overhead::FixResult::kGated;
  d.level = overhead::SearchLevel::kTrack;
  d.tag.restricted = true;
  const std::string r = detection_row(s, d);
  EXPECT_EQ(fields(r), fields(kDetectionsHeader));
  EXPECT_NE(r.find("cam-a,5,300,agv-1,1.000,2.000,0.250000,"), std::string::npos) << r;
  EXPECT_NE(r.find(",1,track,gated"), std::string::npos) << r;
  d.has_fix = false;
  EXPECT_EQ(detection_result(d), "no_fix");
}

class OverheadInputs : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() /
           ("overhead_inputs_" + std::to_string(::testing::UnitTest::GetInstance()->random_seed()) +
            "_" + ::testing::UnitTest::GetInstance()->current_test_info()->name());
    fs::remove_all(dir_);
    fs::create_directories(dir_);
  }
  void TearDown() override { fs::remove_all(dir_); }
  void write(const std::string& name, const std::string& text) {
    fs::create_directories((dir_ / name).parent_path());
    std::ofstream(dir_ / name) << text;
  }
  fs::path dir_;
};

constexpr const char* kSiteHead =
    "name: t\noutline_mm: [[0, 0], [4000, 0], [4000, 3000], [0, 3000]]\ncameras:\n"
    "  - id: cam-a\n    intrinsics: {width_px: 64, height_px: 48, fx: 60, fy: 60, cx: 31.5, "
    "cy: 23.5}\n    pose: {x_mm: 2000, y_mm: 1500, z_mm: 3000}\nfleet:\n";

TEST_F(OverheadInputs, SiteWithTwoVehiclesOnOneTagIsRefused) {
  write("site.yaml",
        std::string(kSiteHead) + "  - {id: agv-1, tag_id: 5}\n  - {id: agv-2, tag_id: 5}\n");
  site::Site s;
  std::vector<std::string> errors;
  EXPECT_FALSE(load_site_file((dir_ / "site.yaml").string(), &s, &errors));
  ASSERT_FALSE(errors.empty());
  EXPECT_NE(errors[0].find("tag_id"), std::string::npos) << errors[0];
}

TEST_F(OverheadInputs, MissingCorruptOrEmptySiteIsRefused) {
  site::Site s;
  std::vector<std::string> errors;
  EXPECT_FALSE(load_site_file((dir_ / "none.yaml").string(), &s, &errors));
  ASSERT_EQ(errors.size(), 1u);
  EXPECT_NE(errors[0].find("none.yaml"), std::string::npos) << errors[0];
  write("bad.yaml", "name: [\n");
  errors.clear();
  EXPECT_FALSE(load_site_file((dir_ / "bad.yaml").string(), &s, &errors));
  EXPECT_FALSE(errors.empty());
  write("nofleet.yaml", std::string(kSiteHead) + "  []\n");
  errors.clear();
  EXPECT_FALSE(load_site_file((dir_ / "nofleet.yaml").string(), &s, &errors));
  ASSERT_FALSE(errors.empty());
  EXPECT_NE(errors.back().find("fleet"), std::string::npos) << errors.back();
}

TEST_F(OverheadInputs, RecordingMustNameASiteCamera) {
  write("site.yaml", std::string(kSiteHead) + "  - {id: agv-1, tag_id: 5}\n");
  site::Site s;
  std::vector<std::string> errors;
  ASSERT_TRUE(load_site_file((dir_ / "site.yaml").string(), &s, &errors));
  std::vector<CameraRecording> cams;
  std::vector<std::string> warnings;
  std::string err;
  const OverheadConfig cfg;
  EXPECT_FALSE(open_recordings({(dir_ / "rec").string()}, s, cfg, &cams, &warnings, &err));
  EXPECT_NE(err.find("no such recording folder"), std::string::npos) << err;
  fs::create_directories(dir_ / "rec");
  EXPECT_FALSE(open_recordings({(dir_ / "rec").string()}, s, cfg, &cams, &warnings, &err));
  EXPECT_NE(err.find("camera.yaml"), std::string::npos) << err;
  write("rec/camera.yaml", "id: cam-z\n");
  EXPECT_FALSE(open_recordings({(dir_ / "rec").string()}, s, cfg, &cams, &warnings, &err));
  EXPECT_NE(err.find("camera 'cam-z' is not in the site (its cameras: cam-a)"), std::string::npos)
      << err;
  write("rec/camera.yaml", "id: agv-1-forward\nvehicle: agv-1\n");
  EXPECT_FALSE(open_recordings({(dir_ / "rec").string()}, s, cfg, &cams, &warnings, &err));
  EXPECT_NE(err.find("vehicle"), std::string::npos) << err;
  write("rec/camera.yaml", "id: cam-a\n");
  EXPECT_FALSE(open_recordings({(dir_ / "rec").string()}, s, cfg, &cams, &warnings, &err));
  EXPECT_NE(err.find("meta.yaml"), std::string::npos) << err;
}

TEST_F(OverheadInputs, LatencyOfACameraNotInTheSiteIsRefused) {
  write("site.yaml", std::string(kSiteHead) + "  - {id: agv-1, tag_id: 5}\n");
  site::Site s;
  std::vector<std::string> errors;
  ASSERT_TRUE(load_site_file((dir_ / "site.yaml").string(), &s, &errors));
  OverheadConfig cfg;
  std::string err;
  EXPECT_TRUE(check_config_against_site(cfg, s, &err));
  cfg.cameras["cam-b"].latency_ms = 10.0;
  EXPECT_FALSE(check_config_against_site(cfg, s, &err));
  EXPECT_NE(err.find("cameras.cam-b: no camera 'cam-b'"), std::string::npos) << err;
}

// Tags whose codes are fewer than identity.min_tag_distance bits apart are refused by name;
// tags 1 and 8 are 11 bits apart, 2 and 6 12, 10 and 11 19.
TEST_F(OverheadInputs, FleetTagsTooCloseAreRefused) {
  write("site.yaml", std::string(kSiteHead) +
                         "  - {id: agv-1, tag_id: 1}\n  - {id: agv-2, tag_id: 10}\n"
                         "  - {id: agv-3, tag_id: 8}\n  - {id: agv-4, tag_id: 11}\n");
  site::Site s;
  std::vector<std::string> errors;
  ASSERT_TRUE(load_site_file((dir_ / "site.yaml").string(), &s, &errors));
  OverheadConfig cfg;
  std::string err;
  EXPECT_FALSE(check_config_against_site(cfg, s, &err));
  EXPECT_NE(err.find("identity.min_tag_distance: tags too close: fleet[0] 'agv-1' (tag 1) and "
                     "fleet[2] 'agv-3' (tag 8): codes 11 bits apart, at least 12 required"),
            std::string::npos)
      << err;
  cfg.min_tag_distance = 11;
  EXPECT_TRUE(check_config_against_site(cfg, s, &err)) << err;
  s.fleet[2].tag_id = 6;
  s.fleet[0].tag_id = 2;  // 2 and 6: 12 bits
  cfg.min_tag_distance = 12;
  EXPECT_TRUE(check_config_against_site(cfg, s, &err)) << err;
  cfg.min_tag_distance = 13;
  EXPECT_FALSE(check_config_against_site(cfg, s, &err));
  EXPECT_NE(err.find("(tag 2)"), std::string::npos) << err;
  EXPECT_NE(err.find("12 bits apart, at least 13 required"), std::string::npos) << err;
  // Every pair is counted: ids 0..5 hold several pairs under 16.
  s.fleet.resize(6);
  for (std::uint32_t i = 0; i < 6; ++i) {
    s.fleet[i].id = "a" + std::to_string(i);
    s.fleet[i].tag_id = i;
  }
  cfg.min_tag_distance = 16;
  EXPECT_FALSE(check_config_against_site(cfg, s, &err));
  EXPECT_NE(err.find("more pairs)"), std::string::npos) << err;
  // The key is read from the file, within its range.
  std::vector<std::string> cfg_errors;
  OverheadConfig read;
  ASSERT_TRUE(parse_config("identity:\n  min_tag_distance: 13\n", &read, &cfg_errors));
  EXPECT_EQ(read.min_tag_distance, 13);
  EXPECT_FALSE(parse_config("identity:\n  min_tag_distance: 10\n", &read, &cfg_errors));
}

}  // namespace
}  // namespace agv::overhead_app
