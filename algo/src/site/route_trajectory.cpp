// A drivable trajectory along a route: every corner rounded by a symmetric
// clothoid-arc-clothoid blend (curvature linear in s over each clothoid), then a speed profile
// limited by the top speed, the lateral acceleration (v^2 k <= a_lat) and the longitudinal
// acceleration (a forward and a backward pass), parametrised by time.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <string>
#include <vector>

#include "agv/site/planner.hpp"

namespace agv::site {

namespace {

using Piece = RouteTrajectory::Piece;

// Pose after s along a piece: heading integrated in closed form, position by Simpson's rule
// (clothoids) or in closed form (lines, arcs).
Pose2 piece_pose(const Piece& p, double s) {
  const double k0 = p.k0_per_mm, dk = p.length_mm > 0 ? (p.k1_per_mm - k0) / p.length_mm : 0.0;
  const double th0 = p.start.theta_rad;
  auto heading = [&](double u) { return th0 + k0 * u + 0.5 * dk * u * u; };
  double x = p.start.x_mm, y = p.start.y_mm;
  if (dk == 0.0 && std::abs(k0) < 1e-15) {
    x += s * std::cos(th0), y += s * std::sin(th0);
  } else if (dk == 0.0) {
    x += (std::sin(th0 + k0 * s) - std::sin(th0)) / k0;
    y += (std::cos(th0) - std::cos(th0 + k0 * s)) / k0;
  } else {
    const int n = 2 * std::max(4, static_cast<int>(std::ceil(s / 10.0)));
    const double h = s / n;
    double sx = 0.0, sy = 0.0;
    for (int i = 0; i <= n; ++i) {
      const double w = (i == 0 || i == n) ? 1.0 : (i % 2 ? 4.0 : 2.0), th = heading(i * h);
      sx += w * std::cos(th), sy += w * std::sin(th);
    }
    x += sx * h / 3.0, y += sy * h / 3.0;
  }
  return {x, y, heading(s)};
}

double piece_curvature(const Piece& p, double s) {
  return p.length_mm > 0 ? p.k0_per_mm + (p.k1_per_mm - p.k0_per_mm) * s / p.length_mm
                         : p.k0_per_mm;
}

// A blend turning by delta (signed) from heading 0 at the origin: its pieces (relative), and the
// tangent length T (corner to blend start/end). Clothoids of length lc up to curvature k_max,
// shortened when the turn is smaller than the two clothoids alone would make.
struct Blend {
  std::vector<Piece> pieces;
  double tangent_mm = 0.0, deviation_mm = 0.0;
};

Blend make_blend(double delta, double k_max, double lc) {
  Blend b;
  const double sg = delta < 0 ? -1.0 : 1.0, ad = std::abs(delta);
  double k = k_max, arc = 0.0;
  if (lc > 0.0 && ad <= k_max * lc) {
    k = ad / lc;  // two clothoids meet at curvature k, no arc
  } else {
    arc = (ad - k * lc) / k;
  }
  Pose2 pose{0, 0, 0};
  const double lens[3] = {lc, arc, lc};
  const double ks[4] = {0.0, sg * k, sg * k, 0.0};
  Pose2 mid{};
  for (int i = 0; i < 3; ++i) {
    if (lens[i] <= 0.0) continue;
    Piece p;
    p.length_mm = lens[i], p.k0_per_mm = ks[i], p.k1_per_mm = ks[i + 1], p.start = pose;
    if (i == 1 || (arc <= 0.0 && i == 0)) {
      mid = piece_pose(p, i == 1 ? 0.5 * lens[i] : lens[i]);
    }
    pose = piece_pose(p, p.length_mm);
    b.pieces.push_back(p);
  }
  // Symmetric: the end lies T past the corner along the new heading, the start T before it.
  b.tangent_mm = std::abs(pose.y_mm / std::sin(delta));
  b.deviation_mm = std::hypot(mid.x_mm - b.tangent_mm, mid.y_mm);
  return b;
}

}  // namespace

struct RouteTrajectoryBuilder {
  // pure_arc[i]: corner i (waypoint i) blended as a plain arc at max curvature.
  static bool build(const std::vector<Vec2>& w, const DriveLimits& lim,
                    const std::vector<bool>& pure_arc, RouteTrajectory* out, std::string* error);
  static void profile(const DriveLimits& lim, RouteTrajectory* out);
};

bool RouteTrajectoryBuilder::build(const std::vector<Vec2>& w, const DriveLimits& lim,
                                   const std::vector<bool>& pure_arc, RouteTrajectory* out,
                                   std::string* error) {
  const std::size_t n = w.size();
  std::vector<double> seg(n > 0 ? n - 1 : 0), head(seg.size());
  for (std::size_t i = 0; i + 1 < n; ++i) {
    seg[i] = std::hypot(w[i + 1].x - w[i].x, w[i + 1].y - w[i].y);
    head[i] = std::atan2(w[i + 1].y - w[i].y, w[i + 1].x - w[i].x);
  }
  std::vector<Blend> blends(n);
  std::vector<double> tan_len(n, 0.0);
  for (std::size_t i = 1; i + 1 < n; ++i) {
    const double delta = wrap_angle_rad(head[i] - head[i - 1]);
    if (std::abs(delta) < 1e-9) continue;
    if (std::abs(delta) > kPi - 1e-6) {
      *error = "corner " + std::to_string(i) + " turns back on itself";
      return false;
    }
    // Room on each side: all of an end segment, half of a segment shared with another corner.
    const double room =
        std::min(i == 1 ? seg[0] : 0.5 * seg[i - 1], i + 2 == n ? seg[i] : 0.5 * seg[i]);
    double lc = pure_arc[i] ? 0.0 : lim.clothoid_length_mm;
    Blend b = make_blend(delta, lim.max_curvature_per_mm, lc);
    for (int it = 0; it < 40 && b.tangent_mm > room && lc > 1e-3; ++it) {
      lc *= 0.7;  // shorter clothoids: a sharper but shorter transition
      if (lc < 1.0) lc = 0.0;
      b = make_blend(delta, lim.max_curvature_per_mm, lc);
    }
    if (b.tangent_mm > room + 1e-9) {
      char buf[200];
      std::snprintf(buf, sizeof buf,
                    "corner %zu at (%.0f, %.0f) mm: a blend at curvature %.5f/mm needs %.0f mm of "
                    "each segment, %.0f mm available",
                    i, w[i].x, w[i].y, lim.max_curvature_per_mm, b.tangent_mm, room);
      *error = buf;
      return false;
    }
    blends[i] = b, tan_len[i] = b.tangent_mm;
  }
  out->pieces.clear();
  out->max_deviation_mm_ = 0.0;
  double s = 0.0;
  for (std::size_t i = 0; i + 1 < n; ++i) {
    const double line = seg[i] - tan_len[i] - tan_len[i + 1];
    const double c = std::cos(head[i]), sn = std::sin(head[i]);
    Piece p;
    p.s0_mm = s, p.length_mm = std::max(0.0, line);
    p.start = {w[i].x + c * tan_len[i], w[i].y + sn * tan_len[i], head[i]};
    if (p.length_mm > 0.0 || (i == 0 && n == 2)) out->pieces.push_back(p), s += p.length_mm;
    if (i + 2 < n && !blends[i + 1].pieces.empty()) {
      const Pose2 origin{w[i + 1].x - c * tan_len[i + 1], w[i + 1].y - sn * tan_len[i + 1],
                         head[i]};
      for (Piece q : blends[i + 1].pieces) {
        q.start = compose(origin, q.start), q.s0_mm = s;
        out->pieces.push_back(q), s += q.length_mm;
      }
      out->max_deviation_mm_ = std::max(out->max_deviation_mm_, blends[i + 1].deviation_mm);
    }
  }
  if (out->pieces.empty()) {  // a single waypoint: at rest there
    Piece p;
    if (n > 0) p.start = {w[0].x, w[0].y, 0.0};
    out->pieces.push_back(p);
  }
  out->length_mm_ = s;
  profile(lim, out);
  return true;
}

void RouteTrajectoryBuilder::profile(const DriveLimits& lim, RouteTrajectory* out) {
  std::vector<double> ks, ss;  // knots every <= 20 mm and at every piece boundary
  for (const Piece& p : out->pieces) {
    const int m = std::max(1, static_cast<int>(std::ceil(p.length_mm / 20.0)));
    for (int j = 0; j < m; ++j) ss.push_back(p.s0_mm + p.length_mm * j / m);
  }
  ss.push_back(out->length_mm_);
  const std::size_t n = ss.size();
  std::vector<double> v(n, lim.speed_mps);
  auto curv_at = [&](double s, int side) {  // side -1: the piece ending at s, +1: starting
    double k = 0.0;
    for (const Piece& p : out->pieces) {
      if (s >= p.s0_mm - 1e-9 && s <= p.s0_mm + p.length_mm + 1e-9) {
        const bool starts = std::abs(s - p.s0_mm) < 1e-9,
                   ends = std::abs(s - p.s0_mm - p.length_mm) < 1e-9;
        if ((side < 0 && starts && p.length_mm > 0) || (side > 0 && ends && p.length_mm > 0))
          continue;
        k = std::max(k, std::abs(piece_curvature(p, s - p.s0_mm)));
      }
    }
    return k;
  };
  std::vector<double> k(n);
  for (std::size_t i = 0; i < n; ++i) k[i] = std::max(curv_at(ss[i], -1), curv_at(ss[i], 1));
  for (std::size_t i = 0; i < n; ++i) {
    // The curvature is linear between knots: the larger of the neighbouring knots' bounds it.
    double kk = k[i];
    if (i > 0) kk = std::max(kk, k[i - 1]);
    if (i + 1 < n) kk = std::max(kk, k[i + 1]);
    if (kk > 0) v[i] = std::min(v[i], std::sqrt(lim.lateral_accel_mps2 / (kk * 1000.0)));
  }
  v.front() = 0.0, v.back() = 0.0;
  for (std::size_t i = 1; i < n; ++i) {
    v[i] = std::min(v[i],
                    std::sqrt(v[i - 1] * v[i - 1] + 2e-3 * lim.accel_mps2 * (ss[i] - ss[i - 1])));
  }
  for (std::size_t i = n - 1; i-- > 0;) {
    v[i] = std::min(v[i],
                    std::sqrt(v[i + 1] * v[i + 1] + 2e-3 * lim.accel_mps2 * (ss[i + 1] - ss[i])));
  }
  std::vector<double> t(n, 0.0);
  for (std::size_t i = 1; i < n; ++i) {
    const double vs = v[i - 1] + v[i];
    t[i] = t[i - 1] + (vs > 0 ? 2e-3 * (ss[i] - ss[i - 1]) / vs : 0.0);
  }
  out->profile_s_mm = ss, out->profile_v_mps = v, out->profile_t_s = t;
  out->duration_s_ = t.back();
}

bool RouteTrajectory::make(const Route& route, const DriveLimits& limits, RouteTrajectory* out,
                           std::string* error) {
  if (route.status != PlanStatus::kOk || route.waypoints_mm.empty()) {
    *error =
        "trajectory: the route has no waypoints (" + std::string(to_string(route.status)) + ")";
    return false;
  }
  if (!(limits.speed_mps > 0) || !(limits.accel_mps2 > 0) || !(limits.lateral_accel_mps2 > 0) ||
      !(limits.max_curvature_per_mm > 0) || !(limits.clothoid_length_mm >= 0) ||
      !std::isfinite(limits.speed_mps + limits.accel_mps2 + limits.lateral_accel_mps2 +
                     limits.max_curvature_per_mm + limits.clothoid_length_mm)) {
    *error = "trajectory: limits must be finite and positive";
    return false;
  }
  std::vector<Vec2> w;  // repeated waypoints dropped: they have no heading
  for (const Vec2& p : route.waypoints_mm) {
    if (w.empty() || std::hypot(p.x - w.back().x, p.y - w.back().y) > 1e-6) w.push_back(p);
  }
  return RouteTrajectoryBuilder::build(w, limits, std::vector<bool>(w.size(), false), out, error);
}

}  // namespace agv::site

namespace agv::site {

bool RouteTrajectory::make_checked(const Route& route, const DriveLimits& limits,
                                   const RoutePlanner& collision, RouteTrajectory* out,
                                   std::string* error, double check_step_mm) {
  if (!make(route, limits, out, error)) return false;
  std::vector<Vec2> w;
  for (const Vec2& p : route.waypoints_mm) {
    if (w.empty() || std::hypot(p.x - w.back().x, p.y - w.back().y) > 1e-6) w.push_back(p);
  }
  std::vector<bool> pure_arc(w.size(), false);
  const double step = std::max(1.0, check_step_mm);
  for (int attempt = 0; attempt < 2; ++attempt) {
    const std::vector<Vec2> pts = out->polyline(step);
    std::size_t bad = pts.size();
    for (std::size_t i = 0; i + 1 < pts.size() && bad == pts.size(); ++i) {
      if (!collision.segment_free(pts[i], pts[i + 1])) bad = i;
    }
    if (bad == pts.size()) return true;
    if (attempt == 1) break;
    // The corners whose blends leave the free space become plain arcs.
    for (std::size_t i = 0; i + 1 < pts.size(); ++i) {
      if (collision.segment_free(pts[i], pts[i + 1])) continue;
      std::size_t best = 0;
      double best_d = 1e300;
      for (std::size_t c = 1; c + 1 < w.size(); ++c) {
        const double d = std::hypot(w[c].x - pts[i].x, w[c].y - pts[i].y);
        if (d < best_d) best_d = d, best = c;
      }
      if (best > 0) pure_arc[best] = true;
    }
    if (!RouteTrajectoryBuilder::build(w, limits, pure_arc, out, error)) return false;
  }
  *error =
      "trajectory: a rounded corner leaves the collision-free space even as a plain arc "
      "at max curvature (max deviation " +
      std::to_string(static_cast<int>(out->max_deviation_mm_)) + " mm)";
  return false;
}

TrajectorySample RouteTrajectory::at(double t_s) const {
  TrajectorySample out;
  if (pieces.empty() || profile_t_s.empty()) return out;
  const double t = std::clamp(std::isfinite(t_s) ? t_s : 0.0, 0.0, duration_s_);
  const std::size_t hi = static_cast<std::size_t>(
      std::upper_bound(profile_t_s.begin(), profile_t_s.end(), t) - profile_t_s.begin());
  const std::size_t i = hi == 0 ? 0 : std::min(hi - 1, profile_t_s.size() - 1);
  double s = profile_s_mm[i], v = profile_v_mps[i];
  if (i + 1 < profile_t_s.size()) {
    const double ds_m = 1e-3 * (profile_s_mm[i + 1] - profile_s_mm[i]);
    const double v0 = profile_v_mps[i], v1 = profile_v_mps[i + 1];
    const double a = ds_m > 0 ? (v1 * v1 - v0 * v0) / (2.0 * ds_m) : 0.0, tau = t - profile_t_s[i];
    v = std::max(0.0, v0 + a * tau);
    s = std::min(profile_s_mm[i + 1], profile_s_mm[i] + 1e3 * (v0 * tau + 0.5 * a * tau * tau));
  }
  std::size_t k = static_cast<std::size_t>(
      std::upper_bound(pieces.begin(), pieces.end(), s,
                       [](double x, const Piece& p) { return x < p.s0_mm; }) -
      pieces.begin());
  k = k == 0 ? 0 : k - 1;
  const Piece& p = pieces[k];
  const double u = std::clamp(s - p.s0_mm, 0.0, p.length_mm);
  out.t_s = t, out.s_mm = s, out.v_mps = v;
  out.pose = piece_pose(p, u);
  out.pose.theta_rad = wrap_angle_rad(out.pose.theta_rad);
  out.curvature_per_mm = piece_curvature(p, u);
  out.omega_radps = v * 1e3 * out.curvature_per_mm;
  return out;
}

std::vector<Vec2> RouteTrajectory::polyline(double step_mm) const {
  std::vector<Vec2> out;
  const double step = std::max(1.0, std::isfinite(step_mm) ? step_mm : 1.0);
  for (const Piece& p : pieces) {
    const int m = std::max(1, static_cast<int>(std::ceil(p.length_mm / step)));
    for (int j = 0; j < m; ++j) {
      const Pose2 q = piece_pose(p, p.length_mm * j / m);
      out.push_back({q.x_mm, q.y_mm});
    }
  }
  if (!pieces.empty()) {
    const Pose2 e = piece_pose(pieces.back(), pieces.back().length_mm);
    out.push_back({e.x_mm, e.y_mm});
  }
  return out;
}

}  // namespace agv::site
