#include "agv/sim/trajectory.hpp"

#include <algorithm>
#include <cmath>
#include <random>

namespace agv::sim {

bool parse_trajectory_kind(const std::string& name, TrajectoryKind* out) {
  static const std::pair<const char*, TrajectoryKind> kNames[] = {
      {"line", TrajectoryKind::kLine},       {"calibration", TrajectoryKind::kCalibration},
      {"square", TrajectoryKind::kSquare},   {"circle", TrajectoryKind::kCircle},
      {"figure8", TrajectoryKind::kFigure8}, {"lawnmower", TrajectoryKind::kLawnmower}};
  for (const auto& [n, k] : kNames) {
    if (name == n) {
      *out = k;
      return true;
    }
  }
  return false;
}

const char* to_string(TrajectoryKind k) {
  switch (k) {
    case TrajectoryKind::kCalibration:
      return "calibration";
    case TrajectoryKind::kLine:
      return "line";
    case TrajectoryKind::kSquare:
      return "square";
    case TrajectoryKind::kCircle:
      return "circle";
    case TrajectoryKind::kFigure8:
      return "figure8";
    case TrajectoryKind::kLawnmower:
      return "lawnmower";
  }
  return "?";
}

namespace {

// Pose after driving s along a segment from `start`.
Pose2 advance(const Pose2& start, const Segment& seg, double s) {
  const double k = seg.curvature_per_mm;
  const double th0 = start.theta_rad;
  if (std::abs(k) < 1e-12) {
    return {start.x_mm + s * std::cos(th0), start.y_mm + s * std::sin(th0), th0};
  }
  const double th1 = th0 + k * s;
  return {start.x_mm + (std::sin(th1) - std::sin(th0)) / k,
          start.y_mm - (std::cos(th1) - std::cos(th0)) / k, wrap_angle_rad(th1)};
}

Segment straight(double len) { return {len, 0.0}; }

Move make_move(bool rotate, double amount, double peak, double accel, double pause_s) {
  Move m;
  m.rotate = rotate;
  m.amount = amount;
  m.accel = accel;
  m.pause_s = pause_s;
  const double a = std::abs(amount);
  double tr = peak / accel;
  if (accel * tr * tr > a) {
    tr = std::sqrt(a / accel);
    peak = accel * tr;
    m.cruise_s = 0.0;
  } else {
    m.cruise_s = (a - accel * tr * tr) / peak;
  }
  m.peak = peak;
  m.ramp_s = tr;
  return m;
}

// Distance (or angle magnitude) covered and rate (>= 0) at time u into the move.
void move_progress(const Move& m, double u, double* pos, double* rate) {
  const double tr = m.ramp_s, tc = m.cruise_s, a = m.accel, total = std::abs(m.amount);
  if (u <= 0.0) {
    *pos = 0.0;
    *rate = 0.0;
  } else if (u < tr) {
    *pos = 0.5 * a * u * u;
    *rate = a * u;
  } else if (u < tr + tc) {
    *pos = 0.5 * a * tr * tr + m.peak * (u - tr);
    *rate = m.peak;
  } else if (u < 2 * tr + tc) {
    const double r = 2 * tr + tc - u;
    *pos = total - 0.5 * a * r * r;
    *rate = a * r;
  } else {
    *pos = total;
    *rate = 0.0;
  }
}

Pose2 move_pose(const Pose2& start, const Move& m, double pos) {
  if (m.rotate) {
    return {start.x_mm, start.y_mm, wrap_angle_rad(start.theta_rad + (m.amount < 0 ? -pos : pos))};
  }
  return {start.x_mm + pos * std::cos(start.theta_rad),
          start.y_mm + pos * std::sin(start.theta_rad), start.theta_rad};
}
// Arc turning by angle_rad (positive = left) with radius r.
Segment arc(double r, double angle_rad) {
  return {r * std::abs(angle_rad), angle_rad > 0 ? 1.0 / r : -1.0 / r};
}

// Why `p` cannot make a trajectory, or "" when its numbers are in range.
std::string params_error(const TrajectoryParams& p) {
  if (!(p.speed_mps > 0.0 && p.speed_mps <= 5.0)) return "speed must be in (0, 5] m/s";
  if (!(p.accel_mps2 > 0.0 && p.accel_mps2 <= 10.0)) return "acceleration must be in (0, 10] m/s^2";
  if (!(p.grid_spacing_mm >= 200.0 && p.grid_spacing_mm <= 100000.0)) {
    return "grid spacing must be in [200, 100000] mm";
  }
  if (p.grid_columns < 2 || p.grid_rows < 2 || p.grid_columns > 1000 || p.grid_rows > 1000) {
    return "grid must have 2..1000 columns and rows";
  }
  if (!(p.lead_mm >= 100.0 && p.lead_mm <= 100000.0)) return "lead must be in [100, 100000] mm";
  if (!std::isfinite(p.lateral_offset_mm) || !std::isfinite(p.grid_origin_mm.x) ||
      !std::isfinite(p.grid_origin_mm.y)) {
    return "grid origin and lateral offset must be finite";
  }
  return "";
}

// The calibration drive: stop-and-go moves with spins, and the start time, distance and pose of
// each move; the repeated block runs from the second move to the end.
void plan_calibration(const TrajectoryParams& p, Trajectory* tr) {
  const double d = p.grid_spacing_mm, a = p.lead_mm;
  const double gx = p.grid_origin_mm.x, gy = p.grid_origin_mm.y, o = p.lateral_offset_mm;
  const int n = std::min(4, p.grid_columns);
  const double acc_v = std::max(p.accel_mps2, 1.5) * 1000.0, v = p.speed_mps * 1000.0;
  const double w_peak = 0.8, acc_w = 3.0, pause = 0.3;
  auto go = [&](double mm) { tr->moves.push_back(make_move(false, mm, v, acc_v, pause)); };
  auto turn = [&](double rad) { tr->moves.push_back(make_move(true, rad, w_peak, acc_w, pause)); };
  tr->start = {gx - a, gy + o, 0.0};
  go(a);
  turn(2 * kPi);
  for (int i = 1; i < n; ++i) {
    go(d);
    turn(i % 2 ? -kPi / 2 : kPi / 2);
    turn(i % 2 ? kPi / 2 : -kPi / 2);
  }
  turn(kPi);
  for (int i = 1; i < n; ++i) go(d);
  turn(-kPi);
  double t = 0.0, sm = 0.0;
  Pose2 pose = tr->start;
  for (size_t i = 0; i < tr->moves.size(); ++i) {
    if (i == 1) {
      tr->block_duration_s = -t;
      tr->block_length_mm = -sm;
    }
    tr->move_start_t_s.push_back(t);
    tr->move_start_s_mm.push_back(sm);
    tr->move_start_pose.push_back(pose);
    const Move& m = tr->moves[i];
    pose = move_pose(pose, m, std::abs(m.amount));
    t += m.duration_s();
    if (!m.rotate) sm += m.amount;
  }
  tr->block_duration_s += t;
  tr->block_length_mm += sm;
  tr->length_mm = sm;
  tr->closure_error_mm =
      std::hypot(pose.x_mm - tr->move_start_pose[1].x_mm, pose.y_mm - tr->move_start_pose[1].y_mm);
}

}  // namespace

bool make_trajectory(const TrajectoryParams& p, Trajectory* out, std::string* error) {
  auto fail = [&](const std::string& why) {
    if (error) *error = why;
    return false;
  };
  if (const std::string why = params_error(p); !why.empty()) return fail(why);
  const double d = p.grid_spacing_mm, a = p.lead_mm;
  const double w = (p.grid_columns - 1) * d, h = (p.grid_rows - 1) * d;
  const double gx = p.grid_origin_mm.x, gy = p.grid_origin_mm.y, o = p.lateral_offset_mm;
  Trajectory tr;
  tr.params = p;
  std::vector<Segment>& s = tr.segments;
  switch (p.kind) {
    case TrajectoryKind::kLine:
      tr.start = {gx - a, gy + o, 0.0};
      s = {straight(w + 2 * a), arc(d / 2, kPi), straight(w + 2 * a), arc(d / 2, kPi)};
      break;
    case TrajectoryKind::kSquare: {
      const double r = std::min(a, 0.25 * std::min(w, h));
      tr.start = {gx + r, gy + o, 0.0};
      s = {straight(w - 2 * r), arc(r, kPi / 2), straight(h - 2 * r), arc(r, kPi / 2),
           straight(w - 2 * r), arc(r, kPi / 2), straight(h - 2 * r), arc(r, kPi / 2)};
      break;
    }
    case TrajectoryKind::kCircle: {
      const Vec2 c{gx + 0.5 * w, gy + 0.5 * h};
      tr.start = {c.x, c.y - d + o, 0.0};
      s = {arc(d - o, 2 * kPi)};
      break;
    }
    case TrajectoryKind::kFigure8: {
      const Vec2 c{gx + 0.5 * w, gy + 0.5 * h};
      tr.start = {c.x + o, c.y, kPi / 2};
      s = {arc(d, 2 * kPi), arc(d, -2 * kPi)};
      break;
    }
    case TrajectoryKind::kCalibration:
      plan_calibration(p, &tr);
      *out = std::move(tr);
      return true;
    case TrajectoryKind::kLawnmower: {
      const int n = p.lawnmower_rows;
      if (n < 2 || n % 2 != 0 || n > p.grid_rows + 1) {
        return fail("lawnmower rows must be even, >= 2 and at most grid rows + 1");
      }
      const double r = std::min(0.5 * a, 0.25 * d);
      tr.start = {gx - a, gy + o, 0.0};
      for (int i = 0; i < n; ++i) {
        s.push_back(straight(w + 2 * a));
        if (i < n - 1) s.push_back(arc(d / 2, i % 2 == 0 ? kPi : -kPi));
      }
      s.push_back(arc(r, kPi / 2));
      s.push_back(straight((n - 1) * d - 2 * r));
      s.push_back(arc(r, kPi / 2));
      break;
    }
  }
  double acc = 0.0;
  Pose2 pose = tr.start;
  for (const Segment& seg : s) {
    if (!(seg.length_mm > 0.0)) return fail("grid too small for this trajectory");
    tr.seg_start_s_mm.push_back(acc);
    tr.seg_start_pose.push_back(pose);
    pose = advance(pose, seg, seg.length_mm);
    acc += seg.length_mm;
  }
  tr.length_mm = acc;
  tr.closure_error_mm = std::hypot(pose.x_mm - tr.start.x_mm, pose.y_mm - tr.start.y_mm);
  *out = std::move(tr);
  return true;
}

MotionState trajectory_state(const Trajectory& tr, std::int64_t t_ns) {
  MotionState m;
  if ((tr.segments.empty() && tr.moves.empty()) || t_ns <= 0) {
    m.pose = tr.start;
    return m;
  }
  const double t = static_cast<double>(t_ns) * 1e-9;
  if (!tr.moves.empty()) {
    // Timed program: lead-in, then the block repeated.
    double u = t, s_base = 0.0;
    size_t i = 0;
    const double lead_t = tr.moves[0].duration_s();
    if (u >= lead_t && tr.block_duration_s > 0.0) {
      const double k = std::floor((u - lead_t) / tr.block_duration_s);
      u -= k * tr.block_duration_s;
      s_base = k * tr.block_length_mm;
    }
    auto it = std::upper_bound(tr.move_start_t_s.begin(), tr.move_start_t_s.end(), u);
    i = static_cast<size_t>(std::max<std::ptrdiff_t>(0, it - tr.move_start_t_s.begin() - 1));
    const Move& mv = tr.moves[i];
    double pos = 0.0, rate = 0.0;
    move_progress(mv, u - tr.move_start_t_s[i], &pos, &rate);
    m.pose = move_pose(tr.move_start_pose[i], mv, pos);
    m.s_mm = s_base + tr.move_start_s_mm[i] + (mv.rotate ? 0.0 : pos);
    m.v_mps = mv.rotate ? 0.0 : rate * 1e-3;
    m.omega_radps = mv.rotate ? (mv.amount < 0 ? -rate : rate) : 0.0;
    return m;
  }
  const double vmax = tr.params.speed_mps, acc = tr.params.accel_mps2;
  const double t_ramp = vmax / acc;
  double s_m = 0.0;
  if (t < t_ramp) {
    m.v_mps = acc * t;
    s_m = 0.5 * acc * t * t;
  } else {
    m.v_mps = vmax;
    s_m = 0.5 * acc * t_ramp * t_ramp + vmax * (t - t_ramp);
  }
  m.s_mm = s_m * 1000.0;
  const double lap_s = std::fmod(m.s_mm, tr.length_mm);
  auto it = std::upper_bound(tr.seg_start_s_mm.begin(), tr.seg_start_s_mm.end(), lap_s);
  const size_t i =
      static_cast<size_t>(std::max<std::ptrdiff_t>(0, it - tr.seg_start_s_mm.begin() - 1));
  const Segment& seg = tr.segments[i];
  m.pose = advance(tr.seg_start_pose[i], seg, lap_s - tr.seg_start_s_mm[i]);
  m.omega_radps = m.v_mps * 1000.0 * seg.curvature_per_mm;
  return m;
}

std::vector<SlipEvent> make_slip_events(const OdometryParams& p, std::int64_t duration_ns) {
  std::vector<SlipEvent> ev;
  if (!(p.slip_rate_per_s > 0.0) || duration_ns <= 0) return ev;
  std::mt19937_64 rng(p.seed * 0x9E3779B97F4A7C15ULL + 17);
  std::exponential_distribution<double> gap(p.slip_rate_per_s);
  std::bernoulli_distribution right(0.5);
  double t = 0.0;
  const double dur = static_cast<double>(duration_ns) * 1e-9;
  while (true) {
    t += gap(rng);
    if (t >= dur || ev.size() > 1000000) break;
    const auto t0 = static_cast<std::int64_t>(t * 1e9);
    ev.push_back({t0, t0 + static_cast<std::int64_t>(p.slip_duration_s * 1e9), right(rng)});
  }
  return ev;
}

namespace {

double hash_gauss(std::uint64_t seed, std::int64_t t_ns, std::uint64_t stream) {
  auto mix = [](std::uint64_t x) {
    x += 0x9e3779b97f4a7c15ULL;
    x = (x ^ (x >> 30)) * 0xbf58476d1ce4e5b9ULL;
    x = (x ^ (x >> 27)) * 0x94d049bb133111ebULL;
    return x ^ (x >> 31);
  };
  const std::uint64_t h1 = mix(seed ^ mix(static_cast<std::uint64_t>(t_ns) ^ mix(stream)));
  const std::uint64_t h2 = mix(h1);
  const double u1 = (static_cast<double>(h1 >> 11) + 0.5) * (1.0 / 9007199254740992.0);
  const double u2 = static_cast<double>(h2 >> 11) * (1.0 / 9007199254740992.0);
  return std::sqrt(-2.0 * std::log(u1)) * std::cos(2.0 * kPi * u2);
}

}  // namespace

bool parse_odom_sample_timing(const std::string& name, OdomSampleTiming* out) {
  if (name == "period_mean") {
    *out = OdomSampleTiming::kPeriodMean;
  } else if (name == "instant") {
    *out = OdomSampleTiming::kInstant;
  } else {
    return false;
  }
  return true;
}

const char* to_string(OdomSampleTiming t) {
  return t == OdomSampleTiming::kPeriodMean ? "period_mean" : "instant";
}

OdometrySample true_odometry(const OdometryParams& p, const Trajectory& tr, std::int64_t t_ns) {
  const MotionState now = trajectory_state(tr, t_ns);
  if (p.timing == OdomSampleTiming::kInstant || p.period_ns <= 0) {
    return {now.v_mps, now.omega_radps};
  }
  // Encoder ticks over the period = distance and heading change between its ends. The heading
  // change is unwrapped by summing wrapped differences over sub-intervals that each turn less
  // than a quarter turn at the path's tightest curvature (one sub-interval at ordinary rates).
  double k_max = 0.0;
  for (const Segment& seg : tr.segments) k_max = std::max(k_max, std::abs(seg.curvature_per_mm));
  const double period_s = static_cast<double>(p.period_ns) * 1e-9;
  double max_turn_rad = tr.params.speed_mps * 1000.0 * k_max * period_s;
  for (const Move& mv : tr.moves) {
    if (mv.rotate) max_turn_rad = std::max(max_turn_rad, mv.peak * period_s);
  }
  const auto n = static_cast<std::int64_t>(std::ceil(max_turn_rad / (0.5 * kPi))) + 1;
  MotionState prev = trajectory_state(tr, t_ns - p.period_ns);
  const double s0_mm = prev.s_mm;
  double turned_rad = 0.0;
  for (std::int64_t i = 1; i <= n; ++i) {
    const MotionState cur =
        i == n ? now : trajectory_state(tr, t_ns - p.period_ns + p.period_ns * i / n);
    turned_rad += wrap_angle_rad(cur.pose.theta_rad - prev.pose.theta_rad);
    prev = cur;
  }
  return {(now.s_mm - s0_mm) * 1e-3 / period_s, turned_rad / period_s};
}

OdometrySample odometry_sample(const OdometryParams& p, const std::vector<SlipEvent>& slips,
                               const Trajectory& tr, std::int64_t t_ns) {
  return odometry_sample(p, slips, true_odometry(p, tr, t_ns), t_ns);
}

OdometrySample odometry_sample(const OdometryParams& p, const std::vector<SlipEvent>& slips,
                               const OdometrySample& truth, std::int64_t t_ns) {
  const double b_m = p.wheelbase_mm * 1e-3;
  const double vl = truth.v_mps - 0.5 * truth.omega_radps * b_m;
  const double vr = truth.v_mps + 0.5 * truth.omega_radps * b_m;
  double rl = vl * (1.0 + p.scale_error - 0.5 * p.scale_asymmetry);
  double rr = vr * (1.0 + p.scale_error + 0.5 * p.scale_asymmetry);
  // Encoders read exactly zero at standstill; noise only while a wheel turns.
  if (vl != 0.0) rl += p.noise_mps * hash_gauss(p.seed, t_ns, 1);
  if (vr != 0.0) rr += p.noise_mps * hash_gauss(p.seed, t_ns, 2);
  // Slip: the wheel spins, reporting more travel than the floor contact made.
  auto it = std::upper_bound(slips.begin(), slips.end(), t_ns,
                             [](std::int64_t t, const SlipEvent& e) { return t < e.t_start_ns; });
  if (it != slips.begin()) {
    const SlipEvent& e = *(it - 1);
    if (t_ns < e.t_end_ns) {
      if (e.right_wheel) {
        rr += p.slip_excess * vr;
      } else {
        rl += p.slip_excess * vl;
      }
    }
  }
  double omega = b_m > 0.0 ? (rr - rl) / b_m : 0.0;
  // Only when set, so default recordings stay byte-identical.
  if (p.yaw_rate_scale_error != 0.0) omega *= 1.0 + p.yaw_rate_scale_error;
  if (p.yaw_rate_bias_radps != 0.0) omega += p.yaw_rate_bias_radps;
  return {0.5 * (rl + rr), omega};
}

}  // namespace agv::sim
