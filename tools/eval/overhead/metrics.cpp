// Scoring of eval_overhead (metrics.hpp).
#include "metrics.hpp"

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>

namespace agv::eval {

double percentile(std::vector<double> v, double q) {
  if (v.empty()) return std::numeric_limits<double>::quiet_NaN();
  const std::size_t k =
      std::min(v.size() - 1, static_cast<std::size_t>(q * static_cast<double>(v.size())));
  std::nth_element(v.begin(), v.begin() + static_cast<std::ptrdiff_t>(k), v.end());
  return v[k];
}

namespace {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

double max_of(const std::vector<double>& v) {
  return v.empty() ? kNaN : *std::max_element(v.begin(), v.end());
}

constexpr double kSwitchMm = 300.0;  // a track this far from its vehicle and nearer another's

double dist(const Pose2& a, const Pose2& b) { return std::hypot(a.x_mm - b.x_mm, a.y_mm - b.y_mm); }

void score_accuracy(const overhead::TrackOutput& o, const Pose2& truth, VehicleScore* v, Score* s) {
  const double ex = o.pose.x_mm - truth.x_mm, ey = o.pose.y_mm - truth.y_mm;
  const double et = wrap_angle_rad(o.pose.theta_rad - truth.theta_rad);
  v->pos_err_mm.push_back(std::hypot(ex, ey));
  v->head_err_deg.push_back(std::abs(rad_to_deg(et)));
  Eigen::Matrix3d p;
  for (int i = 0; i < 9; ++i) p(i / 3, i % 3) = o.cov[static_cast<std::size_t>(i)];
  const Eigen::Vector3d e(ex, ey, et);
  const Eigen::LDLT<Eigen::Matrix3d> ldlt(p);
  if (ldlt.info() == Eigen::Success && ldlt.isPositive()) {
    const double nees = e.dot(ldlt.solve(e));
    if (std::isfinite(nees)) {
      s->nees_sum += nees;
      ++s->nees_n;
      if (nees <= 7.815) ++s->nees_in95;  // chi2, 3 dof, 0.95
    }
  }
  const double err = std::hypot(ex, ey);
  if (err <= 3.0 * o.sigma_xy_mm) ++s->within3;
  if (err > 3.0 * o.sigma_xy_mm && err > 50.0) ++v->confident_wrong;
}

// The covered ticks' own figures (the NEES and identity counts stay with the whole run's).
void score_covered(const overhead::TrackOutput& o, const Pose2& truth, bool in_view,
                   VehicleScore* c) {
  ++c->ticks;
  if (in_view) ++c->in_view;
  if (!o.valid()) return;
  ++c->valid;
  if (in_view) ++c->valid_in_view;
  const double err = dist(o.pose, truth);
  c->pos_err_mm.push_back(err);
  c->head_err_deg.push_back(
      std::abs(rad_to_deg(wrap_angle_rad(o.pose.theta_rad - truth.theta_rad))));
  if (err > 3.0 * o.sigma_xy_mm && err > 50.0) ++c->confident_wrong;
}

}  // namespace

void score_tick(const std::vector<overhead::TrackOutput>& outs,
                const std::vector<sim::AgvState>& truth, const std::vector<std::uint8_t>& in_view,
                Score* s, const std::vector<std::uint8_t>* covered) {
  const std::size_t n = truth.size();
  if (s->vehicles.size() != n) s->vehicles.assign(n, {});
  if (s->pair_close.size() != n) s->pair_close.assign(n, std::vector<std::uint8_t>(n, 0));
  for (const overhead::TrackOutput& o : outs) {
    if (o.agv >= n) continue;
    VehicleScore& v = s->vehicles[o.agv];
    ++v.ticks;
    if (covered && o.agv < covered->size() && (*covered)[o.agv]) {
      score_covered(o, truth[o.agv].pose, in_view[o.agv] != 0, &s->covered);
    }
    if (o.state == overhead::TrackState::kCoasting) {
      score_covered(o, truth[o.agv].pose, in_view[o.agv] != 0, &s->coasting);
    }
    if (in_view[o.agv]) ++v.in_view;
    if (!o.valid()) {
      v.on_other = false;
      continue;
    }
    ++v.valid;
    if (in_view[o.agv]) ++v.valid_in_view;
    score_accuracy(o, truth[o.agv].pose, &v, s);
    const double own = dist(o.pose, truth[o.agv].pose);
    bool other = false;
    for (std::size_t j = 0; j < n; ++j) {
      if (j != o.agv && own > kSwitchMm && dist(o.pose, truth[j].pose) < own) other = true;
    }
    if (other && !v.on_other) ++s->id_switches;
    v.on_other = other;
  }
  for (const overhead::TrackOutput& a : outs) {
    for (const overhead::TrackOutput& b : outs) {
      if (a.agv >= b.agv || b.agv >= n) continue;
      const bool close = a.valid() && b.valid() && dist(a.pose, b.pose) < kSwitchMm;
      std::uint8_t& was = s->pair_close[a.agv][b.agv];
      if (close && !was) ++s->duplicates;
      was = close ? 1 : 0;
    }
  }
}

void score_detections(const std::vector<overhead::Detection>& dets,
                      const std::vector<std::array<Vec2, 4>>& truth_corners,
                      const std::vector<std::uint8_t>& projected,
                      const std::vector<std::uint8_t>& in_image,
                      const std::vector<std::uint8_t>& flipped,
                      const std::vector<std::uint8_t>& tracked, Score* s) {
  auto centre = [](const std::array<Vec2, 4>& c) {
    return Vec2{0.25 * (c[0].x + c[1].x + c[2].x + c[3].x),
                0.25 * (c[0].y + c[1].y + c[2].y + c[3].y)};
  };
  std::vector<std::uint8_t> read(truth_corners.size(), 0), right(truth_corners.size(), 0);
  for (const overhead::Detection& d : dets) {
    ++s->reads;
    if (d.result == overhead::FixResult::kGated) ++s->gated;
    const Vec2 c = centre(d.tag.corners_px);
    const double side = std::hypot(d.tag.corners_px[1].x - d.tag.corners_px[0].x,
                                   d.tag.corners_px[1].y - d.tag.corners_px[0].y);
    std::size_t best = truth_corners.size();
    double best_d = 0.5 * side;
    for (std::size_t j = 0; j < truth_corners.size(); ++j) {
      if (!projected[j]) continue;
      const Vec2 t = centre(truth_corners[j]);
      const double dd = std::hypot(t.x - c.x, t.y - c.y);
      if (dd < best_d) best_d = dd, best = j;
    }
    const bool applied =
        d.result == overhead::FixResult::kApplied || d.result == overhead::FixResult::kStarted;
    if (best == truth_corners.size()) {
      ++s->phantom_reads;
      if (applied) ++s->phantom_fixes;
      continue;
    }
    read[best] = 1;
    if (d.in_fleet && d.agv == best) {
      ++s->right_reads;
      right[best] = 1;
    } else {
      ++s->wrong_reads;
      if (applied) ++s->wrong_fixes;
    }
  }
  for (std::size_t j = 0; j < flipped.size() && j < read.size(); ++j) {
    if (!flipped[j] || !in_image[j]) continue;
    if (read[j] && !right[j]) ++s->flipped_wrong;
    if (j < tracked.size() && tracked[j]) {
      ++s->flipped;
      if (right[j]) ++s->flipped_right;
    } else {
      ++s->flipped_untracked;
      if (right[j]) ++s->flipped_untracked_right;
    }
  }
}

std::string report(const Score& s, const std::vector<std::string>& ids) {
  std::string out;
  char line[512];
  std::snprintf(line, sizeof line, "%-8s %7s %8s %8s %8s %9s %7s %9s %6s\n", "vehicle", "n",
                "p50_mm", "p95_mm", "max_mm", "hd95_deg", "valid%", "inview%", "wrong");
  out += line;
  std::vector<double> all_p, all_h;
  std::uint64_t ticks = 0, valid = 0, in_view = 0, valid_in_view = 0, confident_wrong = 0;
  for (std::size_t i = 0; i < s.vehicles.size(); ++i) {
    const VehicleScore& v = s.vehicles[i];
    all_p.insert(all_p.end(), v.pos_err_mm.begin(), v.pos_err_mm.end());
    all_h.insert(all_h.end(), v.head_err_deg.begin(), v.head_err_deg.end());
    ticks += v.ticks, valid += v.valid, in_view += v.in_view, valid_in_view += v.valid_in_view;
    confident_wrong += v.confident_wrong;
    const double mx = max_of(v.pos_err_mm);
    std::snprintf(
        line, sizeof line, "%-8s %7zu %8.2f %8.2f %8.2f %9.3f %7.1f %9.1f %6llu\n",
        i < ids.size() ? ids[i].c_str() : "?", v.pos_err_mm.size(), percentile(v.pos_err_mm, 0.5),
        percentile(v.pos_err_mm, 0.95), mx, percentile(v.head_err_deg, 0.95),
        v.ticks ? 100.0 * static_cast<double>(v.valid) / static_cast<double>(v.ticks) : 0.0,
        v.in_view ? 100.0 * static_cast<double>(v.valid_in_view) / static_cast<double>(v.in_view)
                  : 0.0,
        static_cast<unsigned long long>(v.confident_wrong));
    out += line;
  }
  const double mx = max_of(all_p);
  auto pct = [](std::uint64_t a, std::uint64_t b) {
    return b ? 100.0 * static_cast<double>(a) / static_cast<double>(b) : 0.0;
  };
  std::snprintf(
      line, sizeof line,
      "overall position error p50 %.2f mm, p95 %.2f mm, max %.2f mm; heading p50 %.3f deg, "
      "p95 %.3f deg, max %.3f deg (%zu outputs)\n",
      percentile(all_p, 0.5), percentile(all_p, 0.95), mx, percentile(all_h, 0.5),
      percentile(all_h, 0.95), max_of(all_h), all_p.size());
  out += line;
  std::snprintf(line, sizeof line,
                "valid ticks %.2f %% of all, %.2f %% of those with the tag in some image; "
                "valid but > 3 sigma and > 50 mm off: %llu\n",
                pct(valid, ticks), pct(valid_in_view, in_view),
                static_cast<unsigned long long>(confident_wrong));
  out += line;
  std::snprintf(
      line, sizeof line,
      "identity: wrong-id fixes %llu (wrong-id reads %llu, phantom reads %llu, phantom "
      "fixes %llu), id switches %llu, duplicate tracks %llu; reads %llu, right %llu, "
      "gated %llu\n",
      static_cast<unsigned long long>(s.wrong_fixes),
      static_cast<unsigned long long>(s.wrong_reads),
      static_cast<unsigned long long>(s.phantom_reads),
      static_cast<unsigned long long>(s.phantom_fixes),
      static_cast<unsigned long long>(s.id_switches), static_cast<unsigned long long>(s.duplicates),
      static_cast<unsigned long long>(s.reads), static_cast<unsigned long long>(s.right_reads),
      static_cast<unsigned long long>(s.gated));
  out += line;
  std::snprintf(line, sizeof line,
                "sigma: NEES mean %.2f (3 dof: 3 if honest), within chi2 95%% %.1f %%, position "
                "within 3 sigma %.1f %%\n",
                s.nees_n ? s.nees_sum / static_cast<double>(s.nees_n) : kNaN,
                pct(s.nees_in95, s.nees_n), pct(s.within3, all_p.size()));
  out += line;
  std::snprintf(line, sizeof line,
                "frame time (thread CPU time, one core): median %.2f ms, p99 %.2f ms, max %.2f ms "
                "over %zu frames; "
                "without a full sweep (%zu): median %.2f ms, p99 %.2f ms, max %.2f ms; with one "
                "(%zu): median %.2f ms\n",
                percentile(s.frame_ms, 0.5), percentile(s.frame_ms, 0.99), max_of(s.frame_ms),
                s.frame_ms.size(), s.frame_windows_ms.size(), percentile(s.frame_windows_ms, 0.5),
                percentile(s.frame_windows_ms, 0.99), max_of(s.frame_windows_ms),
                s.frame_full_ms.size(), percentile(s.frame_full_ms, 0.5));
  out += line;
  if (!s.apriltag_ms.empty()) {
    std::snprintf(line, sizeof line,
                  "libapriltag on the whole frame (decimate 1, one thread, CPU time): median %.1f "
                  "ms over %zu "
                  "frames (%.1fx the pipeline's median)\n",
                  percentile(s.apriltag_ms, 0.5), s.apriltag_ms.size(),
                  percentile(s.apriltag_ms, 0.5) / percentile(s.frame_ms, 0.5));
    out += line;
  }
  if (s.covered.ticks > 0) {
    const VehicleScore& c = s.covered;
    std::snprintf(
        line, sizeof line,
        "tags under a parcel: %llu ticks (%llu with the tag in some image), valid %.2f "
        "%% of them (%.2f %% in view); position p50 %.2f mm, p95 %.2f mm, max %.2f mm; "
        "heading p95 %.3f deg, max %.3f deg; valid but > 3 sigma and > 50 mm off: %llu\n",
        static_cast<unsigned long long>(c.ticks), static_cast<unsigned long long>(c.in_view),
        pct(c.valid, c.ticks), pct(c.valid_in_view, c.in_view), percentile(c.pos_err_mm, 0.5),
        percentile(c.pos_err_mm, 0.95), max_of(c.pos_err_mm), percentile(c.head_err_deg, 0.95),
        max_of(c.head_err_deg), static_cast<unsigned long long>(c.confident_wrong));
    out += line;
  }
  if (s.coasting.ticks > 0) {
    const VehicleScore& c = s.coasting;
    std::snprintf(line, sizeof line,
                  "coasting: %llu ticks (%.2f %% of all); position p50 %.2f mm, p95 %.2f mm, max "
                  "%.2f mm; heading p95 %.3f deg; > 3 sigma and > 50 mm off: %llu\n",
                  static_cast<unsigned long long>(c.ticks), pct(c.ticks, ticks),
                  percentile(c.pos_err_mm, 0.5), percentile(c.pos_err_mm, 0.95),
                  max_of(c.pos_err_mm), percentile(c.head_err_deg, 0.95),
                  static_cast<unsigned long long>(c.confident_wrong));
    out += line;
  }
  if (s.flipped + s.flipped_untracked > 0) {
    std::snprintf(line, sizeof line,
                  "bit errors: tags of tracked vehicles flipped in view %llu, read right %llu "
                  "(%.2f %%); of vehicles without a track %llu, read right %llu; read wrong %llu\n",
                  static_cast<unsigned long long>(s.flipped),
                  static_cast<unsigned long long>(s.flipped_right), pct(s.flipped_right, s.flipped),
                  static_cast<unsigned long long>(s.flipped_untracked),
                  static_cast<unsigned long long>(s.flipped_untracked_right),
                  static_cast<unsigned long long>(s.flipped_wrong));
    out += line;
  }
  return out;
}

}  // namespace agv::eval
