// vision_cost RECORDING [--frames N] [--class all|ok|none|free|cut]
//             [--tracking SIGMA_MM --map FILE] [--row-step N] [--repeat N]
// Instruction cost of the vision pipeline (agv::vision::LandmarkLocalizer::process) on the frames
// of a recording, for docs/guide/deployment.md. Frames are decoded first; one warm-up pass
// classifies them by status: ok, or none (any other status), which splits into free (no landmark
// found) and cut (a landmark partly outside the image: not a landmark-free frame, and the costly
// part of none). The measured pass then calls process() once per selected frame, each call
// bracketed twice:
//   - by agv_cost_frame() (never inlined) for `valgrind --tool=callgrind
//     --toggle-collect=agv_cost_frame*`, natively;
//   - by marker system calls (prctl with an invalid option; EINVAL, no effect) for the qemu
//     plugin insn_count_plugin.c, under qemu-aarch64.
// Both count user-space instructions of the same calls. OpenCV runs single-threaded so that the
// count is one core's work. measure.sh runs the whole comparison.
// --tracking SIGMA_MM: every frame gets a prediction (docs/design/tracking.md) from the recording's
// truth moved by a Gaussian error of SIGMA_MM and SIGMA_MM / 10 degrees (fixed seed), with that
// covariance; the search windows need the landmark map (--map).
// --row-step N: VisionConfig::edge_row_step (default: the configuration's default), so two steps
// can be compared with the same binary.
// --repeat N: N - 1 unmarked passes before the measured one, for a native sampling profiler.
#include <sys/prctl.h>

#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <opencv2/core.hpp>
#include <opencv2/core/utility.hpp>
#include <random>
#include <sstream>
#include <string>
#include <vector>

#include "agv/recording/recording.hpp"
#include "agv/vision/landmark_localizer.hpp"

namespace {

constexpr unsigned long kMarkerOn = 0x41475631UL;   // "AGV1"
constexpr unsigned long kMarkerOff = 0x41475630UL;  // "AGV0"

// Truth pose at t_ns, linearly interpolated (false outside the truth's span).
bool truth_at(const std::vector<agv::recording::TruthRow>& truth, std::int64_t t_ns,
              agv::Pose2* out) {
  auto it = std::lower_bound(
      truth.begin(), truth.end(), t_ns,
      [](const agv::recording::TruthRow& r, std::int64_t t) { return r.t_ns < t; });
  if (it == truth.end() || (it == truth.begin() && it->t_ns != t_ns)) return false;
  const auto& b = *it;
  const auto& a = it == truth.begin() ? b : *(it - 1);
  const double f = b.t_ns == a.t_ns
                       ? 0.0
                       : static_cast<double>(t_ns - a.t_ns) / static_cast<double>(b.t_ns - a.t_ns);
  const double ta = agv::deg_to_rad(a.theta_deg);
  const double dth = agv::wrap_angle_rad(agv::deg_to_rad(b.theta_deg) - ta);
  *out = {a.x_mm + f * (b.x_mm - a.x_mm), a.y_mm + f * (b.y_mm - a.y_mm), ta + f * dth};
  return true;
}

}  // namespace

extern "C" __attribute__((noinline)) int agv_cost_frame(agv::vision::LandmarkLocalizer* loc,
                                                        const cv::Mat* gray,
                                                        agv::vision::LandmarkFix* fix) {
  return static_cast<int>(loc->process(*gray, fix));
}

extern "C" __attribute__((noinline)) int agv_cost_frame_tracking(
    agv::vision::LandmarkLocalizer* loc, const cv::Mat* gray, const agv::vision::Prediction* pred,
    agv::vision::LandmarkFix* fix) {
  return static_cast<int>(loc->process(*gray, *pred, fix));
}

namespace {

// The command line.
struct Args {
  std::string dir;
  size_t max_frames = 1000000;
  std::string cls = "all";
  double tracking_sigma_mm = -1.0;  // < 0: no prediction
  std::string map_file;
  int row_step = 0;   // 0: the default
  bool list = false;  // one line per measured frame (how it was read), after the measurement
  int repeat = 1;     // measured passes: more samples for a native sampling profiler (perf)
};

// false with a message on an unknown option or a bad --class.
bool parse_options(int argc, char** argv, Args* a) {
  for (int i = 2; i + 1 < argc; i += 2) {
    if (!std::strcmp(argv[i], "--frames")) {
      a->max_frames = static_cast<size_t>(std::strtoul(argv[i + 1], nullptr, 10));
    } else if (!std::strcmp(argv[i], "--class")) {
      a->cls = argv[i + 1];
    } else if (!std::strcmp(argv[i], "--tracking")) {
      a->tracking_sigma_mm = std::strtod(argv[i + 1], nullptr);
    } else if (!std::strcmp(argv[i], "--row-step")) {
      a->row_step = std::atoi(argv[i + 1]);
    } else if (!std::strcmp(argv[i], "--list")) {
      a->list = std::atoi(argv[i + 1]) != 0;
    } else if (!std::strcmp(argv[i], "--repeat")) {
      a->repeat = std::max(1, std::atoi(argv[i + 1]));
    } else if (!std::strcmp(argv[i], "--map")) {
      a->map_file = argv[i + 1];
    } else {
      std::fprintf(stderr, "vision_cost: unknown option %s\n", argv[i]);
      return false;
    }
  }
  if (a->cls != "all" && a->cls != "ok" && a->cls != "none" && a->cls != "free" &&
      a->cls != "cut") {
    std::fprintf(stderr, "vision_cost: --class must be all, ok, none, free or cut\n");
    return false;
  }
  return true;
}

// The recording's first max_frames frames; false with a message when one cannot be read.
bool load_frames(const agv::recording::Recording& rec, size_t max_frames,
                 std::vector<cv::Mat>* out) {
  std::vector<cv::Mat>& frames = *out;
  std::string err;
  for (size_t i = 0; i < rec.frames.size() && frames.size() < max_frames; ++i) {
    cv::Mat img;
    if (!agv::recording::load_frame(rec, i, &img, &err)) {
      std::fprintf(stderr, "vision_cost: %s\n", err.c_str());
      return false;
    }
    frames.push_back(img);
  }
  return true;
}

// The landmark map of file (none when file is empty); false with a message when unreadable.
bool load_map(const std::string& map_file, agv::LandmarkMap* out) {
  agv::LandmarkMap& map = *out;
  std::string err;
  if (!map_file.empty()) {
    std::ifstream in(map_file);
    std::stringstream text;
    text << in.rdbuf();
    if (!in || !agv::parse_landmark_map(text.str(), &map, &err)) {
      std::fprintf(stderr, "vision_cost: %s: %s\n", map_file.c_str(), err.c_str());
      return false;
    }
  }
  return true;
}

// Per frame, the truth with noise of sigma_mm (and sigma_mm / 10 deg) as the prediction; none
// where the truth does not reach.
std::vector<agv::vision::Prediction> noisy_predictions(const agv::recording::Recording& rec,
                                                       size_t n_frames, double sigma_mm) {
  std::vector<agv::vision::Prediction> preds(n_frames);
  std::mt19937_64 rng(1);
  std::normal_distribution<double> n01(0.0, 1.0);
  const double s = sigma_mm, h = agv::deg_to_rad(sigma_mm / 10.0);
  for (size_t i = 0; i < n_frames; ++i) {
    agv::Pose2 t;
    if (!truth_at(rec.truth, rec.frames[i].t_ns, &t)) continue;
    agv::vision::Prediction& p = preds[i];
    p.valid = true;
    p.vehicle_in_world = {t.x_mm + s * n01(rng), t.y_mm + s * n01(rng), t.theta_rad + h * n01(rng)};
    p.cov = Eigen::Vector3d(s * s, s * s, h * h).asDiagonal();
  }
  return preds;
}

// Warm-up pass: first-call initialisation stays out of the measurement; classifies frames.
// Returns the frames of class cls; *n_ok counts the frames read.
std::vector<size_t> warm_up(agv::vision::LandmarkLocalizer& loc, const std::vector<cv::Mat>& frames,
                            const std::vector<agv::vision::Prediction>& preds,
                            const std::string& cls, size_t* n_ok_out) {
  std::vector<size_t> selected;
  for (size_t i = 0; i < frames.size(); ++i) {
    agv::vision::LandmarkFix fix;
    using agv::vision::FixStatus;
    const FixStatus st = loc.process(frames[i], preds[i], &fix);
    const bool ok = st == FixStatus::kOk;
    *n_ok_out += ok ? 1 : 0;
    const bool take = cls == "all" || (cls == "ok" && ok) || (cls == "none" && !ok) ||
                      (cls == "free" && st == FixStatus::kNoLandmark) ||
                      (cls == "cut" && st == FixStatus::kPartlyOutside);
    if (take) selected.push_back(i);
  }
  return selected;
}

// Counts over the measured frames.
struct Measured {
  size_t ok = 0, window = 0, probed = 0;
};

// The measured pass (after repeat - 1 unmarked ones), between the profiler's markers.
Measured measure(agv::vision::LandmarkLocalizer& loc, std::vector<cv::Mat>& frames,
                 std::vector<agv::vision::Prediction>& preds, const std::vector<size_t>& selected,
                 bool tracking, const Args& a) {
  const int repeat = a.repeat;
  const bool list = a.list;
  size_t n_ok_measured = 0, n_window = 0, n_probed = 0;
  for (int pass = 1; pass < repeat; ++pass) {
    for (size_t i : selected) {
      agv::vision::LandmarkFix fix;
      if (tracking) {
        agv_cost_frame_tracking(&loc, &frames[i], &preds[i], &fix);
      } else {
        agv_cost_frame(&loc, &frames[i], &fix);
      }
    }
  }
  for (size_t i : selected) {
    agv::vision::LandmarkFix fix;
    prctl(static_cast<int>(kMarkerOn), 0UL, 0UL, 0UL, 0UL);
    const int status = tracking ? agv_cost_frame_tracking(&loc, &frames[i], &preds[i], &fix)
                                : agv_cost_frame(&loc, &frames[i], &fix);
    prctl(static_cast<int>(kMarkerOff), 0UL, 0UL, 0UL, 0UL);
    n_ok_measured += status == static_cast<int>(agv::vision::FixStatus::kOk) ? 1 : 0;
    n_window += fix.search == agv::vision::SearchMode::kWindow ? 1 : 0;
    n_probed += fix.detection_probed ? 1 : 0;
    if (list) {
      std::printf(
          "frame %zu: status %d search %d id %u logo %.3f/%.3f qr_method %d verified %d "
          "centre_only %d grid_decodes %d search_attempts %d predicted %d probed %d pose %a %a "
          "%a\n",
          i, status, static_cast<int>(fix.search), fix.landmark_id, fix.logo_score, fix.logo_margin,
          fix.qr_method, fix.qr_verified ? 1 : 0, fix.qr_centre_only ? 1 : 0, fix.qr_grid_decodes,
          fix.qr_search_attempts, fix.detection_predicted ? 1 : 0, fix.detection_probed ? 1 : 0,
          fix.e_x_mm, fix.e_y_mm, fix.e_phi_deg);
    }
  }
  return {n_ok_measured, n_window, n_probed};
}

}  // namespace

int main(int argc, char** argv) {
  if (argc < 2 || argv[1][0] == '-') {
    std::fprintf(stderr,
                 "usage: vision_cost RECORDING [--frames N] [--class all|ok|none|free|cut] "
                 "[--tracking SIGMA_MM --map FILE] [--row-step N] [--list 1]\n");
    return 2;
  }
  Args args;
  args.dir = argv[1];
  if (!parse_options(argc, argv, &args)) return 2;
  const std::string& cls = args.cls;
  cv::setNumThreads(0);

  agv::recording::Recording rec;
  std::string err;
  if (!agv::recording::read_recording(args.dir, &rec, &err)) {
    std::fprintf(stderr, "vision_cost: %s\n", err.c_str());
    return 1;
  }
  std::vector<cv::Mat> frames;
  if (!load_frames(rec, args.max_frames, &frames)) return 1;
  agv::LandmarkGeometry geometry;
  geometry.size_mm = rec.meta.landmark_size_mm;
  agv::vision::VisionConfig cfg;  // defaults, no clock: timings stay 0
  if (args.row_step > 0) cfg.edge_row_step = args.row_step;
  agv::LandmarkMap map;
  if (!load_map(args.map_file, &map)) return 1;
  const bool tracking = args.tracking_sigma_mm >= 0.0;
  if (tracking && (map.entries.empty() || !rec.has_truth)) {
    std::fprintf(stderr, "vision_cost: --tracking needs --map and the recording's truth.csv\n");
    return 2;
  }
  std::vector<agv::vision::Prediction> preds =
      tracking ? noisy_predictions(rec, frames.size(), args.tracking_sigma_mm)
               : std::vector<agv::vision::Prediction>(frames.size());
  agv::vision::LandmarkLocalizer loc(cfg, rec.meta.camera, geometry,
                                     map.entries.empty() ? nullptr : &map);
  size_t n_ok = 0;
  const std::vector<size_t> selected = warm_up(loc, frames, preds, cls, &n_ok);
  const Measured m = measure(loc, frames, preds, selected, tracking, args);
  const size_t n_ok_measured = m.ok, n_window = m.window, n_probed = m.probed;
  std::printf("vision_cost: %zu frames loaded (%zu ok), class %s: %zu measured (%zu ok), %dx%d\n",
              frames.size(), n_ok, cls.c_str(), selected.size(), n_ok_measured,
              frames.empty() ? 0 : frames[0].cols, frames.empty() ? 0 : frames[0].rows);
  if (tracking) {
    std::printf("vision_cost: tracking, %zu found in the window, %zu placed by the edge probes\n",
                n_window, n_probed);
  }
  return selected.empty() ? 1 : 0;
}
