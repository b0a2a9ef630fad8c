#include "replay_report.hpp"

#include <algorithm>
#include <cinttypes>
#include <cmath>
#include <cstdio>

#include "svg_plot.hpp"

namespace agv::app {

bool truth_at(const std::vector<recording::TruthRow>& truth, std::int64_t t_ns, Pose2* out) {
  if (truth.empty() || t_ns < truth.front().t_ns || t_ns > truth.back().t_ns) return false;
  auto it =
      std::lower_bound(truth.begin(), truth.end(), t_ns,
                       [](const recording::TruthRow& r, std::int64_t t) { return r.t_ns < t; });
  if (it == truth.begin()) {
    *out = {it->x_mm, it->y_mm, deg_to_rad(it->theta_deg)};
    return true;
  }
  const auto& b = *it;
  const auto& a = *(it - 1);
  const double f = static_cast<double>(t_ns - a.t_ns) / static_cast<double>(b.t_ns - a.t_ns);
  const double ta = deg_to_rad(a.theta_deg);
  const double dth = wrap_angle_rad(deg_to_rad(b.theta_deg) - ta);
  *out = {a.x_mm + f * (b.x_mm - a.x_mm), a.y_mm + f * (b.y_mm - a.y_mm),
          wrap_angle_rad(ta + f * dth)};
  return true;
}

namespace {

struct Errs {
  std::vector<double> pos, head;
  void add(const Pose2& est, const Pose2& truth) {
    pos.push_back(std::hypot(est.x_mm - truth.x_mm, est.y_mm - truth.y_mm));
    head.push_back(std::abs(rad_to_deg(wrap_angle_rad(est.theta_rad - truth.theta_rad))));
  }
  static double pct(std::vector<double> v, double p) {
    if (v.empty()) return 0.0;
    std::sort(v.begin(), v.end());
    const auto i = static_cast<std::size_t>(std::ceil(p * static_cast<double>(v.size()))) - 1;
    return v[std::min(i, v.size() - 1)];
  }
  ErrorStats stats() const {
    ErrorStats s;
    s.n = pos.size();
    if (s.n == 0) return s;
    s.pos_p50_mm = pct(pos, 0.5);
    s.pos_p95_mm = pct(pos, 0.95);
    s.pos_max_mm = *std::max_element(pos.begin(), pos.end());
    s.head_p50_deg = pct(head, 0.5);
    s.head_p95_deg = pct(head, 0.95);
    s.head_max_deg = *std::max_element(head.begin(), head.end());
    return s;
  }
};

}  // namespace

AccuracySummary evaluate(const recording::Recording& rec, const std::vector<TickRecord>& ticks,
                         const std::vector<FixRecord>& fixes,
                         std::vector<Vec2>* odometry_only_track) {
  AccuracySummary a;
  Errs fx, at, bw, all, od;
  Pose2 t;
  for (const auto& f : fixes) {
    if (f.fix.status == vision::FixStatus::kOk && truth_at(rec.truth, f.t_exposure_ns, &t)) {
      fx.add(f.fix.vehicle_in_world, t);
    }
  }
  for (const auto& tr : ticks) {
    if (!tr.estimate.valid) {
      ++a.ticks_invalid;
      continue;
    }
    if (!truth_at(rec.truth, tr.t_ns, &t)) continue;
    all.add(tr.estimate.pose, t);
    const std::int64_t since = tr.estimate.time_since_fix_ns;
    if (since >= 0 && since <= 50'000'000) at.add(tr.estimate.pose, t);
    if (since >= 200'000'000) bw.add(tr.estimate.pose, t);
  }
  // Odometry-only dead reckoning from the first truth pose, sampled at the ticks.
  if (!rec.truth.empty() && !rec.odom.empty()) {
    Pose2 p{rec.truth.front().x_mm, rec.truth.front().y_mm,
            deg_to_rad(rec.truth.front().theta_deg)};
    std::int64_t tp = rec.truth.front().t_ns;
    std::size_t oi = 0;
    double v = 0.0, w = 0.0;
    auto advance_to = [&](std::int64_t t_ns) {
      while (tp < t_ns) {
        std::int64_t next = t_ns;
        if (oi < rec.odom.size() && rec.odom[oi].t_ns <= t_ns)
          next = std::max(tp, rec.odom[oi].t_ns);
        const double dt = static_cast<double>(next - tp) * 1e-9;
        const double th_mid = p.theta_rad + 0.5 * w * dt;
        p.x_mm += 1000.0 * v * dt * std::cos(th_mid);
        p.y_mm += 1000.0 * v * dt * std::sin(th_mid);
        p.theta_rad = wrap_angle_rad(p.theta_rad + w * dt);
        tp = next;
        if (oi < rec.odom.size() && rec.odom[oi].t_ns <= tp) {
          v = rec.odom[oi].v_mps;
          w = rec.odom[oi].omega_radps;
          ++oi;
        }
      }
    };
    for (const auto& tr : ticks) {
      if (tr.t_ns < tp) continue;
      advance_to(tr.t_ns);
      if (odometry_only_track) odometry_only_track->push_back({p.x_mm, p.y_mm});
      if (truth_at(rec.truth, tr.t_ns, &t)) od.add(p, t);
    }
  }
  a.fixes = fx.stats();
  a.at_landmark = at.stats();
  a.between = bw.stats();
  a.all = all.stats();
  a.odometry_only = od.stats();
  return a;
}

std::string format_accuracy(const AccuracySummary& a) {
  std::string s = "accuracy against truth.csv (position mm / heading deg):\n";
  char buf[256];
  auto row = [&](const char* name, const ErrorStats& e) {
    if (e.n == 0) {
      std::snprintf(buf, sizeof buf, "  %-34s (no samples)\n", name);
    } else {
      std::snprintf(buf, sizeof buf,
                    "  %-34s n=%-6zu p50 %7.3f  p95 %7.3f  max %7.3f | p50 %6.3f  p95 %6.3f  max "
                    "%6.3f\n",
                    name, e.n, e.pos_p50_mm, e.pos_p95_mm, e.pos_max_mm, e.head_p50_deg,
                    e.head_p95_deg, e.head_max_deg);
    }
    s += buf;
  };
  row("vision fixes (at exposure)", a.fixes);
  row("fused, at a landmark (<=50 ms)", a.at_landmark);
  row("fused, between (>=200 ms)", a.between);
  row("fused, all valid ticks", a.all);
  row("odometry only (dead reckoning)", a.odometry_only);
  std::snprintf(buf, sizeof buf, "  ticks without a valid pose: %zu\n", a.ticks_invalid);
  s += buf;
  return s;
}

bool write_poses_csv(const std::string& path, const std::vector<TickRecord>& ticks,
                     std::string* error) {
  FILE* f = std::fopen(path.c_str(), "w");
  if (!f) {
    *error = path + ": cannot open for writing";
    return false;
  }
  std::fprintf(f,
               "t_ns,valid,health,x_mm,y_mm,theta_deg,v_mps,omega_radps,sigma_x_mm,sigma_y_mm,"
               "sigma_theta_deg,time_since_fix_ms,faults,rejections\n");
  for (const auto& t : ticks) {
    const auto& e = t.estimate;
    std::fprintf(
        f, "%" PRId64 ",%d,%d,%.4f,%.4f,%.5f,%.5f,%.6f,%.4f,%.4f,%.5f,%.1f,%u,%u\n", t.t_ns,
        e.valid ? 1 : 0, static_cast<int>(e.health), e.pose.x_mm, e.pose.y_mm,
        rad_to_deg(e.pose.theta_rad), e.v_mps, e.omega_radps, std::sqrt(std::max(0.0, e.cov(0, 0))),
        std::sqrt(std::max(0.0, e.cov(1, 1))), rad_to_deg(std::sqrt(std::max(0.0, e.cov(2, 2)))),
        e.time_since_fix_ns < 0 ? -1.0 : static_cast<double>(e.time_since_fix_ns) / 1e6,
        static_cast<unsigned>(t.status.faults), static_cast<unsigned>(t.status.rejections));
  }
  const bool ok = std::fclose(f) == 0;
  if (!ok) *error = path + ": write failed";
  return ok;
}

bool write_fixes_csv(const std::string& path, const std::vector<FixRecord>& fixes,
                     std::string* error) {
  FILE* f = std::fopen(path.c_str(), "w");
  if (!f) {
    *error = path + ": cannot open for writing";
    return false;
  }
  std::fprintf(f,
               "t_ns,status,landmark_id,e_x_mm,e_y_mm,e_phi_deg,x_mm,y_mm,theta_deg,sigma_x_mm,"
               "sigma_y_mm,sigma_theta_deg,vision_ms\n");
  for (const auto& r : fixes) {
    const auto& x = r.fix;
    const bool ok = x.status == vision::FixStatus::kOk;
    std::fprintf(
        f, "%" PRId64 ",%s,%u,%.4f,%.4f,%.5f,%.4f,%.4f,%.5f,%.4f,%.4f,%.5f,%.3f\n", r.t_exposure_ns,
        vision::to_string(x.status), static_cast<unsigned>(x.landmark_id), ok ? x.e_x_mm : 0.0,
        ok ? x.e_y_mm : 0.0, ok ? x.e_phi_deg : 0.0, ok ? x.vehicle_in_world.x_mm : 0.0,
        ok ? x.vehicle_in_world.y_mm : 0.0, ok ? rad_to_deg(x.vehicle_in_world.theta_rad) : 0.0,
        ok ? std::sqrt(std::max(0.0, x.cov_world(0, 0))) : 0.0,
        ok ? std::sqrt(std::max(0.0, x.cov_world(1, 1))) : 0.0,
        ok ? rad_to_deg(std::sqrt(std::max(0.0, x.cov_world(2, 2)))) : 0.0, x.timings.total_ms);
  }
  const bool ok = std::fclose(f) == 0;
  if (!ok) *error = path + ": write failed";
  return ok;
}

bool write_plot(const std::string& path, const recording::Recording& rec,
                const std::vector<TickRecord>& ticks, const std::vector<Vec2>& odometry_only,
                const LandmarkMap* map, std::string* error) {
  std::vector<plot::Series> series;
  if (!rec.truth.empty()) {
    plot::Series s{"truth", "#2a9d2a", {}, false};
    for (const auto& t : rec.truth) s.points_mm.push_back({t.x_mm, t.y_mm});
    series.push_back(std::move(s));
  }
  if (!odometry_only.empty()) series.push_back({"odometry only", "#999999", odometry_only, true});
  plot::Series fused{"fused (EKF)", "#1f5fbf", {}, false};
  for (const auto& t : ticks) {
    if (t.estimate.valid) fused.points_mm.push_back({t.estimate.pose.x_mm, t.estimate.pose.y_mm});
  }
  series.push_back(std::move(fused));
  std::vector<plot::Marker> marks;
  if (map) {
    for (const auto& [id, e] : map->entries) {
      marks.push_back({{e.pose.x_mm, e.pose.y_mm}, e.pose.theta_rad, std::to_string(id)});
    }
  }
  return plot::write_trajectory_svg(path, "agvloc replay: " + rec.dir, series, marks, error);
}

}  // namespace agv::app
