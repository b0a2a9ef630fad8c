// eval_vision: frames with ground truth, per-frame evaluation and the table rows.
#include <Eigen/Dense>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <opencv2/imgcodecs.hpp>

#include "eval_vision.hpp"

namespace eval_vision {

std::int64_t now_ns() {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(
             std::chrono::steady_clock::now().time_since_epoch())
      .count();
}

double pct(std::vector<double> v, double p) {
  if (v.empty()) return std::nan("");
  std::sort(v.begin(), v.end());
  const double idx = p / 100.0 * static_cast<double>(v.size() - 1);
  const size_t i = static_cast<size_t>(idx);
  const double f = idx - static_cast<double>(i);
  return i + 1 < v.size() ? v[i] * (1 - f) + v[i + 1] * f : v[i];
}

std::string g_dump_dir;

namespace {

bool fully_visible(const CameraModel& cam, const LandmarkGeometry& g, const Pose2& e,
                   double margin_px) {
  const Pose2 l_in_v = inverse(e);
  for (const Vec2& c : g.outer_corners_landmark_mm()) {
    Vec2 px;
    if (!cam.vehicle_to_pixel(transform(l_in_v, c), &px)) return false;
    if (px.x < margin_px || px.y < margin_px || px.x > cam.intrinsics.width_px - 1 - margin_px ||
        px.y > cam.intrinsics.height_px - 1 - margin_px) {
      return false;
    }
  }
  return true;
}

// Samples e in the paper's range (-70 < e_x < 70, -45 < e_y < 70 mm), heading over the full
// circle; `want_full` selects fully visible or cut landmarks.
Pose2 sample_pose(std::mt19937_64& rng, const CameraModel& cam, const LandmarkGeometry& g,
                  bool want_full) {
  std::uniform_real_distribution<double> ux(-70, 70), uy(-45, 70), uphi(-kPi, kPi);
  for (;;) {
    const Pose2 e{ux(rng), uy(rng), uphi(rng)};
    const bool full = fully_visible(cam, g, e, 2.0);
    if (full == want_full) return e;
  }
}
}  // namespace

void evaluate(LandmarkLocalizer& loc, const std::vector<Frame>& frames, Stats* s,
              const std::string& tag) {
  LandmarkFix fix;
  for (const Frame& f : frames) {
    loc.process(f.img, &fix);
    ++s->n;
    ++s->status[fix.status];
    if (fix.qr_method == 1) ++s->qr_guided;
    if (fix.qr_method == 2) ++s->qr_search;
    s->t_total.push_back(fix.timings.total_ms);
    if (fix.status != FixStatus::kOk) {
      if (!g_dump_dir.empty() && !tag.empty() && s->status[fix.status] <= 4) {
        char name[256];
        std::snprintf(name, sizeof name, "%s/%s_%d_%d_ex%.0f_ey%.0f_phi%.0f.png",
                      g_dump_dir.c_str(), tag.c_str(), static_cast<int>(fix.status), s->n,
                      f.e_true.x_mm, f.e_true.y_mm, rad_to_deg(f.e_true.theta_rad));
        cv::imwrite(name, f.img);
      }
      continue;
    }
    const double dh =
        std::abs(rad_to_deg(wrap_angle_rad(deg_to_rad(fix.e_phi_deg) - f.e_true.theta_rad)));
    if (dh > 45.0) {
      ++s->wrong_direction;
      continue;
    }
    ++s->ok;
    const double pe = std::hypot(fix.e_x_mm - f.e_true.x_mm, fix.e_y_mm - f.e_true.y_mm);
    if (!g_dump_dir.empty() && !tag.empty() && pe > 0.3) {
      cv::Mat ov;
      loc.draw_overlay(f.img, fix, &ov);
      char name[256];
      std::snprintf(name, sizeof name, "%s/%s_bad%d_%.2fmm.png", g_dump_dir.c_str(), tag.c_str(),
                    s->n, pe);
      cv::imwrite(name, ov);
    }
    s->pos_err.push_back(pe);
    s->head_err.push_back(dh);
    s->world_err.push_back(std::hypot(fix.vehicle_in_world.x_mm - f.vehicle_world.x_mm,
                                      fix.vehicle_in_world.y_mm - f.vehicle_world.y_mm));
    s->t_detect.push_back(fix.timings.detect_ms);
    s->t_decode.push_back(fix.timings.decode_ms);
    s->t_direction.push_back(fix.timings.direction_ms);
    s->t_pose.push_back(fix.timings.pose_ms);
    // Normalised estimation error squared of the world pose (3 dof; mean 3 if consistent).
    Eigen::Vector3d err(fix.vehicle_in_world.x_mm - f.vehicle_world.x_mm,
                        fix.vehicle_in_world.y_mm - f.vehicle_world.y_mm,
                        wrap_angle_rad(fix.vehicle_in_world.theta_rad - f.vehicle_world.theta_rad));
    s->nees.push_back(err.dot(fix.cov_world.ldlt().solve(err)));
  }
}

void print_header() {
  std::printf(
      "| condition | frames | detected | wrong dir | pos p50 / p95 / max (mm) | heading p50 / p95 "
      "/ "
      "max (deg) | mean NEES | QR read guided / search | statuses "
      "|\n|---|---|---|---|---|---|---|---|---|\n");
}

void print_row(const std::string& name, const Stats& s) {
  std::string st;
  for (const auto& [k, v] : s.status) {
    if (k == FixStatus::kOk) continue;
    char b[96];
    std::snprintf(b, sizeof b, "%s%s: %d", st.empty() ? "" : ", ", to_string(k), v);
    st += b;
  }
  double nees = 0;
  for (double v : s.nees) nees += v;
  if (!s.nees.empty()) nees /= static_cast<double>(s.nees.size());
  std::printf(
      "| %s | %d | %.1f %% | %d | %.3f / %.3f / %.3f | %.4f / %.4f / %.4f | %.1f | %d / %d | %s "
      "|\n",
      name.c_str(), s.n, 100.0 * s.ok / std::max(1, s.n), s.wrong_direction, pct(s.pos_err, 50),
      pct(s.pos_err, 95), pct(s.pos_err, 100), pct(s.head_err, 50), pct(s.head_err, 95),
      pct(s.head_err, 100), nees, s.qr_guided, s.qr_search, st.empty() ? "-" : st.c_str());
  std::fflush(stdout);
}

std::vector<Frame> render_set(const sim::Scene& scene, const CameraModel& cam, const Condition& c,
                              int n, std::uint64_t seed) {
  sim::FrameRenderer r(scene, cam);
  std::mt19937_64 rng(seed);
  std::vector<Frame> out;
  for (int i = 0; i < n; ++i) {
    Frame f;
    f.e_true = sample_pose(rng, cam, scene.geometry, c.want_full);
    f.vehicle_world = compose(kLandmarkWorld, f.e_true);
    sim::RenderOptions o;
    if (c.options) c.options(rng, &o);
    o.degradation_seed = rng();
    f.img = r.render(f.vehicle_world, o, rng);
    out.push_back(std::move(f));
  }
  return out;
}
}  // namespace eval_vision
