// agvloc-desk calibrate: commissioning calibrations (docs/guide/camera.md). `calibrate intrinsics`
// estimates the camera intrinsics from board images; the other subcommands register below.
#include <CLI/CLI.hpp>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iterator>

#include "calib_cli.hpp"
#include "calib_intrinsics.hpp"
#include "cli_parse.hpp"
#include "commands.hpp"
#include "config.hpp"
#include "desk_input.hpp"
#include "subcommands.hpp"

namespace agv::desk {

#if !AGV_HAVE_CERES
// Built without Ceres (the arm64 cross build): the vehicle calibration is not in this binary.
int calibrate_vehicle(int, char**) {
  std::fprintf(stderr,
               "agvloc-desk calibrate vehicle: not in this build (needs Ceres, Debian "
               "libceres-dev); run it on the desk machine\n");
  return 2;
}
#endif

namespace {

namespace fs = std::filesystem;

// One line per subcommand.
const Subcommand kCalibrateSubcommands[] = {
    {"intrinsics", calibrate_intrinsics,
     "camera intrinsics from images of a ChArUco board or chessboard"},
    {"vehicle", calibrate_vehicle,
     "mounting, odometry and time offset from a calibration drive over mapped landmarks"},
    {"check", calibrate_check, "parked-vehicle check with a printed landmark at a taped pose"},
    {"ceiling", calibrate_ceiling, "a ceiling camera's pose from tags at surveyed positions"},
    {"ceiling-check", calibrate_ceiling_check,
     "the site file's ceiling camera pose checked against tags at surveyed positions"},
    {"ranging-mount", calibrate_ranging_mount,
     "the second camera's mount from a drive past rack landmarks, localized on the floor"},
};
const CommandGroup kCalibrate{"calibrate", kCalibrateSubcommands, std::size(kCalibrateSubcommands)};

}  // namespace

// The top-level usage lists the subcommands from the same table, so none can be left out.
void print_calibrate_subcommands(FILE* f) { print_group_lines(f, kCalibrate); }

namespace {

bool write_text(const std::string& path, const std::string& text) {
  std::ofstream f(path, std::ios::binary | std::ios::trunc);
  f << text;
  return static_cast<bool>(f);
}

// Prints the recovered-vs-true table against a configuration file holding the true camera
// (e.g. truth.yaml of agvloc-desk sim-board).
bool print_truth_table(FILE* out, const std::string& path, const calib::Result& r) {
  config::Config cfg;
  std::vector<std::string> errors;
  if (!config::load_config(path, &cfg, &errors)) {
    for (const auto& e : errors) std::fprintf(stderr, "agvloc-desk calibrate: %s\n", e.c_str());
    return false;
  }
  const auto& t = cfg.camera_model.intrinsics;
  const auto& e = r.intrinsics;
  std::fprintf(out, "recovered vs true (%s):\n", path.c_str());
  std::fprintf(out, "  param      recovered         true        error\n");
  auto row = [&](const char* n, double rec, double tru, bool rel) {
    if (rel) {
      std::fprintf(out, "  %-5s %14.6f %12.6f %+11.4f %%\n", n, rec, tru,
                   100.0 * (rec - tru) / tru);
    } else {
      std::fprintf(out, "  %-5s %14.6f %12.6f %+11.4f\n", n, rec, tru, rec - tru);
    }
  };
  row("fx", e.fx, t.fx, true);
  row("fy", e.fy, t.fy, true);
  row("cx", e.cx, t.cx, false);
  row("cy", e.cy, t.cy, false);
  row("k1", e.k1, t.k1, false);
  row("k2", e.k2, t.k2, false);
  row("p1", e.p1, t.p1, false);
  row("p2", e.p2, t.p2, false);
  row("k3", e.k3, t.k3, false);
  return true;
}

const char* const kIntrinsicsWho = "agvloc-desk calibrate intrinsics";

struct IntrinsicsArgs {
  std::string images, out, coverage, report, truth, board_type = "charuco";
  calib::BoardSpec spec;
  calib::Options opt;
  std::string print_board;
};

// The command line: -1 to go on, else the exit code.
int parse_intrinsics_args(int argc, char** argv, IntrinsicsArgs* a) {
  CLI::App app{
      "Camera intrinsics (fx fy cx cy k1 k2 p1 p2 k3) from PNG images of a ChArUco board or a "
      "chessboard: rejects blurred views by name, reports the RMS reprojection error per view "
      "and the image coverage, writes the camera section of the configuration "
      "(docs/guide/camera.md)",
      "agvloc-desk calibrate intrinsics"};
  calib::Options& opt = a->opt;
  app.add_option("--images", a->images, "Directory of PNG images (all *.png, sorted by name)");
  app.add_option("--print-board", a->print_board,
                 "Write the board as SVG at physical scale (print at 100 %) and exit");
  calib::add_board_options(app, &a->spec, &a->board_type);
  app.add_option("--out", a->out, "Write the configuration snippet here (default: stdout)");
  app.add_option("--coverage", a->coverage, "Write the coverage picture (SVG) here");
  app.add_option("--report", a->report, "Also write the text report here");
  app.add_option("--min-views", opt.min_views, "Fewer usable views: no result")
      ->check(CLI::Range(3, 10000))
      ->capture_default_str();
  app.add_option("--min-corners", opt.min_corners, "Fewer corners in a view: view not used")
      ->check(CLI::Range(4, 100000))
      ->capture_default_str();
  app.add_option("--max-blur-px", opt.max_blur_px,
                 "Reject views whose edge blur (Gaussian sigma estimate) is above this")
      ->check(calib::finite_in(0.1, 100.0))
      ->capture_default_str();
  app.add_option("--max-rms-px", opt.max_rms_px,
                 "No result when the RMS reprojection error is above this")
      ->check(calib::finite_in(0.001, 100.0))
      ->capture_default_str();
  app.add_flag("--fix-k3", opt.fix_k3, "Keep k3 = 0 (narrow lenses)");
  app.add_flag("--zero-tangent", opt.zero_tangent, "Keep p1 = p2 = 0");
  app.add_flag("--fix-aspect", opt.fix_aspect, "Estimate one focal length (fx = fy)");
  app.add_flag("--fix-principal-point", opt.fix_principal_point,
               "Keep the principal point at the image centre");
  app.add_option("--truth", a->truth,
                 "Configuration file with the true intrinsics (simulated images, e.g. "
                 "sim-board's truth.yaml): print recovered vs true");
  return cli::parse(app, argc, argv);
}

// --print-board: the board as SVG; the exit code.
int print_board_svg(const calib::BoardSpec& spec, const std::string& path) {
  const char* who = kIntrinsicsWho;
  std::string error;
  sim::CalibBoard board;
  const double margin = (spec.type == calib::BoardType::kChessboard ? 1.0 : 0.5) * spec.square_mm;
  if (!calib::make_sim_board(spec, margin, &board, &error)) {
    std::fprintf(stderr, "%s: %s\n", who, error.c_str());
    return 2;
  }
  if (!write_text(path, calib::board_svg(spec, board))) {
    std::fprintf(stderr, "%s: cannot write %s\n", who, path.c_str());
    return 1;
  }
  std::printf("%s: wrote %s\n", who, path.c_str());
  return 0;
}

// The PNG images of --images, each detected (or named as unreadable): -1 to go on, else the exit
// code.
int read_views(const IntrinsicsArgs& a, std::vector<calib::View>* views) {
  const char* who = kIntrinsicsWho;
  const std::string& images = a.images;
  std::string error;
  if (images.empty()) {
    std::fprintf(stderr, "%s: --images DIR is required (or --print-board FILE.svg)\n", who);
    return 2;
  }
  std::error_code ec;
  if (!fs::is_directory(images, ec)) {
    std::fprintf(stderr, "%s: --images %s: not a directory\n", who, images.c_str());
    return 2;
  }
  std::vector<fs::path> files;
  std::vector<std::string> skipped;
  if (!input::list_pngs(images, &files, &skipped, &error)) {
    std::fprintf(stderr, "%s: --images %s\n", who, error.c_str());
    return 2;
  }
  // Not regular files (a symlink loop, a FIFO): skipped by name and counted, never read.
  for (const auto& s : skipped) std::fprintf(stderr, "%s: warning: skipped %s\n", who, s.c_str());
  if (!skipped.empty()) {
    std::fprintf(stderr, "%s: warning: %zu .png entr%s of %s skipped (not regular files)\n", who,
                 skipped.size(), skipped.size() == 1 ? "y" : "ies", images.c_str());
  }
  if (files.empty()) {
    std::fprintf(stderr, "%s: %s: no .png images\n", who, images.c_str());
    return 2;
  }
  for (const auto& f : files) {
    cv::Mat gray;
    std::string err;
    if (!input::read_gray(f.string(), &gray, &err)) {
      calib::View v;
      v.name = f.filename().string();
      v.reject_reason = "cannot read: " + err;
      views->push_back(v);
      continue;
    }
    views->push_back(calib::detect_view(gray, f.filename().string(), a.spec, a.opt));
  }
  return -1;
}

// The report, the coverage picture, the truth table and the snippet; the exit code.
int write_intrinsics_outputs(const IntrinsicsArgs& a, const calib::Result& r) {
  const char* who = kIntrinsicsWho;
  // The report goes to stdout when the snippet goes to a file, else to stderr.
  FILE* rep = a.out.empty() ? stderr : stdout;
  const std::string text = calib::report_text(r);
  std::fputs(text.c_str(), rep);
  if (!a.report.empty() && !write_text(a.report, text)) {
    std::fprintf(stderr, "%s: cannot write %s\n", who, a.report.c_str());
    return 1;
  }
  if (!a.coverage.empty() && r.usable > 0) {
    if (!write_text(a.coverage, calib::coverage_svg(r))) {
      std::fprintf(stderr, "%s: cannot write %s\n", who, a.coverage.c_str());
      return 1;
    }
    std::fprintf(rep, "coverage picture: %s\n", a.coverage.c_str());
  }
  if (!r.ok) {
    if (rep != stderr) std::fprintf(stderr, "%s: %s\n", who, r.error.c_str());
    return 1;
  }
  if (!a.truth.empty() && !print_truth_table(rep, a.truth, r)) return 1;
  const std::string snippet = calib::config_snippet(r, a.images);
  if (a.out.empty()) {
    std::fputs(snippet.c_str(), stdout);
  } else {
    if (!write_text(a.out, snippet)) {
      std::fprintf(stderr, "%s: cannot write %s\n", who, a.out.c_str());
      return 1;
    }
    std::fprintf(rep, "wrote %s\n", a.out.c_str());
  }
  return 0;
}

}  // namespace

int calibrate(int argc, char** argv) { return dispatch_group(kCalibrate, argc, argv); }

int calibrate_intrinsics(int argc, char** argv) {
  IntrinsicsArgs a;
  if (const int rc = parse_intrinsics_args(argc, argv, &a); rc >= 0) return rc;
  calib::apply_board_type(a.board_type, &a.spec);
  std::string error;
  if (!calib::validate_board(a.spec, &error)) {
    std::fprintf(stderr, "%s: %s\n", kIntrinsicsWho, error.c_str());
    return 2;
  }
  if (!a.print_board.empty()) return print_board_svg(a.spec, a.print_board);
  std::vector<calib::View> views;
  if (const int rc = read_views(a, &views); rc >= 0) return rc;
  const calib::Result r = calib::calibrate(std::move(views), a.spec, a.opt);
  return write_intrinsics_outputs(a, r);
}

}  // namespace agv::desk
