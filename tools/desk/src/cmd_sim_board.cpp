// agvloc-desk sim-board: simulated views of a calibration board through a known camera, for
// testing `agvloc-desk calibrate intrinsics` (PNG images + truth.yaml with the true camera).
#include <CLI/CLI.hpp>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>

#include "agv/recording/png_io.hpp"
#include "agv/sim/calib_board.hpp"
#include "calib_cli.hpp"
#include "calib_intrinsics.hpp"
#include "cli_parse.hpp"
#include "commands.hpp"

namespace agv::desk {

namespace calib {

SimBoardSet default_sim_board_set() {
  SimBoardSet s;
  s.camera.width_px = 640;
  s.camera.height_px = 480;
  s.camera.fx = 771.5;
  s.camera.fy = 768.2;
  s.camera.cx = 323.4;
  s.camera.cy = 236.8;
  s.camera.k1 = -0.12;
  s.camera.k2 = 0.08;
  s.camera.p1 = 0.0006;
  s.camera.p2 = -0.0004;
  s.camera.k3 = 0.0;
  return s;
}

bool simulate_board_views(const BoardSpec& spec, const SimBoardSet& set, std::vector<SimView>* out,
                          std::string* error) {
  sim::CalibBoard board;
  const double margin = set.margin_mm >= 0.0
                            ? set.margin_mm
                            : (spec.type == BoardType::kChessboard ? 1.0 : 0.5) * spec.square_mm;
  if (!make_sim_board(spec, margin, &board, error)) return false;
  sim::BoardPoseOptions po;
  po.max_tilt_deg = set.max_tilt_deg;
  po.min_visible = spec.type == BoardType::kChessboard ? 1.0 : 0.7;
  const double side = std::max(spec.squares_x, spec.squares_y) * spec.square_mm;
  // Distances at which the board's longer side spans 85 % .. 45 % of the image width.
  po.near_mm = set.camera.fx * side / (0.85 * set.camera.width_px);
  po.far_mm = set.camera.fx * side / (0.45 * set.camera.width_px);
  const int total = set.views + set.blurred;
  const auto poses = sim::calib_view_poses(board, set.camera, total, set.seed, po);
  if (static_cast<int>(poses.size()) != total) {
    *error = "no board pose keeps the board in view: the board is too large for this camera";
    return false;
  }
  out->clear();
  for (int k = 0; k < total; ++k) {
    SimView v;
    // Blurred views spread evenly through the sequence.
    for (int j = 0; j < set.blurred; ++j) {
      if (k == (j + 1) * total / (set.blurred + 1)) v.blurred = true;
    }
    char name[32];
    std::snprintf(name, sizeof name, "view_%03d.png", k);
    v.name = name;
    sim::BoardImageOptions io;
    io.blur_sigma_px = v.blurred ? set.blurred_sigma_px : set.blur_sigma_px;
    io.noise_sigma = set.noise_sigma;
    io.bow_mm = set.bow_mm;
    io.seed = set.seed * 100003u + static_cast<std::uint64_t>(k);
    v.image = sim::render_board_view(board, set.camera, poses[static_cast<size_t>(k)], io);
    if (v.image.empty()) {
      *error = "the camera cannot render (size or focal length not positive)";
      return false;
    }
    out->push_back(std::move(v));
  }
  return true;
}

Result calibrate_simulated_board(const CameraIntrinsics& camera, int views, double bow_mm,
                                 std::uint64_t seed) {
  BoardSpec spec;
  spec.square_mm = 60.0;
  spec.marker_mm = 45.0;
  SimBoardSet set;
  set.camera = camera;
  set.views = views;
  set.blurred = 0;
  set.bow_mm = bow_mm;
  set.seed = seed;
  std::vector<SimView> sim;
  Result r;
  if (!simulate_board_views(spec, set, &sim, &r.error)) return r;
  const Options options;
  std::vector<View> detected;
  for (const SimView& v : sim) detected.push_back(detect_view(v.image, v.name, spec, options));
  return calibrate(std::move(detected), spec, options);
}

std::string truth_yaml(const SimBoardSet& set, const std::vector<SimView>& views) {
  char buf[1024];
  std::string blurred;
  for (const auto& v : views) {
    if (v.blurred) blurred += " " + v.name;
  }
  const auto& k = set.camera;
  std::snprintf(buf, sizeof buf,
                "# True camera of agvloc-desk sim-board (simulated views).\n"
                "# Deliberately blurred views (sigma %.2f px):%s\n"
                "# Board bowed at its centre: %.3g mm\n"
                "camera:\n  width: %d\n  height: %d\n"
                "intrinsics:\n  fx: %.12g\n  fy: %.12g\n  cx: %.12g\n  cy: %.12g\n"
                "  k1: %.12g\n  k2: %.12g\n  p1: %.12g\n  p2: %.12g\n  k3: %.12g\n",
                set.blurred_sigma_px, blurred.empty() ? " none" : blurred.c_str(), set.bow_mm,
                k.width_px, k.height_px, k.fx, k.fy, k.cx, k.cy, k.k1, k.k2, k.p1, k.p2, k.k3);
  return buf;
}

}  // namespace calib

int sim_board(int argc, char** argv) {
  CLI::App app{
      "Simulated views of a calibration board through a known camera (with distortion): "
      "varied poses covering the image, mild blur and noise, a few deliberately blurred "
      "views. Writes view_NNN.png and truth.yaml (the true camera as a configuration file) "
      "for `agvloc-desk calibrate intrinsics --truth`",
      "agvloc-desk sim-board"};
  calib::SimBoardSet set = calib::default_sim_board_set();
  calib::BoardSpec spec;
  std::string out_dir, board_type = "charuco";
  bool clean = false;
  app.add_option("--out", out_dir, "Directory to write (created)")->required();
  calib::add_board_options(app, &spec, &board_type);
  app.add_option("--views", set.views, "Views of normal sharpness")
      ->check(CLI::Range(1, 1000))
      ->capture_default_str();
  app.add_option("--blurred", set.blurred, "Additional deliberately blurred views")
      ->check(CLI::Range(0, 1000))
      ->capture_default_str();
  app.add_option("--blurred-sigma-px", set.blurred_sigma_px, "Their Gaussian blur")
      ->check(CLI::Range(0.0, 50.0))
      ->capture_default_str();
  app.add_option("--blur-px", set.blur_sigma_px, "Mild Gaussian blur of every other view")
      ->check(CLI::Range(0.0, 50.0))
      ->capture_default_str();
  app.add_option("--noise", set.noise_sigma, "Gaussian sensor noise (8-bit units)")
      ->check(CLI::Range(0.0, 100.0))
      ->capture_default_str();
  app.add_option("--bow-mm", set.bow_mm, "The board bowed this much at its centre (not flat)")
      ->check(CLI::Range(-20.0, 20.0))
      ->capture_default_str();
  app.add_flag("--clean", clean, "No blur and no noise on the normal views");
  app.add_option("--max-tilt-deg", set.max_tilt_deg, "Board tilt range (+-)")
      ->check(CLI::Range(0.0, 60.0))
      ->capture_default_str();
  app.add_option("--seed", set.seed, "Poses and noise")->capture_default_str();
  auto& k = set.camera;
  app.add_option("--width", k.width_px, "True camera: image width")
      ->check(CLI::Range(16, 8192))
      ->capture_default_str();
  app.add_option("--height", k.height_px, "True camera: image height")
      ->check(CLI::Range(16, 8192))
      ->capture_default_str();
  app.add_option("--fx", k.fx, "True camera")->check(CLI::Range(1.0, 1e6))->capture_default_str();
  app.add_option("--fy", k.fy, "True camera")->check(CLI::Range(1.0, 1e6))->capture_default_str();
  app.add_option("--cx", k.cx, "True camera")->capture_default_str();
  app.add_option("--cy", k.cy, "True camera")->capture_default_str();
  app.add_option("--k1", k.k1, "True camera")->capture_default_str();
  app.add_option("--k2", k.k2, "True camera")->capture_default_str();
  app.add_option("--p1", k.p1, "True camera")->capture_default_str();
  app.add_option("--p2", k.p2, "True camera")->capture_default_str();
  app.add_option("--k3", k.k3, "True camera")->capture_default_str();
  if (const int parse_rc = cli::parse(app, argc, argv); parse_rc >= 0) return parse_rc;
  calib::apply_board_type(board_type, &spec);
  if (clean) {
    set.blur_sigma_px = 0.0;
    set.noise_sigma = 0.0;
  }
  const char* who = "agvloc-desk sim-board";
  std::vector<calib::SimView> views;
  std::string error;
  if (!calib::simulate_board_views(spec, set, &views, &error)) {
    std::fprintf(stderr, "%s: %s\n", who, error.c_str());
    return 2;
  }
  std::error_code ec;
  std::filesystem::create_directories(out_dir, ec);
  if (ec) {
    std::fprintf(stderr, "%s: cannot create %s: %s\n", who, out_dir.c_str(), ec.message().c_str());
    return 1;
  }
  for (const auto& v : views) {
    const std::string path = out_dir + "/" + v.name;
    if (!png::write(path, v.image, &error)) {
      std::fprintf(stderr, "%s: %s: %s\n", who, path.c_str(), error.c_str());
      return 1;
    }
  }
  const std::string truth = out_dir + "/truth.yaml";
  std::ofstream f(truth, std::ios::trunc);
  f << calib::truth_yaml(set, views);
  if (!f) {
    std::fprintf(stderr, "%s: cannot write %s\n", who, truth.c_str());
    return 1;
  }
  std::printf("%s: wrote %zu views (%d deliberately blurred) and %s (simulated)\n", who,
              views.size(), set.blurred, truth.c_str());
  return 0;
}

}  // namespace agv::desk
