// eval_overhead: the overhead tracker (agv_overhead) on a simulated fleet under ceiling cameras.
// The fleet simulator drives the vehicles, every camera's frames are rendered (the regions around
// vehicles over a background rendered once), CameraFrameProcessor + FleetTracker run on them in
// arrival order (exposure + each camera's latency), and the outputs at a fixed rate are scored
// against the simulator's truth. Figures: docs/design/overhead.md ("Evaluation").
#include <apriltag/apriltag.h>
#include <apriltag/tag36h11.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <ctime>
#include <fstream>
#include <iterator>
#include <map>
#include <memory>
#include <string>
#include <vector>

#include "agv/overhead/camera_frame.hpp"
#if AGV_EVAL_CALIBRATE
#include "calibrate.hpp"
#endif
#include "metrics.hpp"
#include "trace.hpp"
#include "world.hpp"

namespace {

using agv::eval::World;
using agv::eval::WorldOptions;

struct Options {
  WorldOptions world;
  double fps = 10.0, output_hz = 30.0;
  double calib_error_mm = 0.0, calib_error_deg = 0.0;
  // The pose sigma per parameter the tracker is told (the site file's pose_sigma); < 0: that
  // of the error, error / sqrt(3) per axis (a random direction of that length).
  double calib_sigma_mm = -1.0, calib_sigma_deg = -1.0;
  // --calibrate-tags N: the cameras as this project's calibration solves them from N surveyed
  // tags each (calibrate.hpp), the survey off by --survey-error-mm, the lens from --board-views
  // rendered board views (0: the true lens); replaces the two above.
  agv::eval::CalibrationSetup calib;
  // The trays' departure from level the tracker is told (TrayPlaneSigma): 0 = level trays.
  double tray_tilt_sigma_deg = 0.0, tray_height_sigma_mm = 0.0;
  // --tray-tilt-surveyed: the tracker's fleet has every tray's true tilt (a surveyed site file).
  bool tray_tilt_surveyed = false;
  int bit_errors = 0;
  double bit_errors_from_s = 3.0;
  double latency_ms = 30.0, latency_spread_ms = 20.0;
  int apriltag_every = 0;
  double max_wall_s = 0.0;  // > 0: stop taking frames after this long and score what ran
  int full_sweep_every = agv::overhead::SearchParams{}.full_sweep_every_frames;
  int sweep_max_pixels = agv::overhead::SearchParams{}.sweep_max_pixels;
  int max_decimation = agv::overhead::SearchParams{}.max_decimation;
  bool clean = false;
  bool tray_area_search = false;  // --tray-area-search: SearchParams::tray_box_holds_window false
  // --route-prior: the tracker gets each vehicle's route whenever the simulator starts a task leg
  // (as the fleet manager's order would) and extrapolates coasting tracks along it.
  bool route_prior = false;
  std::string tray_model;  // --tray-model: the learned tray detector instead of the classical fit
  std::string reacquire_model;  // --reacquire-model: re-acquisition of lost covered vehicles
  std::string trace_prefix;     // --trace-prefix: per-tick and per-fix CSVs (trace.hpp)
};

const char* kUsage =
    "usage: eval_overhead [--cameras-height-mm H] [--width W --height H] [--tag-px P]\n"
    "  [--cameras 1|4] [--site-mm L] [--agvs N] [--duration-s S] [--fps F] [--output-hz F]\n"
    "  [--seed S] [--parcels FRACTION] [--load-from-s S] [--cover-tags] [--clutter N]\n"
    "  [--calib-error-mm E] [--calib-error-deg E]\n"
    "  [--calib-sigma-mm S] [--calib-sigma-deg S] [--calibrate-tags N] [--survey-error-mm S]\n"
    "  [--board-views N] [--board-bow-mm B]\n"
    "  [--tray-tilt-deg D] [--tray-height-error-mm E] [--tray-tilt-sigma-deg S]\n"
    "  [--tray-height-sigma-mm S] [--tray-tilt-surveyed]\n"
    "  [--bit-errors N] [--bit-errors-from-s S] [--latency-ms L] [--latency-spread-ms L]\n"
    "  [--full-sweep-every N] [--sweep-max-pixels N] [--max-decimation N] [--apriltag-every N] "
    "[--max-wall-s S] [--no-distortion] [--clean]\n"
    "  [--tray-model ONNX] [--reacquire-model ONNX] [--trace-prefix PATH_PREFIX]\n"
    "  [--route-prior] [--tray-area-search]\n";

bool parse(int argc, char** argv, Options* o, std::string* error) {
  std::map<std::string, double*> num{{"--cameras-height-mm", &o->world.camera_height_mm},
                                     {"--tag-px", &o->world.tag_px},
                                     {"--site-mm", &o->world.site_mm},
                                     {"--duration-s", &o->world.duration_s},
                                     {"--fps", &o->fps},
                                     {"--output-hz", &o->output_hz},
                                     {"--parcels", &o->world.parcels},
                                     {"--load-from-s", &o->world.load_from_s},
                                     {"--calib-error-mm", &o->calib_error_mm},
                                     {"--calib-error-deg", &o->calib_error_deg},
                                     {"--calib-sigma-mm", &o->calib_sigma_mm},
                                     {"--calib-sigma-deg", &o->calib_sigma_deg},
                                     {"--survey-error-mm", &o->calib.survey_error_mm},
                                     {"--board-bow-mm", &o->calib.board_bow_mm},
                                     {"--tray-tilt-deg", &o->world.tray_tilt_deg},
                                     {"--tray-height-error-mm", &o->world.tray_height_error_mm},
                                     {"--tray-tilt-sigma-deg", &o->tray_tilt_sigma_deg},
                                     {"--tray-height-sigma-mm", &o->tray_height_sigma_mm},
                                     {"--bit-errors-from-s", &o->bit_errors_from_s},
                                     {"--latency-ms", &o->latency_ms},
                                     {"--latency-spread-ms", &o->latency_spread_ms},
                                     {"--max-wall-s", &o->max_wall_s}};
  std::map<std::string, int*> ints{{"--width", &o->world.width_px},
                                   {"--height", &o->world.height_px},
                                   {"--cameras", &o->world.cameras},
                                   {"--agvs", &o->world.agvs},
                                   {"--clutter", &o->world.clutter},
                                   {"--bit-errors", &o->bit_errors},
                                   {"--calibrate-tags", &o->calib.tags},
                                   {"--board-views", &o->calib.board_views},
                                   {"--apriltag-every", &o->apriltag_every},
                                   {"--full-sweep-every", &o->full_sweep_every},
                                   {"--sweep-max-pixels", &o->sweep_max_pixels},
                                   {"--max-decimation", &o->max_decimation}};
  std::map<std::string, bool*> flags{{"--clean", &o->clean},
                                     {"--cover-tags", &o->world.cover_tags},
                                     {"--route-prior", &o->route_prior},
                                     {"--tray-area-search", &o->tray_area_search},
                                     {"--tray-tilt-surveyed", &o->tray_tilt_surveyed}};
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    if (flags.count(a)) {
      *flags[a] = true;
      continue;
    }
    if (a == "--no-distortion") {
      o->world.k1 = o->world.k2 = 0.0;
      continue;
    }
    if (i + 1 >= argc) return *error = a + ": unknown option or missing value", false;
    char* end = nullptr;
    const std::string v = argv[++i];
    if (a == "--tray-model") {
      o->tray_model = v;
      continue;
    }
    if (a == "--reacquire-model") {
      o->reacquire_model = v;
      continue;
    }
    if (a == "--trace-prefix") {
      o->trace_prefix = v;
      continue;
    }
    if (a == "--seed") {
      o->world.seed = std::strtoull(v.c_str(), &end, 10);
    } else if (num.count(a)) {
      *num[a] = std::strtod(v.c_str(), &end);
    } else if (ints.count(a)) {
      *ints[a] = static_cast<int>(std::strtol(v.c_str(), &end, 10));
    } else {
      return *error = a + ": unknown option", false;
    }
    if (end == v.c_str() || *end != '\0') return *error = a + ": not a number: " + v, false;
  }
  const WorldOptions& w = o->world;
  if (w.camera_height_mm < 1500 || w.width_px < 64 || w.height_px < 64 || w.tag_px < 8 ||
      (w.cameras != 1 && w.cameras != 4) || w.site_mm < 3000 || w.agvs < 1 || w.agvs > 500 ||
      w.duration_s <= 0 || o->fps <= 0 || o->fps > 120 || o->output_hz <= 0 || w.parcels < 0 ||
      w.parcels > 1 || w.clutter < 0 || o->bit_errors < 0 || o->bit_errors > 36 ||
      o->latency_ms < 0 || o->latency_spread_ms < 0 || o->full_sweep_every < 1 ||
      o->sweep_max_pixels < 0 || o->max_decimation < 1 || o->max_decimation > 8 ||
      !(w.tray_tilt_deg >= 0 && w.tray_tilt_deg < 30) || !(w.tray_height_error_mm >= 0) ||
      !(o->tray_tilt_sigma_deg >= 0 && o->tray_tilt_sigma_deg < 30) ||
      !(o->tray_height_sigma_mm >= 0) ||
      (o->calib.tags != 0 && (o->calib.tags < 3 || o->calib.tags > 100)) ||
      !(o->calib.survey_error_mm >= 0 && o->calib.survey_error_mm < 1000) ||
      o->calib.board_views < 0 || (o->calib.board_views > 0 && o->calib.board_views < 10) ||
      !(std::abs(o->calib.board_bow_mm) < 20)) {
    return *error = "an option is out of range", false;
  }
  return true;
}

// CPU time of this thread (ms): the pipeline's cost on one core, whatever else the machine runs.
double thread_cpu_ms() {
  timespec ts{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
  return 1e3 * static_cast<double>(ts.tv_sec) + 1e-6 * static_cast<double>(ts.tv_nsec);
}

double apriltag_full_frame_ms(const cv::Mat& gray) {
  apriltag_family_t* tf = tag36h11_create();
  apriltag_detector_t* td = apriltag_detector_create();
  apriltag_detector_add_family_bits(td, tf, 2);
  td->quad_decimate = 1.0f;
  td->nthreads = 1;
  image_u8_t im{gray.cols, gray.rows, static_cast<int>(gray.step), gray.data};
  const double t0 = thread_cpu_ms();
  zarray_t* dets = apriltag_detector_detect(td, &im);
  const double t1 = thread_cpu_ms();
  apriltag_detections_destroy(dets);
  apriltag_detector_destroy(td);
  tag36h11_destroy(tf);
  return t1 - t0;
}

struct FrameEvent {
  std::int64_t arrival_ns = 0, exposure_ns = 0;
  std::size_t camera = 0;
};

std::vector<FrameEvent> frame_events(const Options& o, std::size_t cameras) {
  std::vector<FrameEvent> ev;
  const double period_ns = 1e9 / o.fps;
  const auto end_ns = static_cast<std::int64_t>(o.world.duration_s * 1e9);
  for (std::size_t c = 0; c < cameras; ++c) {
    // Free-running cameras: exposures staggered across the period, latencies spread over the
    // cameras, so fixes reach the tracker out of exposure order.
    const double offset = period_ns * static_cast<double>(c) / static_cast<double>(cameras);
    const double lat = o.latency_ms + (cameras > 1 ? o.latency_spread_ms * static_cast<double>(c) /
                                                         static_cast<double>(cameras - 1)
                                                   : 0.0);
    for (int k = 0;; ++k) {
      const auto t = static_cast<std::int64_t>(offset + k * period_ns);
      if (t > end_ns) break;
      ev.push_back({t + static_cast<std::int64_t>(lat * 1e6), t, c});
    }
  }
  std::sort(ev.begin(), ev.end(), [](const FrameEvent& a, const FrameEvent& b) {
    return a.arrival_ns != b.arrival_ns ? a.arrival_ns < b.arrival_ns : a.camera < b.camera;
  });
  return ev;
}

// Tags wholly inside the image (2 px in).
std::vector<std::uint8_t> inside(const std::vector<std::array<agv::Vec2, 4>>& corners,
                                 const std::vector<std::uint8_t>& ok, int w, int h) {
  std::vector<std::uint8_t> in(corners.size(), 0);
  for (std::size_t i = 0; i < corners.size(); ++i) {
    bool all = ok[i] != 0;
    for (const agv::Vec2& c : corners[i])
      all = all && c.x >= 2 && c.y >= 2 && c.x < w - 2 && c.y < h - 2;
    in[i] = all ? 1 : 0;
  }
  return in;
}

void print_header(const Options& o, const agv::site::Site& site) {
  const agv::CameraIntrinsics& k = site.cameras[0].intrinsics;
  std::printf(
      "eval_overhead (simulated, rendered frames): site %.0f x %.0f mm, %zu camera(s) at "
      "%.0f mm, %dx%d, fx %.1f px (tag %.0f px at tray height), %d AGVs, %.1f s at %.1f fps, "
      "seed %llu, parcels %.2f (%s%s), clutter %d, calibration error %.1f mm / %.2f deg, bit "
      "errors %d from %.1f s, latency %.0f..%.0f ms, full sweep every %d frames%s%s\n",
      o.world.site_mm, o.world.site_mm, site.cameras.size(), o.world.camera_height_mm, k.width_px,
      k.height_px, k.fx, o.world.tag_px, o.world.agvs, o.world.duration_s, o.fps,
      static_cast<unsigned long long>(o.world.seed), o.world.parcels,
      o.world.load_from_s >= 0.0 ? "loaded during the run" : "loaded from the start",
      o.world.cover_tags ? ", over the tags" : "", o.world.clutter, o.calib_error_mm,
      o.calib_error_deg, o.bit_errors, o.bit_errors_from_s, o.latency_ms,
      o.latency_ms + o.latency_spread_ms, o.full_sweep_every, o.clean ? ", clean" : "",
      o.route_prior ? ", route prior" : "");
  std::printf(
      "  trays: tilted %.2f deg, tags up to %.1f mm off their height; the tracker told "
      "%.2f deg / %.1f mm%s\n",
      o.world.tray_tilt_deg, o.world.tray_height_error_mm, o.tray_tilt_sigma_deg,
      o.tray_height_sigma_mm, o.tray_tilt_surveyed ? ", and every tray's tilt" : "");
  for (const auto& c : site.cameras) {
    std::printf("  camera %s at (%.0f, %.0f, %.0f) mm\n", c.id.c_str(), c.t_site_cam_mm[0],
                c.t_site_cam_mm[1], c.t_site_cam_mm[2]);
  }
}

void print_counters(const agv::overhead::FrameCounters& fc,
                    const agv::overhead::TrackerCounters& tc) {
  using ull = unsigned long long;
  std::printf(
      "pipeline: frames %llu, windows track/area/full %llu/%llu/%llu (not searched %llu), "
      "predicted reads %llu, searched tags %llu, unknown ids %llu, no fix %llu; tracker: "
      "applied %llu, started %llu, gated %llu, too old %llu, replays %llu, lost %llu\n",
      ull(fc.frames), ull(fc.windows_track), ull(fc.windows_area), ull(fc.windows_full),
      ull(fc.windows_skipped), ull(fc.predicted_reads), ull(fc.searched_tags), ull(fc.unknown_ids),
      ull(fc.no_fix), ull(tc.applied), ull(tc.started), ull(tc.gated), ull(tc.too_old),
      ull(tc.replays), ull(tc.lost));
}

// The cameras as this project's calibration solves them (calibrate.hpp); false with *error.
bool calibrated_cameras(const Options& o, const agv::site::Site& site,
                        std::vector<agv::site::CeilingCamera>* out, std::string* error) {
#if AGV_EVAL_CALIBRATE
  agv::eval::CalibrationSetup setup = o.calib;
  setup.seed = o.world.seed * 131;
  return agv::eval::calibrated_cameras(site, setup, out, error);
#else
  (void)o, (void)site, (void)out;
  return *error = "--calibrate-tags: this build has no desk library (agv_desk)", false;
#endif
}

// The tracker's idea of the cameras: the rendered ones moved by the calibration error, with
// the pose sigma a calibration would state.
std::vector<agv::site::CeilingCamera> believed_cameras(const Options& o,
                                                       const agv::site::Site& site,
                                                       std::mt19937_64* rng) {
  std::vector<agv::site::CeilingCamera> believed;
  const double sigma_mm =
      o.calib_sigma_mm >= 0 ? o.calib_sigma_mm : o.calib_error_mm / std::sqrt(3.0);
  const double sigma_rad = agv::deg_to_rad(
      o.calib_sigma_deg >= 0 ? o.calib_sigma_deg : o.calib_error_deg / std::sqrt(3.0));
  std::printf("tracker told: camera pose sigma %.3f mm, %.4f deg per parameter\n", sigma_mm,
              agv::rad_to_deg(sigma_rad));
  for (const auto& c : site.cameras) {
    believed.push_back(agv::eval::perturbed(c, o.calib_error_mm, o.calib_error_deg, rng));
    believed.back().position_sigma_mm = {sigma_mm, sigma_mm, sigma_mm};
    believed.back().angle_sigma_rad = {sigma_rad, sigma_rad, sigma_rad};
  }
  return believed;
}

// The learned tray detector from an ONNX file; false with a message when it cannot be loaded.
bool load_tray_model(const std::string& path, agv::overhead::CameraFrameProcessor* proc,
                     bool reacquire) {
  std::ifstream f(path, std::ios::binary);
  const std::string bytes((std::istreambuf_iterator<char>(f)), std::istreambuf_iterator<char>());
  auto net = std::make_shared<agv::overhead::TrayNet>();
  std::string why;
  if (!net->load(bytes.data(), bytes.size(), &why)) {
    std::fprintf(stderr, "eval_overhead: %s: %s\n", path.c_str(), why.c_str());
    return false;
  }
  if (reacquire) {
    proc->set_reacquire(std::move(net));
  } else {
    proc->set_tray_net(std::move(net));
  }
  return true;
}

// Every camera's view of the site without vehicles and parcels, rendered once.
void set_backgrounds(const Options& o, const World& world, agv::eval::RegionRenderer* renderer) {
  const agv::site::Site& site = world.site();
  agv::sim::SiteScene empty = world.scene_at(0);
  empty.site.fleet.clear();
  empty.agvs.clear();
  empty.parcels.clear();
  for (std::size_t c = 0; c < site.cameras.size(); ++c) {
    renderer->set_background(c, empty, agv::sim::RenderCamera::from_ceiling(site.cameras[c]),
                             o.world.seed + c);
  }
}

// Bit errors put into the tags in the image from bit_errors_from_s on; 1 for each tag changed.
std::vector<std::uint8_t> flip_bits(const Options& o, const FrameEvent& fe,
                                    const std::vector<std::array<agv::Vec2, 4>>& corners,
                                    const std::vector<std::uint8_t>& in_image, cv::Mat* img,
                                    std::mt19937_64* rng) {
  std::vector<std::uint8_t> flipped(corners.size(), 0);
  if (o.bit_errors > 0 && fe.exposure_ns >= static_cast<std::int64_t>(o.bit_errors_from_s * 1e9)) {
    for (std::size_t i = 0; i < corners.size(); ++i) {
      if (in_image[i] && agv::eval::flip_tag_cells(img, corners[i], o.bit_errors, rng) > 0) {
        flipped[i] = 1;
      }
    }
  }
  return flipped;
}

// 1 for each vehicle whose tag is inside some camera's image.
std::vector<std::uint8_t> in_some_view(const World& world,
                                       const std::vector<agv::sim::AgvState>& truth) {
  const agv::site::Site& site = world.site();
  const agv::CameraIntrinsics& k = site.cameras[0].intrinsics;
  std::vector<std::uint8_t> in_view(truth.size(), 0);
  for (const auto& c : site.cameras) {
    std::vector<std::uint8_t> ok;
    const auto corners = world.tag_corners(agv::sim::RenderCamera::from_ceiling(c), truth, &ok);
    const auto in = inside(corners, ok, k.width_px, k.height_px);
    for (std::size_t i = 0; i < in.size(); ++i) in_view[i] = in_view[i] || in[i];
  }
  return in_view;
}

// 1 for each vehicle the tracker follows at t_ns.
std::vector<std::uint8_t> tracked_at(const agv::overhead::FleetTracker& tracker, std::size_t n,
                                     std::int64_t t_ns) {
  std::vector<std::uint8_t> tracked(n, 0);
  for (std::size_t i = 0; i < tracked.size(); ++i) {
    const agv::overhead::TrackState st = tracker.output(i, t_ns).state;
    tracked[i] = st != agv::overhead::TrackState::kNone && st != agv::overhead::TrackState::kLost;
  }
  return tracked;
}

// One frame through the processor, its thread CPU time recorded (apart for frames with a full
// sweep); false with a message on error.
bool process_timed(const FrameEvent& fe, const cv::Mat& img,
                   agv::overhead::CameraFrameProcessor* proc, agv::overhead::FleetTracker* tracker,
                   std::vector<agv::overhead::Detection>* dets, agv::eval::Score* score) {
  std::string error;
  const std::uint64_t full_before = proc->counters().windows_full;
  const double t0 = thread_cpu_ms();
  if (!proc->process(fe.camera, fe.exposure_ns, img, tracker, dets, &error)) {
    std::fprintf(stderr, "eval_overhead: %s\n", error.c_str());
    return false;
  }
  const double ms = thread_cpu_ms() - t0;
  score->frame_ms.push_back(ms);
  if (proc->counters().windows_full > full_before) {
    score->frame_full_ms.push_back(ms);
  } else {
    score->frame_windows_ms.push_back(ms);
  }
  return true;
}

void print_tray_boxes(const agv::overhead::CameraFrameProcessor& proc) {
  std::printf(
      "tray boxes (%s): applied %llu, gated %llu, refused %llu, disagreeing with a tag %llu\n",
      proc.tray_learned() ? "learned" : "classical",
      static_cast<unsigned long long>(proc.counters().tray_fixes),
      static_cast<unsigned long long>(proc.counters().tray_gated),
      static_cast<unsigned long long>(proc.counters().tray_refused),
      static_cast<unsigned long long>(proc.counters().tray_tag_disagree));
  const agv::overhead::FrameCounters& c = proc.counters();
  std::printf("tray boxes refused by reason:");
  for (std::size_t r = 1; r < agv::overhead::kTrayRefusalCount; ++r) {
    std::printf(" %s %llu", agv::overhead::to_string(static_cast<agv::overhead::TrayRefusal>(r)),
                static_cast<unsigned long long>(c.tray_refused_by[r]));
  }
  std::printf("\n");
  std::printf(
      "re-acquisition (%s): sweeps %llu, detector windows %llu, tracks restarted %llu, "
      "ambiguous boxes %llu, half turn unknown %llu\n",
      proc.reacquiring() ? "on" : "off", static_cast<unsigned long long>(c.reacquire_sweeps),
      static_cast<unsigned long long>(c.reacquire_windows),
      static_cast<unsigned long long>(c.reacquired),
      static_cast<unsigned long long>(c.reacquire_ambiguous),
      static_cast<unsigned long long>(c.reacquire_heading_unknown));
}

// The routes the simulator gave, handed to the tracker as their times pass (the fleet manager's
// orders as they arrive).
struct RouteFeed {
  std::vector<agv::eval::RouteEvent> events;
  std::size_t next = 0, refused = 0;
  void give(std::int64_t t_ns, agv::overhead::FleetTracker* tracker) {
    for (; next < events.size() && events[next].t_ns <= t_ns; ++next) {
      const agv::eval::RouteEvent& r = events[next];
      std::string why;
      if (!tracker->set_route(r.agv, r.waypoints_mm, r.t_ns, &why)) {
        std::fprintf(stderr, "eval_overhead: route of vehicle %zu refused: %s\n", r.agv,
                     why.c_str());
        ++refused;
      }
    }
  }
};

agv::overhead::SearchParams search_params(const Options& o) {
  agv::overhead::SearchParams sp;
  sp.full_sweep_every_frames = o.full_sweep_every;
  sp.sweep_max_pixels = o.sweep_max_pixels;
  sp.max_decimation = o.max_decimation;
  sp.tray_box_holds_window = !o.tray_area_search;
  return sp;
}

// The fleet as the tracker is told it: each tray's tilt when it was surveyed.
std::vector<agv::site::FleetAgv> told_fleet(const Options& o, const World& world) {
  std::vector<agv::site::FleetAgv> fleet = world.site().fleet;
  for (std::size_t i = 0; o.tray_tilt_surveyed && i < fleet.size(); ++i) {
    fleet[i].tray_roll_rad = world.tray_roll_rad[i];
    fleet[i].tray_pitch_rad = world.tray_pitch_rad[i];
  }
  return fleet;
}

int run(const Options& o) {
  const auto wall0 = std::chrono::steady_clock::now();
  World world;
  std::string error;
  if (!world.build(o.world, &error)) {
    std::fprintf(stderr, "eval_overhead: %s\n", error.c_str());
    return 2;
  }
  const agv::site::Site& site = world.site();
  const agv::CameraIntrinsics& k = site.cameras[0].intrinsics;
  print_header(o, site);
  std::mt19937_64 rng(o.world.seed * 7919 + 3);
  std::vector<agv::site::CeilingCamera> believed;
  if (o.calib.tags > 0) {
    if (!calibrated_cameras(o, site, &believed, &error)) {
      std::fprintf(stderr, "eval_overhead: %s\n", error.c_str());
      return 2;
    }
  } else {
    believed = believed_cameras(o, site, &rng);
  }
  agv::overhead::CameraFrameProcessor proc(believed, told_fleet(o, world), {}, search_params(o));
  proc.set_tray_plane_sigma({o.tray_tilt_sigma_deg * agv::kPi / 180.0, o.tray_height_sigma_mm});
  agv::overhead::TrackerParams tp;
  tp.route_prior = o.route_prior;
  agv::overhead::FleetTracker tracker(site.fleet.size(), tp);
  RouteFeed routes;
  if (o.route_prior) routes.events = world.route_events();
  auto give_routes = [&](std::int64_t t) { routes.give(t, &tracker); };
  if (!o.tray_model.empty() && !load_tray_model(o.tray_model, &proc, false)) return 2;
  if (!o.reacquire_model.empty() && !load_tray_model(o.reacquire_model, &proc, true)) return 2;
  agv::eval::Trace trace;
  if (!o.trace_prefix.empty() && !trace.open(o.trace_prefix, &error)) {
    std::fprintf(stderr, "eval_overhead: %s\n", error.c_str());
    return 2;
  }

  const agv::sim::SiteRenderParams rp =
      o.clean ? agv::sim::SiteRenderParams{} : agv::sim::realistic_site_params();
  agv::eval::RegionRenderer renderer(k, rp);
  set_backgrounds(o, world, &renderer);
  const auto wall_bg = std::chrono::steady_clock::now();

  agv::eval::Score score;
  std::vector<std::string> ids;
  for (const auto& a : site.fleet) ids.push_back(a.id);
  const auto tick_ns = static_cast<std::int64_t>(1e9 / o.output_hz);
  auto end_ns = static_cast<std::int64_t>(o.world.duration_s * 1e9);
  std::int64_t next_tick = tick_ns;
  auto do_tick = [&](std::int64_t t) {
    give_routes(t);
    tracker.update_states(t);
    const std::vector<agv::sim::AgvState> truth = world.states_at(t);
    const std::vector<std::uint8_t> covered = world.tags_covered_at(t);
    const std::vector<agv::overhead::TrackOutput> outs = tracker.outputs(t);
    agv::eval::score_tick(outs, truth, in_some_view(world, truth), &score, &covered);
    trace.tick(t, outs, truth);
  };
  double render_s = 0.0;
  std::size_t frame_index = 0;
  std::vector<agv::overhead::Detection> dets;
  for (const FrameEvent& fe : frame_events(o, site.cameras.size())) {
    if (o.max_wall_s > 0.0 &&
        std::chrono::duration<double>(std::chrono::steady_clock::now() - wall0).count() >
            o.max_wall_s) {
      end_ns = std::min(end_ns, fe.exposure_ns);
      std::printf("stopped at the wall-time limit: scored up to t = %.2f s\n",
                  1e-9 * static_cast<double>(end_ns));
      break;
    }
    while (next_tick <= fe.arrival_ns && next_tick <= end_ns) {
      do_tick(next_tick);
      next_tick += tick_ns;
    }
    give_routes(fe.arrival_ns);
    const auto r0 = std::chrono::steady_clock::now();
    const agv::sim::SiteScene scene = world.scene_at(fe.exposure_ns);
    const agv::sim::RenderCamera rc = agv::sim::RenderCamera::from_ceiling(site.cameras[fe.camera]);
    cv::Mat img = renderer.render(fe.camera, scene, rc, o.world.seed * 100003 + frame_index);
    std::vector<std::uint8_t> ok;
    const auto corners = world.tag_corners(rc, scene.agvs, &ok);
    const auto in_image = inside(corners, ok, k.width_px, k.height_px);
    const std::vector<std::uint8_t> flipped = flip_bits(o, fe, corners, in_image, &img, &rng);
    render_s += std::chrono::duration<double>(std::chrono::steady_clock::now() - r0).count();
    const std::vector<std::uint8_t> tracked = tracked_at(tracker, corners.size(), fe.exposure_ns);
    dets.clear();
    if (!process_timed(fe, img, &proc, &tracker, &dets, &score)) return 2;
    if (frame_index % 200 == 199) {
      std::fprintf(stderr, "eval_overhead: frame %zu, t %.2f s\n", frame_index + 1,
                   1e-9 * static_cast<double>(fe.exposure_ns));
    }
    if (o.apriltag_every > 0 && frame_index % static_cast<std::size_t>(o.apriltag_every) == 0) {
      score.apriltag_ms.push_back(apriltag_full_frame_ms(img));
    }
    agv::eval::score_detections(dets, corners, ok, in_image, flipped, tracked, &score);
    if (trace.active()) trace.fixes(fe.arrival_ns, dets, scene.agvs);
    ++frame_index;
  }
  while (next_tick <= end_ns) {
    do_tick(next_tick);
    next_tick += tick_ns;
  }
  std::fputs(agv::eval::report(score, ids).c_str(), stdout);
  print_counters(proc.counters(), tracker.counters());
  print_tray_boxes(proc);
  if (o.route_prior) {
    std::printf("route prior: %zu routes given, %zu refused\n", routes.next - routes.refused,
                routes.refused);
  }
  const double wall =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - wall0).count();
  std::printf("wall %.1f s (backgrounds %.1f s, frames rendered %.1f s, %.1f Mpx of regions)\n",
              wall, std::chrono::duration<double>(wall_bg - wall0).count(), render_s,
              1e-6 * static_cast<double>(renderer.pixels_rendered()));
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  Options o;
  std::string error;
  if (!parse(argc, argv, &o, &error)) {
    std::fprintf(stderr, "eval_overhead: %s\n%s", error.c_str(), kUsage);
    return 2;
  }
  return run(o);
}
