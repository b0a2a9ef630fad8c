// The vehicle calibration's least-squares problem (Ceres), shared by its two halves:
// calib_vehicle.cpp builds and solves it, calib_vehicle_report.cpp turns the solution into the
// report. Model: calib_vehicle.hpp.
#pragma once

#include <ceres/ceres.h>

#include <array>
#include <cmath>
#include <cstdint>
#include <limits>
#include <map>
#include <utility>
#include <vector>

#include "calib_vehicle.hpp"

namespace agv::desk::vcal::detail {

constexpr int kMount = 6;  // offset_x_mm, offset_y_mm, yaw_rad, height_mm, roll_rad, pitch_rad
constexpr int kOdo = 4;    // speed_scale, yaw_rate_scale, yaw_rate_bias_radps, yaw_per_metre_rad
constexpr int kNumGlobal = kMount + kOdo + 1;
constexpr double kInf = std::numeric_limits<double>::infinity();

inline double as_double(double x) { return x; }
template <typename T, int N>
double as_double(const ceres::Jet<T, N>& j) {
  return j.a;
}

// Odometry on the odometry clock, seconds relative to a reference (for precision).
struct OdomTable {
  std::vector<double> t;  // stamps T_k, s
  std::vector<double> v_mmps, w;
  double quarter_track_sq_mm2 = 0.0;  // track^2 / 4: the unequal wheels' speed term
};

// Relative motion (dx, dy, dtheta) in the frame at camera time a, from a to b (b >= a), with
// the rates of calib_vehicle.hpp.
template <typename T>
void integrate(const OdomTable& od, double a_s, double b_s, const T* odo, const T* dt, T* rel) {
  const T a = T(a_s) + dt[0], b = T(b_s) + dt[0];
  T x(0.0), y(0.0), th(0.0);
  // First sample whose interval (T_{k-1}, T_k] can overlap [a, b].
  const double a_d = a_s + as_double(dt[0]) - 1e-3;  // generous margin
  size_t k = static_cast<size_t>(std::lower_bound(od.t.begin(), od.t.end(), a_d) - od.t.begin());
  if (k == 0) k = 1;
  for (; k < od.t.size(); ++k) {
    const T lo_k(od.t[k - 1]), hi_k(od.t[k]);
    if (!(lo_k < b)) break;
    const T lo = a > lo_k ? a : lo_k;
    const T hi = b < hi_k ? b : hi_k;
    if (!(hi > lo)) continue;
    const T h = hi - lo;
    const T dth = (odo[1] * od.w[k] + odo[2] + odo[3] * (1e-3 * od.v_mmps[k])) * h;
    const T mid = th + 0.5 * dth;
    const T ds = (odo[0] * od.v_mmps[k] + odo[3] * (1e-3 * od.quarter_track_sq_mm2) * od.w[k]) * h;
    x += ds * cos(mid);
    y += ds * sin(mid);
    th += dth;
  }
  rel[0] = x;
  rel[1] = y;
  rel[2] = th;
}

template <typename T>
void rotation_vc(const T* m, T r[9]) {
  const T cy = cos(m[2]), sy = sin(m[2]), cp = cos(m[5]), sp = sin(m[5]), cr = cos(m[4]),
          sr = sin(m[4]);
  const T b[9] = {cy * cp,
                  cy * sp * sr - sy * cr,
                  cy * sp * cr + sy * sr,
                  sy * cp,
                  sy * sp * sr + cy * cr,
                  sy * sp * cr - cy * sr,
                  -sp,
                  cp * sr,
                  cp * cr};
  for (int i = 0; i < 3; ++i) {
    r[3 * i + 0] = -b[3 * i + 1];
    r[3 * i + 1] = -b[3 * i + 0];
    r[3 * i + 2] = -b[3 * i + 2];
  }
}

struct FrameCost {
  const OdomTable* od;
  double t_anchor_s, t_frame_s;
  Pose2 landmark;             // world <- landmark
  std::array<Vec2, 8> local;  // printed corners in the landmark frame
  std::array<Vec2, 8> xn;
  std::array<bool, 8> valid;
  double scale;  // fx / sigma; the landmark's sigma after the first solve

  // off: the landmark's corner offsets (x, y per corner, landmark frame, mm).
  template <typename T>
  bool operator()(const T* mount, const T* odo, const T* dt, const T* anchor, const T* off,
                  T* res) const {
    T rel[3];
    integrate(*od, t_anchor_s, t_frame_s, odo, dt, rel);
    const T ca = cos(anchor[2]), sa = sin(anchor[2]);
    const T px = anchor[0] + ca * rel[0] - sa * rel[1];
    const T py = anchor[1] + sa * rel[0] + ca * rel[1];
    const T th = anchor[2] + rel[2];
    const T c = cos(th), s = sin(th);
    T r[9];
    rotation_vc(mount, r);
    const double cl = std::cos(landmark.theta_rad), sl = std::sin(landmark.theta_rad);
    for (int i = 0; i < 8; ++i) {
      if (!valid[static_cast<size_t>(i)]) {
        res[2 * i] = T(0.0);
        res[2 * i + 1] = T(0.0);
        continue;
      }
      const T lx = T(local[static_cast<size_t>(i)].x) + off[2 * i],
              ly = T(local[static_cast<size_t>(i)].y) + off[2 * i + 1];
      const T wx = T(landmark.x_mm) + cl * lx - sl * ly - px,
              wy = T(landmark.y_mm) + sl * lx + cl * ly - py;
      const T vx = c * wx + s * wy - mount[0], vy = -s * wx + c * wy - mount[1], vz = -mount[3];
      const T xc = r[0] * vx + r[3] * vy + r[6] * vz;
      const T yc = r[1] * vx + r[4] * vy + r[7] * vz;
      const T zc = r[2] * vx + r[5] * vy + r[8] * vz;
      res[2 * i] = (xc / zc - xn[static_cast<size_t>(i)].x) * scale;
      res[2 * i + 1] = (yc / zc - xn[static_cast<size_t>(i)].y) * scale;
    }
    return true;
  }
};

struct LinkCost {
  const OdomTable* od;
  double t_a_s, t_b_s;
  double inv_sigma_pos, inv_sigma_th;

  template <typename T>
  bool operator()(const T* odo, const T* dt, const T* a, const T* b, T* res) const {
    T rel[3];
    integrate(*od, t_a_s, t_b_s, odo, dt, rel);
    // Relative pose A^-1 B vs the odometry's, in A's frame.
    const T ca = cos(a[2]), sa = sin(a[2]);
    const T dx = b[0] - a[0], dy = b[1] - a[1];
    const T lx = ca * dx + sa * dy, ly = -sa * dx + ca * dy;
    T dth = b[2] - a[2] - rel[2];
    // Wrap to (-pi, pi].
    while (dth > T(kPi)) dth -= T(2.0 * kPi);
    while (dth <= T(-kPi)) dth += T(2.0 * kPi);
    res[0] = (lx - rel[0]) * inv_sigma_pos;
    res[1] = (ly - rel[1]) * inv_sigma_pos;
    res[2] = dth * inv_sigma_th;
    return true;
  }
};

// The N(0, tau^2) prior of one landmark's corner offsets; tau is set after the first solve.
struct OffsetPrior {
  const double* inv_tau;
  template <typename T>
  bool operator()(const T* off, T* res) const {
    for (int i = 0; i < 16; ++i) res[i] = off[i] * *inv_tau;
    return true;
  }
};

struct SubPass {
  int pass = 0;
  std::vector<size_t> frames;  // indices into obs
};

struct WearStats {
  double sigma_px = 0.0;  // corner noise about the per-corner means (at least pixel_sigma_px)
  double tau_mm = 0.0;    // RMS of the per-corner means (at least min_print_offset_mm)
  std::array<double, 16> mean_offset_mm{};
};

// The problem and everything the report needs of it. Ceres keeps pointers into the parameter
// arrays: built in place, never moved or resized once the residual blocks are added.
struct Solve {
  OdomTable od;
  std::int64_t t_ref = 0;                        // time origin of od and the costs
  std::vector<CornerObservation> obs;            // mapped, inside the odometry span
  std::vector<std::pair<size_t, size_t>> passes;  // [first, last] obs index
  std::vector<SubPass> subs;
  double mount[kMount] = {};
  double odo[kOdo] = {};
  double dt[1] = {};
  std::vector<std::array<double, 3>> anchors;  // per sub-pass: the vehicle pose at its start
  ceres::Problem problem;
  std::vector<ceres::ResidualBlockId> frame_blocks;
  std::vector<FrameCost*> frame_costs;  // owned by the problem
  std::vector<int> frame_pass, frame_nvalid;
  std::vector<size_t> frame_lm;
  // Landmarks in id order, each with its 16 corner offsets and the inverse of their prior sigma.
  std::map<std::uint32_t, size_t> lm_index;
  std::vector<std::array<double, 16>> offsets;
  std::vector<double> inv_tau;
  std::vector<WearStats> wear;
  // RMS corner residuals (px) with the printed geometry, before and after the solve.
  std::vector<double> before, after, lm_before, lm_after;
  double chi2_scale = 1.0;
};

// The report of a solved problem: parameters with their covariance, passes, landmarks.
void report(const Options& opt, const VehicleParams& initial, Solve& s, Result* out);

}  // namespace agv::desk::vcal::detail
