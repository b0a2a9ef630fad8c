// agvloc-desk calibrate check: parked-vehicle check of the camera calibration with a printed
// landmark at a taped pose (logic: calib_check.hpp; procedure: docs/guide/commissioning.md).
// Exit 0 within tolerance, 1 out of tolerance, 2 bad input.
#include <CLI/CLI.hpp>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <sstream>

#include "agv/recording/recording.hpp"
#include "calib_check.hpp"
#include "calib_cli.hpp"
#include "cli_parse.hpp"
#include "commands.hpp"
#include "config.hpp"
#include "desk_input.hpp"

namespace agv::desk {

namespace {

namespace fs = std::filesystem;

// Frames of one path: a PNG, or a recording directory (all of its frames). Only listed here:
// each is read when the check reaches it and dropped after (calib::FrameInput::load), so memory
// does not grow with the number of frames.
bool list_frames(const std::string& path, std::vector<desk::calib::FrameInput>* frames,
                 std::string* err) {
  auto frame = [](const std::string& file) {
    desk::calib::FrameInput f;
    f.name = file;
    f.load = [file](cv::Mat* img, std::string* e) {
      if (input::read_gray(file, img, e)) return true;
      *e = "cannot read frame: " + *e;
      return false;
    };
    return f;
  };
  std::error_code ec;
  if (fs::is_directory(path, ec)) {
    recording::Recording rec;
    if (!recording::read_recording(path, &rec, err)) {
      *err = path + ": not a readable recording: " + *err;
      return false;
    }
    if (rec.frames.empty()) {
      *err = path + ": recording has no frames";
      return false;
    }
    for (const auto& f : rec.frames) frames->push_back(frame((fs::path(path) / f.file).string()));
    return true;
  }
  // Checked now, not when the frame is reached: a FIFO or a missing file is a typo to report
  // before minutes of work.
  if (!input::regular_file(path, input::kMaxImageBytes, err)) {
    *err = "cannot read frame: " + *err;
    return false;
  }
  frames->push_back(frame(path));
  return true;
}

}  // namespace

int calibrate_check(int argc, char** argv) {
  CLI::App app{
      "Parked-vehicle check of the camera calibration: one printed landmark at a taped pose "
      "under the parked vehicle; prints the deviation of the measured from the taped pose and "
      "what it points to (mounting offset, yaw, height, distortion, focus). Exit 0 within "
      "tolerance, 1 out of tolerance, 2 bad input (docs/guide/commissioning.md)",
      "agvloc-desk calibrate check"};
  std::string config_path, map_path, pose_text, pose_is = "landmark-in-vehicle", placements_csv;
  std::vector<std::string> inputs;
  double printed_size_mm = 0.0;
  desk::calib::Tolerances tol;
  app.add_option("--config", config_path, "agvloc configuration (camera intrinsics, mounting)")
      ->required();
  app.add_option("frames", inputs, "PNG frames or recording directories of one placement");
  app.add_option("--pose", pose_text,
                 "Taped pose X_MM,Y_MM,HEADING_DEG of the frames' placement (see --pose-is)");
  app.add_option("--pose-is", pose_is,
                 "landmark-in-vehicle (the landmark's pose in the vehicle frame: x forward from "
                 "the reference point, y left) | vehicle-in-world (the vehicle's pose in the "
                 "world; the landmark's from the map)")
      ->capture_default_str();
  app.add_option("--placements", placements_csv,
                 "CSV 'frame,x_mm,y_mm,heading_deg' (header line first): several placements, "
                 "one frame or recording per row, rows with equal poses form one placement; "
                 "paths relative to the CSV");
  app.add_option("--map", map_path, "Landmark map (default: the configuration's landmark.map)");
  app.add_option("--printed-size-mm", printed_size_mm,
                 "Outer side of the print as measured with calipers (default: landmark.size_mm; "
                 "the range of landmark.size_mm)")
      ->check(calib::key_range("landmark.size_mm"));
  // Tolerances: positive and finite (an infinite one would pass anything).
  const auto tol_range = calib::finite_in(1e-6, 1e3);
  const struct {
    const char* flag;
    double* value;
    const char* what;
  } tolerances[] = {
      {"--tol-mm", &tol.position_mm, "Position tolerance"},
      {"--tol-deg", &tol.heading_deg, "Heading tolerance"},
      {"--tol-height-mm", &tol.height_mm, "Height tolerance"},
      {"--tol-spread-mm", &tol.spread_mm, "Spread over the frames of one placement"},
      {"--tol-residual-mm", &tol.residual_mm, "Edge-point rms about the fitted square"},
  };
  for (const auto& t : tolerances)
    app.add_option(t.flag, *t.value, t.what)->check(tol_range)->capture_default_str();
  if (const int parse_rc = cli::parse(app, argc, argv); parse_rc >= 0) return parse_rc;
  auto bad = [](const std::string& msg) {
    std::fprintf(stderr, "agvloc-desk calibrate check: %s\n", msg.c_str());
    return 2;
  };
  if (pose_is != "landmark-in-vehicle" && pose_is != "vehicle-in-world") {
    return bad("--pose-is '" + pose_is + "': landmark-in-vehicle or vehicle-in-world");
  }
  const bool world = pose_is == "vehicle-in-world";
  if (placements_csv.empty() == inputs.empty()) {
    return bad("give the frames (with --pose) or --placements CSV, not both, not neither");
  }
  if (!inputs.empty() && pose_text.empty()) {
    return bad("--pose X_MM,Y_MM,HEADING_DEG missing: the taped pose of the landmark");
  }

  std::string err;
  if (!input::regular_file(config_path, config::kMaxConfigBytes, &err)) {
    return bad("config " + err);
  }
  config::Config cfg;
  if (!config::load_config_or_report(config_path, "agvloc-desk calibrate check", &cfg)) return 2;
  if (map_path.empty()) map_path = cfg.map_file;
  LandmarkMap map;
  if (!map_path.empty() && !config::load_map_file(map_path, &map, &err)) return bad(err);
  if (world && map_path.empty()) {
    return bad("--pose-is vehicle-in-world needs a map (--map or landmark.map in the config)");
  }
  if (printed_size_mm == 0.0) printed_size_mm = cfg.landmark_size_mm;

  // (pose text, paths) per placement, in order of first appearance.
  std::vector<std::pair<Pose2, std::vector<std::string>>> groups;
  if (!inputs.empty()) {
    Pose2 p;
    if (!desk::calib::parse_pose(pose_text, &p))
      return bad("--pose '" + pose_text + "': expected X,Y,DEG");
    groups.push_back({p, inputs});
  } else {
    std::string text;
    if (!recording::read_file_bounded(placements_csv, 1u << 20, &text, &err)) return bad(err);
    std::vector<desk::calib::PlacementRows> rows;
    if (!desk::calib::parse_placements_csv(text, placements_csv, &rows, &err)) return bad(err);
    const fs::path base = fs::path(placements_csv).parent_path();
    for (auto& r : rows) {
      for (std::string& f : r.frames) {
        if (fs::path(f).is_relative()) f = (base / f).string();
      }
      groups.push_back({r.taped, std::move(r.frames)});
    }
  }

  std::vector<desk::calib::PlacementInput> placements(groups.size());
  for (size_t g = 0; g < groups.size(); ++g) {
    for (const std::string& path : groups[g].second) {
      if (!list_frames(path, &placements[g].frames, &err)) return bad(err);
    }
    placements[g].taped = groups[g].first;
    placements[g].taped_is_vehicle_in_world = world;
  }

  desk::calib::CheckResult r;
  if (!desk::calib::run_check(cfg.camera_model, cfg.vision, printed_size_mm,
                              map_path.empty() ? nullptr : &map, placements, tol, &r, &err)) {
    return bad(err);
  }
  std::fputs(desk::calib::format_report(cfg.camera_model, r).c_str(), stdout);
  return r.within_tolerance() ? 0 : 1;
}

}  // namespace agv::desk
