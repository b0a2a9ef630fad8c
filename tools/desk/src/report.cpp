#include "report.hpp"

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <sstream>

#include "svg_plot.hpp"

namespace agv::desk {

namespace {

// poses.csv of a 2.8 h replay is ~130 MB (docs/guide/replay.md); fixes.csv is smaller.
constexpr std::uintmax_t kMaxOutputCsvBytes = 512ull << 20;

bool parse_number(const std::string& s, double* out) {
  if (s.empty()) return false;
  char* end = nullptr;
  *out = std::strtod(s.c_str(), &end);
  return end == s.c_str() + s.size() && std::isfinite(*out);
}

bool parse_int64(const std::string& s, std::int64_t* out) {
  if (s.empty()) return false;
  char* end = nullptr;
  errno = 0;
  *out = std::strtoll(s.c_str(), &end, 10);
  return end == s.c_str() + s.size() && errno == 0;
}

// Calls row(fields) for every data line after checking the header's first columns.
template <class RowFn>
bool read_csv(const std::string& path, const std::string& header_prefix, std::size_t columns,
              std::string* error, RowFn row) {
  std::string text;
  if (!recording::read_file_bounded(path, kMaxOutputCsvBytes, &text, error)) return false;
  std::istringstream in(text);
  std::string line;
  std::size_t line_no = 0;
  std::vector<std::string> f;
  while (std::getline(in, line)) {
    ++line_no;
    if (line_no == 1) {
      if (line.rfind(header_prefix, 0) != 0) {
        *error = path + ": header does not start with '" + header_prefix + "'";
        return false;
      }
      continue;
    }
    if (line.empty()) continue;
    f.clear();
    std::size_t a = 0;
    for (;;) {
      const std::size_t b = line.find(',', a);
      f.push_back(line.substr(a, b == std::string::npos ? std::string::npos : b - a));
      if (b == std::string::npos) break;
      a = b + 1;
    }
    if (f.size() < columns || !row(f)) {
      *error = path + ":" + std::to_string(line_no) + ": malformed row";
      return false;
    }
  }
  if (line_no == 0) {
    *error = path + ": empty file";
    return false;
  }
  return true;
}

}  // namespace

bool read_poses_csv(const std::string& path, std::vector<PoseRow>* out, std::string* error) {
  out->clear();
  return read_csv(path, "t_ns,valid,health,x_mm,y_mm,theta_deg", 12, error,
                  [&](const std::vector<std::string>& f) {
                    std::int64_t t;
                    double valid, health, x, y, th, sx, sy, sth, since_ms;
                    if (!parse_int64(f[0], &t) || !parse_number(f[1], &valid) ||
                        !parse_number(f[2], &health) || !parse_number(f[3], &x) ||
                        !parse_number(f[4], &y) || !parse_number(f[5], &th) ||
                        !parse_number(f[8], &sx) || !parse_number(f[9], &sy) ||
                        !parse_number(f[10], &sth) || !parse_number(f[11], &since_ms)) {
                      return false;
                    }
                    // Beyond int64 nanoseconds llround gives a negative value (fuzz_report_csv:
                    // 1e300 read as a time since fix of -9.2e18 ns, not "no fix yet").
                    if (since_ms > 9.2e12) return false;
                    PoseRow r;
                    r.t_ns = t;
                    r.valid = valid != 0.0;
                    r.pose = {x, y, deg_to_rad(th)};
                    r.health = health >= 0.0 && health <= 3.0 ? static_cast<int>(health) : -1;
                    r.sigma_x_mm = sx;
                    r.sigma_y_mm = sy;
                    r.sigma_theta_rad = deg_to_rad(sth);
                    // Written with 0.1 ms resolution; -1 means no fix yet.
                    r.time_since_fix_ns = since_ms < 0 ? -1 : std::llround(since_ms * 1e6);
                    out->push_back(r);
                    return true;
                  });
}

bool read_fixes_csv(const std::string& path, std::vector<FixRow>* out, std::string* error) {
  out->clear();
  return read_csv(path, "t_ns,status,landmark_id", 9, error,
                  [&](const std::vector<std::string>& f) {
                    if (f[1] != "ok") return true;
                    std::int64_t t;
                    double x, y, th;
                    if (!parse_int64(f[0], &t) || !parse_number(f[6], &x) ||
                        !parse_number(f[7], &y) || !parse_number(f[8], &th)) {
                      return false;
                    }
                    out->push_back({t, {x, y, deg_to_rad(th)}});
                    return true;
                  });
}

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

AccuracySummary evaluate(const recording::Recording& rec, const std::vector<PoseRow>& ticks,
                         const std::vector<FixRow>& fixes, std::vector<Vec2>* odometry_only_track) {
  AccuracySummary a;
  Errs fx, at, bw, all, od;
  Pose2 t;
  for (const auto& f : fixes) {
    if (truth_at(rec.truth, f.t_exposure_ns, &t)) fx.add(f.vehicle_in_world, t);
  }
  for (const auto& tr : ticks) {
    if (!tr.valid) {
      ++a.ticks_invalid;
      continue;
    }
    if (!truth_at(rec.truth, tr.t_ns, &t)) continue;
    all.add(tr.pose, t);
    const std::int64_t since = tr.time_since_fix_ns;
    if (since >= 0 && since <= 50'000'000) at.add(tr.pose, t);
    if (since >= 200'000'000) bw.add(tr.pose, t);
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

bool write_plot(const std::string& path, const recording::Recording& rec,
                const std::vector<PoseRow>& ticks, const std::vector<Vec2>& odometry_only,
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
    if (t.valid) fused.points_mm.push_back({t.pose.x_mm, t.pose.y_mm});
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

}  // namespace agv::desk
