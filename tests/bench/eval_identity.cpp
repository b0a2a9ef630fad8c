// Map-guided identity evaluation (docs/design/map_identity.md): simulated frames where every
// landmark's QR code is partly covered, with predictions = truth + noise, on a 1000 mm grid, on a
// 150 mm grid of landmarks with one heading, and with wrong predictions (kidnapped vehicle).
//   eval_identity [--frames N] [--cover F] [--seed S] [--min-rate R] [--row-step N]
// Prints one line per run; exit status 1 when a wrong identity occurs in any run or the fix rate of
// the correct-prediction runs is below --min-rate (the ctest runs a small version).
#include <Eigen/Core>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <random>
#include <string>
#include <vector>

#include "agv/sim/render.hpp"
#include "agv/vision/landmark_localizer.hpp"
#include "agv/vision/map_identity.hpp"

using namespace agv;

namespace {

// A fix is the wrong landmark when its world pose is further from the truth than any correct fix
// can be (the landmark fit is good to ~0.1 mm / 0.05 deg; a neighbour is >= 150 mm away).
constexpr double kWrongMm = 5.0;
constexpr double kWrongDeg = 1.0;
// Prediction noise: a tracking filter a few landmarks after the last fix.
constexpr double kPredSigmaMm = 3.0;
constexpr double kPredSigmaDeg = 0.3;

Vec2 rot_vec(Vec2 v, double a) {
  const double c = std::cos(a), s = std::sin(a);
  return {c * v.x - s * v.y, s * v.x + c * v.y};
}

struct Args {
  int frames = 300;
  double cover = 1.0 / 3.0;
  std::uint64_t seed = 1;
  double min_rate = 0.99;
  int row_step = 0;  // --row-step: VisionConfig::edge_row_step (0 = default)
};

struct Counts {
  int frames = 0, qr_only_ok = 0, ok = 0, qr = 0, guided = 0, wrong = 0, wrong_qr_only = 0;
  int gate_wrong = 0;
  // Per map-guided frame: the same frame without (QR unreadable) and with the prediction.
  std::vector<double> plain_ms,
      guided_ms;  // frames where the pose gate alone would accept the wrong landmark
  double max_err_mm = 0.0;
};

LandmarkMap grid(int n, double spacing_mm, bool one_heading) {
  if (!one_heading) return sim::default_landmark_grid(n, n, spacing_mm);
  LandmarkMap m;
  std::uint32_t id = 1;
  for (int r = 0; r < n; ++r) {
    for (int c = 0; c < n; ++c, ++id) m.entries[id] = {id, {c * spacing_mm, r * spacing_mm, 0.0}};
  }
  return m;
}

bool border_in_view(const CameraModel& cam, const Pose2& vehicle, const Pose2& landmark) {
  const Pose2 l_in_v = compose(inverse(vehicle), landmark);
  for (const Vec2& q : LandmarkGeometry{}.outer_corners_landmark_mm()) {
    Vec2 px;
    if (!cam.vehicle_to_pixel(transform(l_in_v, q), &px) || px.x < 0.5 || px.y < 0.5 ||
        px.x > cam.intrinsics.width_px - 1.5 || px.y > cam.intrinsics.height_px - 1.5) {
      return false;
    }
  }
  return true;
}

bool is_wrong(const vision::LandmarkFix& f, const Pose2& truth) {
  if (f.status != vision::FixStatus::kOk) return false;
  const double e =
      std::hypot(f.vehicle_in_world.x_mm - truth.x_mm, f.vehicle_in_world.y_mm - truth.y_mm);
  const double a =
      std::abs(rad_to_deg(wrap_angle_rad(f.vehicle_in_world.theta_rad - truth.theta_rad)));
  return e > kWrongMm || a > kWrongDeg;
}

// kind 0: prediction = truth + noise; 1: kidnapped by 200..500 mm in a random direction;
// 2: kidnapped by exactly one grid spacing (+x or +y), same heading.
Counts run(const LandmarkMap& map, double spacing_mm, int kind, bool id_only, const Args& a) {
  const CameraModel cam = CameraModel::default_640x480();
  sim::Scene scene;
  std::string err;
  if (!sim::make_scene(map, LandmarkGeometry{},
                       id_only ? sim::PayloadMode::kIdOnly : sim::PayloadMode::kFull, &scene,
                       &err)) {
    std::fprintf(stderr, "scene: %s\n", err.c_str());
    std::exit(2);
  }
  const sim::FrameRenderer renderer(scene, cam);
  vision::VisionConfig vc;
  if (a.row_step > 0) vc.edge_row_step = a.row_step;
  vision::LandmarkLocalizer loc(vc, cam, LandmarkGeometry{}, &map);
  sim::RenderOptions o = sim::realistic_options();
  o.qr_cover_fraction = a.cover;
  std::mt19937_64 rng(a.seed * 1000 + static_cast<std::uint64_t>(kind) * 17 +
                      static_cast<std::uint64_t>(spacing_mm));
  std::uniform_real_distribution<double> ux(-25.0, 25.0), uy(-15.0, 15.0), uh(-kPi, kPi),
      uk(200.0, 500.0), u01(0.0, 1.0);
  std::normal_distribution<double> n01(0.0, 1.0);
  std::vector<const LandmarkMapEntry*> entries;
  for (const auto& [id, e] : map.entries) entries.push_back(&e);
  Counts c;
  int attempts = 0;
  while (c.frames < a.frames && attempts < a.frames * 20) {
    ++attempts;
    const LandmarkMapEntry& e = *entries[rng() % entries.size()];
    // Vehicle so that the landmark sits near the image centre (camera model, not the mount).
    Vec2 centre_v;
    cam.pixel_to_vehicle(
        {(cam.intrinsics.width_px - 1) / 2.0, (cam.intrinsics.height_px - 1) / 2.0}, &centre_v);
    const double th = uh(rng);
    const Vec2 off{centre_v.x + ux(rng), centre_v.y + uy(rng)};
    // W<-V such that the landmark is at `off` in the vehicle frame.
    const Vec2 r = rot_vec(off, th);
    const Pose2 truth{e.pose.x_mm - r.x, e.pose.y_mm - r.y, th};
    if (!border_in_view(cam, truth, e.pose)) continue;
    ++c.frames;
    o.degradation_seed = a.seed + static_cast<std::uint64_t>(c.frames);
    const cv::Mat img = renderer.render(truth, o, rng);
    vision::Prediction p;
    p.valid = true;
    p.cov = Eigen::Matrix3d::Zero();
    p.cov(0, 0) = p.cov(1, 1) = kPredSigmaMm * kPredSigmaMm;
    p.cov(2, 2) = std::pow(deg_to_rad(kPredSigmaDeg), 2);
    Pose2 pv{truth.x_mm + kPredSigmaMm * n01(rng), truth.y_mm + kPredSigmaMm * n01(rng),
             truth.theta_rad + deg_to_rad(kPredSigmaDeg) * n01(rng)};
    if (kind == 1) {
      const double d = uk(rng), dir = uh(rng);
      pv.x_mm += d * std::cos(dir);
      pv.y_mm += d * std::sin(dir);
    } else if (kind == 2) {
      (u01(rng) < 0.5 ? pv.x_mm : pv.y_mm) += (u01(rng) < 0.5 ? -1.0 : 1.0) * spacing_mm;
    }
    p.vehicle_in_world = pv;
    vision::LandmarkFix plain, fix;
    const auto t0 = std::chrono::steady_clock::now();
    loc.process(img, &plain);
    const auto t1 = std::chrono::steady_clock::now();
    loc.process(img, p, &fix);
    const auto t2 = std::chrono::steady_clock::now();
    if (fix.identity == vision::FixIdentity::kMapGuided) {
      c.plain_ms.push_back(std::chrono::duration<double, std::milli>(t1 - t0).count());
      c.guided_ms.push_back(std::chrono::duration<double, std::milli>(t2 - t1).count());
    }
    if (plain.status == vision::FixStatus::kOk) ++c.qr_only_ok;
    if (is_wrong(plain, truth)) ++c.wrong_qr_only;
    // What the pose gate alone would decide with this prediction (the measured landmark taken as
    // its true pose, the logo's turn known): how often the module check is the only protection.
    const Pose2 l_true = compose(inverse(truth), e.pose);
    Eigen::Matrix3d fit_cov = Eigen::Matrix3d::Zero();
    fit_cov(0, 0) = fit_cov(1, 1) = 0.05 * 0.05;
    fit_cov(2, 2) = std::pow(deg_to_rad(0.01), 2);
    const vision::MapIdentityDecision g =
        vision::gate_identity({l_true.x_mm, l_true.y_mm}, l_true.theta_rad, fit_cov,
                              {true, false, false, false}, p, map, vision::MapIdentityConfig{});
    if (g.result == vision::MapIdentityResult::kAccepted && g.id != e.id) ++c.gate_wrong;
    if (fix.status == vision::FixStatus::kOk) {
      ++c.ok;
      if (fix.identity == vision::FixIdentity::kMapGuided) ++c.guided;
      if (fix.identity == vision::FixIdentity::kQrCode) ++c.qr;
      const double err_mm = std::hypot(fix.vehicle_in_world.x_mm - truth.x_mm,
                                       fix.vehicle_in_world.y_mm - truth.y_mm);
      if (is_wrong(fix, truth)) {
        ++c.wrong;
        std::fprintf(stderr, "WRONG: kind %d frame %d id %u err %.1f mm identity %s\n", kind,
                     c.frames, fix.landmark_id, err_mm, vision::to_string(fix.identity));
      } else if (err_mm > c.max_err_mm) {
        c.max_err_mm = err_mm;
      }
    }
  }
  return c;
}

}  // namespace

int main(int argc, char** argv) {
  Args a;
  for (int i = 1; i + 1 < argc; i += 2) {
    const std::string k = argv[i];
    if (k == "--frames")
      a.frames = std::atoi(argv[i + 1]);
    else if (k == "--cover")
      a.cover = std::atof(argv[i + 1]);
    else if (k == "--seed")
      a.seed = std::strtoull(argv[i + 1], nullptr, 10);
    else if (k == "--min-rate")
      a.min_rate = std::atof(argv[i + 1]);
    else if (k == "--row-step")
      a.row_step = std::atoi(argv[i + 1]);
    else {
      std::fprintf(stderr,
                   "usage: eval_identity [--frames N] [--cover F] [--seed S] [--min-rate R] "
                   "[--row-step N]\n");
      return 2;
    }
  }
  struct Run {
    const char* name;
    double spacing;
    bool one_heading;
    int kind;
    bool id_only = false;
  };
  const Run runs[] = {{"grid1000", 1000.0, false, 0},
                      {"close150", 150.0, true, 0},
                      {"grid1000_id_only_payload", 1000.0, false, 0, true},
                      {"kidnap_200_500mm", 1000.0, false, 1},
                      {"kidnap_200_500mm_close", 150.0, true, 1},
                      {"kidnap_one_spacing_close", 150.0, true, 2},
                      {"kidnap_one_spacing_grid", 1000.0, false, 2}};
  std::printf("realistic_options + qr_cover_fraction %.3f, prediction sigma %.1f mm / %.1f deg\n",
              a.cover, kPredSigmaMm, kPredSigmaDeg);
  std::printf("%-26s %6s %9s %9s %6s %6s %7s %6s %10s %10s\n", "run", "frames", "qr_only%", "fix%",
              "qr", "map", "wrong", "wrongQ", "max_err_mm", "gate_wrong");
  bool fail = false;
  for (const Run& r : runs) {
    const LandmarkMap map = grid(5, r.spacing, r.one_heading);
    const Counts c = run(map, r.spacing, r.kind, r.id_only, a);
    const double rate = c.frames ? static_cast<double>(c.ok) / c.frames : 0.0;
    std::printf("%-26s %6d %8.1f%% %8.1f%% %6d %6d %7d %6d %10.3f %10d\n", r.name, c.frames,
                c.frames ? 100.0 * c.qr_only_ok / c.frames : 0.0, 100.0 * rate, c.qr, c.guided,
                c.wrong, c.wrong_qr_only, c.max_err_mm, c.gate_wrong);
    if (!c.guided_ms.empty()) {
      auto median = [](std::vector<double> v) {
        std::nth_element(v.begin(), v.begin() + static_cast<long>(v.size() / 2), v.end());
        return v[v.size() / 2];
      };
      std::printf(
          "%-26s map-guided frames: median %.3f ms without the prediction (unreadable), "
          "%.3f ms with it\n",
          "", median(c.plain_ms), median(c.guided_ms));
    }
    std::fflush(stdout);
    if (c.wrong > 0 || c.wrong_qr_only > 0) fail = true;
    // The rate target is for the full payload (the generator's default); id-only codes are version
    // 1, whose neighbours differ on fewer modules, so a cover more often leaves too few to compare
    // (refused, never wrong): reported, not checked.
    if (r.kind == 0 && r.spacing > 500.0 && !r.id_only && rate < a.min_rate) {
      std::fprintf(stderr, "%s: fix rate %.3f below %.3f\n", r.name, rate, a.min_rate);
      fail = true;
    }
  }
  return fail ? 1 : 0;
}
