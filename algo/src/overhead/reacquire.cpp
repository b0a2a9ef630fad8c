// Re-acquisition of lost vehicles from learned tray boxes (reacquire.hpp).
#include "agv/overhead/reacquire.hpp"

#include <algorithm>
#include <cmath>

#include "agv/overhead/tag_fix.hpp"

namespace agv::overhead {

std::string validate(const ReacquireParams& p) {
  if (!(p.max_speed_mps > 0.0)) return "max_speed_mps must be > 0";
  if (!(p.max_turn_rate_radps > 0.0)) return "max_turn_rate_radps must be > 0";
  if (!(p.max_lost_s > 0.0)) return "max_lost_s must be > 0";
  if (p.sweep_every_frames < 1) return "sweep_every_frames must be >= 1";
  if (!(p.min_score > 0.0 && p.min_score <= 1.0)) return "min_score must be in (0, 1]";
  if (!(p.max_size_error_rel > 0.0 && p.max_size_error_rel < 1.0)) {
    return "max_size_error_rel must be in (0, 1)";
  }
  if (!(p.explained_mm > 0.0)) return "explained_mm must be > 0";
  if (!(p.min_travel_mm > 0.0)) return "min_travel_mm must be > 0";
  if (!(p.max_travel_angle_rad > 0.0 && p.max_travel_angle_rad < 0.5 * kPi)) {
    return "max_travel_angle_rad must be in (0, pi/2)";
  }
  if (!(p.max_pair_gap_s > 0.0)) return "max_pair_gap_s must be > 0";
  return "";
}

const char* to_string(ReacquireOutcome o) {
  switch (o) {
    case ReacquireOutcome::kAssigned:
      return "assigned";
    case ReacquireOutcome::kExplained:
      return "explained";
    case ReacquireOutcome::kNoCandidate:
      return "no candidate";
    case ReacquireOutcome::kAmbiguous:
      return "ambiguous";
    case ReacquireOutcome::kHeadingUnknown:
      return "heading unknown";
  }
  return "?";
}

double reach_radius_mm(const LostVehicle& v, std::int64_t t_ns, const ReacquireParams& p) {
  const double dt_s = std::max(0.0, 1e-9 * static_cast<double>(t_ns - v.last_fix_t_ns));
  return 3.0 * v.last_sigma_xy_mm + 1000.0 * p.max_speed_mps * dt_s;
}

std::vector<Vec2> sweep_tiles(const site::CeilingCamera& cam, double plane_mm, double window_mm,
                              double tray_length_mm) {
  const CameraIntrinsics& k = cam.intrinsics;
  Vec2 lo{1e300, 1e300}, hi{-1e300, -1e300};
  int seen = 0;
  // The image's outline on the plane (its edges sampled: distortion bends them).
  constexpr int kSteps = 8;
  for (int i = 0; i <= kSteps; ++i) {
    const double f = static_cast<double>(i) / kSteps;
    for (const Vec2 px :
         {Vec2{f * (k.width_px - 1), 0.0}, Vec2{f * (k.width_px - 1), k.height_px - 1.0},
          Vec2{0.0, f * (k.height_px - 1)}, Vec2{k.width_px - 1.0, f * (k.height_px - 1)}}) {
      Vec2 xy;
      if (!pixel_to_plane(cam, px, plane_mm, &xy)) continue;
      lo = {std::min(lo.x, xy.x), std::min(lo.y, xy.y)};
      hi = {std::max(hi.x, xy.x), std::max(hi.y, xy.y)};
      ++seen;
    }
  }
  std::vector<Vec2> out;
  const double step = window_mm - tray_length_mm;
  if (seen == 0 || !(step > 0.0)) return out;
  const auto count = [&](double span) {
    return std::max(1, static_cast<int>(std::ceil(span / step)));
  };
  const int nx = count(hi.x - lo.x), ny = count(hi.y - lo.y);
  // Centred on the footprint: the first and last tiles overhang it equally.
  const double x0 = 0.5 * (lo.x + hi.x) - 0.5 * step * (nx - 1);
  const double y0 = 0.5 * (lo.y + hi.y) - 0.5 * step * (ny - 1);
  for (int j = 0; j < ny; ++j) {
    for (int i = 0; i < nx; ++i) out.push_back({x0 + step * i, y0 + step * j});
  }
  return out;
}

std::vector<PlaneTray> merge_sweep_boxes(const std::vector<PlaneTray>& boxes, double min_score,
                                         double merge_mm) {
  std::vector<PlaneTray> sorted;
  for (const PlaneTray& b : boxes) {
    if (b.score >= min_score) sorted.push_back(b);
  }
  std::stable_sort(sorted.begin(), sorted.end(),
                   [](const PlaneTray& a, const PlaneTray& b) { return a.score > b.score; });
  std::vector<PlaneTray> out;
  for (const PlaneTray& b : sorted) {
    bool dup = false;
    for (const PlaneTray& k : out) {
      dup = dup ||
            std::hypot(b.centre_mm.x - k.centre_mm.x, b.centre_mm.y - k.centre_mm.y) < merge_mm;
    }
    if (!dup) out.push_back(b);
  }
  return out;
}

namespace {

bool tray_size_fits(const PlaneTray& t, const site::FleetAgv& a, double rel) {
  const double known_long = std::max(a.tray_length_mm, a.tray_width_mm);
  const double known_short = std::min(a.tray_length_mm, a.tray_width_mm);
  return std::abs(t.length_mm / known_long - 1.0) <= rel &&
         std::abs(t.width_mm / known_short - 1.0) <= rel;
}

bool in_disk(const PlaneTray& t, const LostVehicle& v, std::int64_t t_ns,
             const ReacquireParams& p) {
  const double d = std::hypot(t.centre_mm.x - v.last_pose.x_mm, t.centre_mm.y - v.last_pose.y_mm);
  return d <= reach_radius_mm(v, t_ns, p);
}

bool explained_by(const PlaneTray& t, const std::vector<Vec2>& explained, double within_mm) {
  for (const Vec2& e : explained) {
    if (std::hypot(t.centre_mm.x - e.x, t.centre_mm.y - e.y) < within_mm) return true;
  }
  return false;
}

}  // namespace

std::vector<ReacquireBox> assign_boxes(const std::vector<PlaneTray>& boxes,
                                       const std::vector<LostVehicle>& lost,
                                       const std::vector<Vec2>& explained,
                                       const std::vector<site::FleetAgv>& fleet, std::int64_t t_ns,
                                       const ReacquireParams& p) {
  std::vector<ReacquireBox> out(boxes.size());
  // Per box the lost vehicles it may be, per vehicle how many boxes it may be.
  std::vector<std::vector<std::size_t>> cands(boxes.size());
  std::vector<int> boxes_of(lost.size(), 0);
  for (std::size_t b = 0; b < boxes.size(); ++b) {
    out[b].tray = boxes[b];
    if (explained_by(boxes[b], explained, p.explained_mm)) {
      out[b].outcome = ReacquireOutcome::kExplained;
      continue;
    }
    for (std::size_t v = 0; v < lost.size(); ++v) {
      const LostVehicle& l = lost[v];
      if (l.agv >= fleet.size() || !in_disk(boxes[b], l, t_ns, p) ||
          !tray_size_fits(boxes[b], fleet[l.agv], p.max_size_error_rel)) {
        continue;
      }
      cands[b].push_back(v);
      ++boxes_of[v];
    }
  }
  for (std::size_t b = 0; b < boxes.size(); ++b) {
    if (out[b].outcome == ReacquireOutcome::kExplained) continue;
    if (cands[b].empty()) {
      out[b].outcome = ReacquireOutcome::kNoCandidate;
    } else if (cands[b].size() > 1 || boxes_of[cands[b][0]] > 1) {
      out[b].outcome = ReacquireOutcome::kAmbiguous;
    } else {
      out[b].outcome = ReacquireOutcome::kAssigned;
      out[b].agv = lost[cands[b][0]].agv;
    }
  }
  return out;
}

bool resolve_heading(const PlaneTray& box, const LostVehicle& v, std::int64_t t_ns,
                     bool have_previous, const PlaneTray& previous, std::int64_t previous_t_ns,
                     const site::FleetAgv& agv, const ReacquireParams& p, double* theta_rad) {
  const bool long_is_x = agv.tray_length_mm >= agv.tray_width_mm;
  const double axis = wrap_angle_rad(long_is_x ? box.axis_rad : box.axis_rad + 0.5 * kPi);
  const auto nearer = [&](double ref) {
    return std::abs(wrap_angle_rad(axis - ref)) <= 0.5 * kPi ? axis : wrap_angle_rad(axis + kPi);
  };
  const double dt_s = std::max(0.0, 1e-9 * static_cast<double>(t_ns - v.last_fix_t_ns));
  // The most the heading can have changed: the fix's own 3 sigma, then the top turn rate.
  const double turn_max = 3.0 * v.last_sigma_theta_rad + p.max_turn_rate_radps * dt_s;
  if (turn_max < 0.5 * kPi - p.max_travel_angle_rad) {
    *theta_rad = nearer(v.last_pose.theta_rad);
    return true;
  }
  if (!p.forward_only || !have_previous) return false;
  const double gap_s = 1e-9 * static_cast<double>(t_ns - previous_t_ns);
  const Vec2 d{box.centre_mm.x - previous.centre_mm.x, box.centre_mm.y - previous.centre_mm.y};
  if (!(gap_s > 0.0 && gap_s <= p.max_pair_gap_s) || std::hypot(d.x, d.y) < p.min_travel_mm) {
    return false;
  }
  const double travel = std::atan2(d.y, d.x);
  const double theta = nearer(travel);
  if (std::abs(wrap_angle_rad(theta - travel)) > p.max_travel_angle_rad) return false;
  *theta_rad = theta;
  return true;
}

}  // namespace agv::overhead
