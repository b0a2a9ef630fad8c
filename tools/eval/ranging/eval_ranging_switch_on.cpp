// eval_ranging_switch_on: a vehicle switched on away from every floor landmark, standing still,
// with rack landmarks in view of its second camera (the "localized within 1 s"). At each
// random pose of eval_ranging_frames' scene (1280x800, lens distortion, calibration and mount
// errors, per-frame degradations) the camera takes `frames` RENDERED frames at 15 fps, each with
// its own noise; the LandmarkObserver reads them without a prior (full sweep), and the Localizer
// gets them through on_ranging with the wheels at rest, once per initialisation rule on the same
// observations: each frame's fix alone (RangingAidConfig::stack_fixes false); the frames' fixes
// stacked with two landmarks whose circles cross below 15 degrees refused
// (FixOptions::face_yaw_pairs_below_crossing false); stacked with such pairs seeded from their
// face yaws (the default); and the default with the range-bearing updates not told which share of
// their covariance repeats (RangeBearingObs::R_systematic zero). Reports per rule: poses localized
// within the frames, time to the first valid pose, its error and 3-sigma coverage, and the same
// at the end.
// Not a ctest; figures in docs/design/ranging.md ("Switched on"). Usage: eval_ranging_switch_on
// [trials=60] [seed=1] [frames=15] [mount_error_deg=1]
//                               [mount_error_mm=5] [calibration_error_scale=1]
// AGV_EVAL_CAL_TERMS (letters f, c, k) keeps only those lens errors: focal lengths, principal
// point, distortion. AGV_EVAL_BOARD_VIEWS=N: instead of drawn lens errors, AGV_EVAL_LENSES
// (default 8) lenses calibrated by the desk's `calibrate intrinsics` code from N rendered views
// of a ChArUco board bowed AGV_EVAL_BOARD_BOW_MM (default 0.5), trial t taking lens t mod K;
// AGV_EVAL_FOCAL_SIGMA_REL sets the focal sigma the observer is told (default 0.002).
// AGV_EVAL_LENS_PER_LANDMARK set: the fixes weigh the focal lengths' share per landmark
// (FixOptions::lens_in_weights false), as before it was estimated. With AGV_EVAL_POSES set, one
// line per trial of the default rule on stderr (pose, landmarks, the first pose's error and NEES)
// to trace which poses miss.
#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <map>
#include <random>
#include <string>
#include <vector>

#include "agv/localizer/localizer.hpp"
#include "agv/ranging/observe.hpp"
#include "agv/sim/ranging_camera.hpp"
#include "agv/sim/site_render.hpp"
#include "fix_errors.hpp"
#include "ranging_scene.hpp"
#ifdef AGV_EVAL_CALIBRATE
#include "calib_intrinsics.hpp"
#endif

namespace {

using namespace agv;
using ranging_eval::kNees3Sigma;

constexpr std::int64_t kMs = 1'000'000;
constexpr std::int64_t kFramePeriodNs = 66'666'667;  // 15 fps
constexpr std::int64_t kOdomPeriodNs = 10 * kMs;

using Frame = std::vector<localizer::RackObservation>;

double pct(std::vector<double> v, double q) {
  if (v.empty()) return std::nan("");
  std::sort(v.begin(), v.end());
  const std::size_t i = std::min(v.size() - 1, static_cast<std::size_t>(q * (v.size() - 1) + 0.5));
  return v[i];
}

// The observer's landmarks as the firmware hands them to the localizer (RackObserver::observe).
Frame rack_frame(const ranging::ObserveResult& res, const ranging::RangingMount& mount,
                 double mount_sigma_rad, double mount_sigma_mm) {
  Frame out;
  for (const ranging::LandmarkObservation& o : res.seen) {
    localizer::RackObservation r;
    r.vehicle = ranging::fix_observation(o);
    const ranging::SensorRangeBearing s =
        ranging::sensor_range_bearing(mount, o, mount_sigma_rad, mount_sigma_mm);
    r.sensor = {
        s.landmark_xy_mm, s.sensor_xy_mm, s.sensor_yaw_rad, s.range_mm, s.bearing_rad, s.R, 0.0,
        s.R_systematic};
    out.push_back(r);
  }
  return out;
}

struct Outcome {
  std::int64_t first_valid_ns = -1;
  Eigen::Vector3d first_error = Eigen::Vector3d::Zero(), end_error = Eigen::Vector3d::Zero();
  double first_nees = 0.0, end_nees = 0.0;
  // At the end, the position's NEES (2 dof) and the heading's (1 dof) apart.
  double end_nees_xy = 0.0, end_nees_theta = 0.0;
  bool end_valid = false;
  localizer::OutputStats stats;  // at the end
};

Eigen::Vector3d pose_error(const fusion::PoseEstimate& e, const Pose2& truth) {
  return {e.pose.x_mm - truth.x_mm, e.pose.y_mm - truth.y_mm,
          wrap_angle_rad(e.pose.theta_rad - truth.theta_rad)};
}

double nees(const fusion::PoseEstimate& e, const Eigen::Vector3d& err) {
  const Eigen::Matrix3d P = e.cov.topLeftCorner<3, 3>();
  return err.dot(P.ldlt().solve(err));
}

// Standing still at truth: wheels at rest at 100 Hz, the frames at 15 fps, a tick after each.
Outcome stand(const localizer::LocalizerConfig& cfg, const std::vector<Frame>& frames,
              const Pose2& truth) {
  localizer::Localizer loc(cfg);
  Outcome out;
  std::size_t next = 0;
  const std::int64_t end_ns = static_cast<std::int64_t>(frames.size()) * kFramePeriodNs;
  for (std::int64_t t = 0; t <= end_ns; t += kOdomPeriodNs) {
    loc.on_odometry(t, 0.0, 0.0);
    const std::int64_t frame_ns = static_cast<std::int64_t>(next) * kFramePeriodNs;
    if (next >= frames.size() || t < frame_ns) continue;
    loc.on_ranging(frame_ns, frames[next++]);
    loc.set_camera_state(t, false, false);
    const localizer::TickRecord rec = loc.tick(t);
    out.end_valid = rec.pose_valid;
    if (!rec.pose_valid) continue;
    out.end_error = pose_error(rec.estimate, truth);
    out.end_nees = nees(rec.estimate, out.end_error);
    const Eigen::Vector2d exy = out.end_error.head<2>();
    out.end_nees_xy = exy.dot(rec.estimate.cov.topLeftCorner<2, 2>().ldlt().solve(exy));
    out.end_nees_theta = out.end_error.z() * out.end_error.z() / rec.estimate.cov(2, 2);
    if (out.first_valid_ns >= 0) continue;
    out.first_valid_ns = t;
    out.first_error = out.end_error;
    out.first_nees = out.end_nees;
  }
  out.stats = loc.stats();
  return out;
}

// One trial of the default rule: where, what its first frame read, the first pose's error and
// NEES.
void print_trial(std::size_t t, const Pose2& truth, const std::vector<Frame>& frames,
                 const Outcome& o) {
  std::fprintf(stderr, "\ntrial %zu at %.0f %.0f %.1f deg, landmarks", t, truth.x_mm, truth.y_mm,
               rad_to_deg(truth.theta_rad));
  for (const localizer::RackObservation& r : frames.front()) {
    std::fprintf(stderr, " %.0fmm/%.1fdeg", r.sensor.range_mm, rad_to_deg(r.sensor.bearing_rad));
  }
  std::fprintf(stderr, "; first %s err %.1f %.1f mm %.2f deg nees %.1f\n",
               o.first_valid_ns < 0 ? "none" : "valid", o.first_error.x(), o.first_error.y(),
               rad_to_deg(o.first_error.z()), o.first_nees);
}

struct RuleTally {
  std::string name;
  // Frames of the vehicles not localized in time: refused fixes by status, disagreeing runs.
  std::map<std::string, std::uint64_t> refused;
  std::uint64_t disagreed = 0;
  int localized = 0, first_inside = 0, end_inside = 0, end_inside_xy = 0, end_inside_theta = 0;
  std::vector<double> first_ms, first_mm, first_deg, end_mm, end_deg;
  void add(const Outcome& o) {
    if (o.first_valid_ns < 0) {
      for (std::size_t k = 0; k < o.stats.ranging_fix_refused.size(); ++k) {
        if (o.stats.ranging_fix_refused[k] == 0) continue;
        refused[ranging::fix_status_name(static_cast<ranging::FixStatus>(k))] +=
            o.stats.ranging_fix_refused[k];
      }
      disagreed += o.stats.ranging_fixes_disagreed;
      return;
    }
    ++localized;
    first_ms.push_back(static_cast<double>(o.first_valid_ns) / 1e6);
    first_mm.push_back(std::hypot(o.first_error.x(), o.first_error.y()));
    first_deg.push_back(std::abs(rad_to_deg(o.first_error.z())));
    first_inside += o.first_nees <= kNees3Sigma;
    if (!o.end_valid) return;
    end_mm.push_back(std::hypot(o.end_error.x(), o.end_error.y()));
    end_deg.push_back(std::abs(rad_to_deg(o.end_error.z())));
    end_inside += o.end_nees <= kNees3Sigma;
    end_inside_xy += o.end_nees_xy <= 11.83;  // chi2(2) at 0.9973
    end_inside_theta += o.end_nees_theta <= 9.0;
  }
  void print(int in_view) const {
    const auto share = [](int n, std::size_t of) { return of ? 100.0 * n / of : 0.0; };
    std::printf(
        "| %s | %d of %d (%.0f %%) | %.0f / %.0f | %.1f / %.1f | %.2f / %.2f | %.1f %% | "
        "%.1f / %.1f | %.2f / %.2f | %.1f %% (%.1f / %.1f) |\n",
        name.c_str(), localized, in_view, share(localized, static_cast<std::size_t>(in_view)),
        pct(first_ms, 0.5), pct(first_ms, 0.95), pct(first_mm, 0.5), pct(first_mm, 0.95),
        pct(first_deg, 0.5), pct(first_deg, 0.95), share(first_inside, first_mm.size()),
        pct(end_mm, 0.5), pct(end_mm, 0.95), pct(end_deg, 0.5), pct(end_deg, 0.95),
        share(end_inside, end_mm.size()), share(end_inside_xy, end_mm.size()),
        share(end_inside_theta, end_mm.size()));
  }
};

double env_number(const char* name, double fallback) {
  const char* v = std::getenv(name);
  return v != nullptr ? std::atof(v) : fallback;
}

// The lenses AGV_EVAL_BOARD_VIEWS asks for (none without it); false when a calibration fails
// or the build has no desk tool.
bool calibrated_lenses(const CameraIntrinsics& truth, std::uint64_t seed,
                       std::vector<CameraIntrinsics>* out) {
  const int views = static_cast<int>(env_number("AGV_EVAL_BOARD_VIEWS", 0));
  if (views <= 0) return true;
#ifdef AGV_EVAL_CALIBRATE
  const int lenses = std::max(1, static_cast<int>(env_number("AGV_EVAL_LENSES", 8)));
  const double bow_mm = env_number("AGV_EVAL_BOARD_BOW_MM", 0.5);
  for (int i = 0; i < lenses; ++i) {
    const std::uint64_t board_seed = seed * 100 + static_cast<std::uint64_t>(i);
    const desk::calib::Result r =
        desk::calib::calibrate_simulated_board(truth, views, bow_mm, board_seed);
    if (!r.ok) {
      std::fprintf(stderr, "eval_ranging_switch_on: lens calibration: %s\n", r.error.c_str());
      return false;
    }
    const CameraIntrinsics& k = r.intrinsics;
    std::printf(
        "lens from %d of %d board views (bowed %.2f mm, seed %llu), rms %.3f px; error fx "
        "%+.3f %% fy %+.3f %% (own sigma %.3f / %.3f %%), cx %+.2f cy %+.2f px, k1 %+.5f\n",
        r.usable, views, bow_mm, static_cast<unsigned long long>(board_seed), r.rms_px,
        100.0 * (k.fx / truth.fx - 1.0), 100.0 * (k.fy / truth.fy - 1.0),
        100.0 * r.stddev[0] / k.fx, 100.0 * r.stddev[1] / k.fy, k.cx - truth.cx, k.cy - truth.cy,
        k.k1 - truth.k1);
    out->push_back(k);
  }
  return true;
#else
  (void)truth;
  (void)seed;
  (void)out;
  std::fprintf(stderr, "eval_ranging_switch_on: built without the desk tool: no board views\n");
  return false;
#endif
}

}  // namespace

int main(int argc, char** argv) {
  const int trials = argc > 1 ? std::atoi(argv[1]) : 60;
  const std::uint64_t seed = argc > 2 ? std::strtoull(argv[2], nullptr, 10) : 1;
  const int n_frames = argc > 3 ? std::max(2, std::atoi(argv[3])) : 15;
  const double mount_deg = argc > 4 ? std::atof(argv[4]) : 1.0;
  const double mount_mm = argc > 5 ? std::atof(argv[5]) : 5.0;
  ranging_eval::CalibrationErrors cal;
  cal.scale = argc > 6 ? std::atof(argv[6]) : 1.0;
  if (const char* terms = std::getenv("AGV_EVAL_CAL_TERMS")) {
    const std::string t(terms);
    cal.focal = t.find('f') != std::string::npos;
    cal.principal_point = t.find('c') != std::string::npos;
    cal.distortion = t.find('k') != std::string::npos;
  }
  const bool dump = std::getenv("AGV_EVAL_POSES") != nullptr;
  const sim::SiteScene scene = ranging_eval::warehouse(seed);
  const CameraIntrinsics k_true = ranging_eval::true_camera();
  const sim::SiteFrameRenderer renderer(k_true);
  ranging::RangingMount mount_true;
  mount_true.x_mm = 300.0;
  mount_true.z_mm = 1000.0;
  const std::vector<Pose2> poses = ranging_eval::trial_poses(scene, trials, seed);
  std::vector<CameraIntrinsics> lenses;
  if (!calibrated_lenses(k_true, seed, &lenses)) return 2;

  const double s_yaw = deg_to_rad(mount_deg) / std::sqrt(3.0), s_off = mount_mm / std::sqrt(3.0);
  ranging::ObserveOptions oopt;
  oopt.mount_sigma_rad = s_yaw;
  oopt.mount_sigma_mm = s_off;
  oopt.calibration_sigma_px = 0.5;
  oopt.focal_sigma_rel = env_number("AGV_EVAL_FOCAL_SIGMA_REL", 0.002);
  localizer::LocalizerConfig base;
  base.fusion.health.odom_timeout_ns = 50 * kMs;
  base.camera_timeout_ns = 200 * kMs;
  base.ranging.common_bearing_sigma_rad = std::hypot(s_yaw, 1.0 / k_true.fx);
  base.ranging.fix.lens_in_weights = std::getenv("AGV_EVAL_LENS_PER_LANDMARK") == nullptr;
  localizer::LocalizerConfig single = base;
  single.ranging.stack_fixes = false;
  single.ranging.fix.face_yaw_pairs_below_crossing = false;
  localizer::LocalizerConfig refused = base;
  refused.ranging.fix.face_yaw_pairs_below_crossing = false;
  // Per rule, per group (the most landmarks read in one of the frames: two, three or more).
  const char* kRules[4] = {"each frame's fix alone", "stacked, shallow pairs refused",
                           "stacked, shallow pairs seeded from face yaws (default)",
                           "the default, the EKF not told what repeats"};
  RuleTally tally[4][2];
  int in_view[2] = {0, 0};
  for (int r = 0; r < 4; ++r) {
    for (int g = 0; g < 2; ++g) tally[r][g].name = std::string(kRules[r]) + (g ? ", 3+" : ", 2");
  }
  for (std::size_t t = 0; t < poses.size(); ++t) {
    std::mt19937_64 rng(seed * 7919 + t);
    const sim::SiteRenderParams params = ranging_eval::degraded(rng);
    ranging::RangingMount m_est;
    if (!lenses.empty()) cal.calibrated = &lenses[t % lenses.size()];
    const ranging::LandmarkObserver observer = ranging_eval::believed_observer(
        rng, k_true, mount_true, mount_deg, mount_mm, scene, oopt, &m_est, cal);
    std::vector<Frame> frames;
    std::size_t most = 0;
    for (int f = 0; f < n_frames; ++f) {
      const sim::RenderResult img =
          renderer.render(scene, sim::ranging_camera(k_true, poses[t], mount_true), params,
                          (seed * 131 + t) * 1009 + static_cast<std::uint64_t>(f));
      frames.push_back(rack_frame(observer.observe(img.image), m_est, s_yaw, s_off));
      most = std::max(most, frames.back().size());
    }
    if (most < 2) continue;  // one landmark never localizes: not a trial of the rule
    const int g = most >= 3 ? 1 : 0;
    ++in_view[g];
    tally[0][g].add(stand(single, frames, poses[t]));
    tally[1][g].add(stand(refused, frames, poses[t]));
    const Outcome def = stand(base, frames, poses[t]);
    tally[2][g].add(def);
    if (dump) print_trial(t, poses[t], frames, def);
    for (Frame& f : frames) {
      for (localizer::RackObservation& o : f) o.sensor.R_systematic.setZero();
    }
    tally[3][g].add(stand(base, frames, poses[t]));
    std::fprintf(stderr, "\r%zu / %zu poses", t + 1, poses.size());
  }
  std::fprintf(stderr, "\n");
  std::printf(
      "RENDERED frames, standing still: %zu poses, %d with at most two landmarks read in a "
      "frame, %d with three or more (the trials; the rest saw fewer), %d frames each at 15 fps; "
      "mount error +-%.3g deg / +-%.3g mm\n\n",
      poses.size(), in_view[0], in_view[1], n_frames, mount_deg, mount_mm);
  std::printf(
      "| initialisation, landmarks | localized | first valid ms p50 / p95 | first pose mm p50 / "
      "p95 | deg p50 / p95 | 3-sigma | at the end mm p50 / p95 | deg p50 / p95 | 3-sigma "
      "(position / heading) |\n"
      "|---|---|---|---|---|---|---|---|---|\n");
  for (int g = 0; g < 2; ++g) {
    for (int r = 0; r < 4; ++r) tally[r][g].print(in_view[g]);
  }
  std::printf("\nNot localized in time, their frames' fixes refused:\n");
  for (int r = 0; r < 3; ++r) {
    for (int g = 0; g < 2; ++g) {
      std::printf("- %s:", tally[r][g].name.c_str());
      for (const auto& [k, v] : tally[r][g].refused)
        std::printf(" %s %llu", k.c_str(), static_cast<unsigned long long>(v));
      std::printf("; runs broken by a disagreeing fix %llu\n",
                  static_cast<unsigned long long>(tally[r][g].disagreed));
    }
  }
  return 0;
}
