// CameraFrameProcessor's re-acquisition step (reacquire.hpp): which vehicles are lost, the sweep
// of the view around them with the learned detector, and a track restarted from a box.
#include <algorithm>
#include <cmath>
#include <set>

#include "agv/overhead/camera_frame.hpp"
#include "camera_frame_internal.hpp"

namespace agv::overhead {

namespace {

bool disk_meets_square(Vec2 centre, double radius, Vec2 square_centre, double half) {
  const double dx = std::max(0.0, std::abs(centre.x - square_centre.x) - half);
  const double dy = std::max(0.0, std::abs(centre.y - square_centre.y) - half);
  return std::hypot(dx, dy) <= radius;
}

}  // namespace

// The vehicles to search for: lost (not read this frame, no valid or tentative track) and last
// fixed less than max_lost_s ago. The others' positions explain boxes near them.
std::vector<LostVehicle> CameraFrameProcessor::lost_vehicles(FrameWork* w,
                                                             std::vector<Vec2>* explained) {
  std::vector<LostVehicle> lost;
  const auto max_lost_ns = static_cast<std::int64_t>(reacquire_.max_lost_s * 1e9);
  for (std::size_t i = 0; i < fleet_.size(); ++i) {
    if (w->has_tag_pose[i]) {
      explained->push_back({w->tag_pose[i].x_mm, w->tag_pose[i].y_mm});
      continue;
    }
    const TrackOutput o = w->tracker->output(i, w->t_ns);
    Remembered& r = remembered_[i];
    if (o.valid() || o.state == TrackState::kTentative) {
      explained->push_back({o.pose.x_mm, o.pose.y_mm});
      if (o.valid()) {
        const TrackOutput at_fix = w->tracker->output(i, o.last_fix_t_ns);
        r.known = true;
        r.last = {i, at_fix.pose, at_fix.sigma_xy_mm, at_fix.sigma_theta_rad, o.last_fix_t_ns};
      }
      continue;
    }
    if (r.known && w->t_ns - r.last.last_fix_t_ns <= max_lost_ns) lost.push_back(r.last);
  }
  return lost;
}

// The learned detector on the tiles of the view that meet a lost vehicle's disk, at each lost
// tray height.
std::vector<PlaneTray> CameraFrameProcessor::sweep_for(const cv::Mat& gray, std::size_t camera,
                                                       std::int64_t t_ns,
                                                       const std::vector<LostVehicle>& lost) {
  const TrayNetGeometry& g = reacquire_net_->geometry();
  const double window_mm = g.input_px * g.mm_per_px;
  std::set<double> heights;
  double longest = 0.0;
  for (const LostVehicle& v : lost) {
    heights.insert(fleet_[v.agv].tray_height_mm);
    longest = std::max({longest, fleet_[v.agv].tray_length_mm, fleet_[v.agv].tray_width_mm});
  }
  std::vector<PlaneTray> boxes;
  for (const double h : heights) {
    for (const Vec2& c : sweep_tiles(cameras_[camera], h, window_mm, longest)) {
      bool wanted = false;
      for (const LostVehicle& v : lost) {
        wanted =
            wanted || (fleet_[v.agv].tray_height_mm == h &&
                       disk_meets_square({v.last_pose.x_mm, v.last_pose.y_mm},
                                         reach_radius_mm(v, t_ns, reacquire_), c, 0.5 * window_mm));
      }
      if (!wanted) continue;
      ++counters_.reacquire_windows;
      const std::vector<PlaneTray> found =
          reacquire_net_->detect_on_plane(gray, cameras_[camera], c, h, reacquire_net_params_);
      boxes.insert(boxes.end(), found.begin(), found.end());
    }
  }
  return boxes;
}

void CameraFrameProcessor::reacquire_lost(const cv::Mat& gray, FrameWork* w) {
  std::vector<Vec2> explained;
  const std::vector<LostVehicle> lost = lost_vehicles(w, &explained);
  if (lost.empty()) return;
  if (sweep_frames_[w->camera]++ % static_cast<std::uint64_t>(reacquire_.sweep_every_frames) != 0) {
    return;
  }
  ++counters_.reacquire_sweeps;
  const std::vector<PlaneTray> raw = sweep_for(gray, w->camera, w->t_ns, lost);
  double narrowest = 1e300;
  for (const LostVehicle& v : lost) {
    narrowest = std::min({narrowest, fleet_[v.agv].tray_width_mm, fleet_[v.agv].tray_length_mm});
  }
  const std::vector<PlaneTray> boxes =
      merge_sweep_boxes(raw, reacquire_.min_score, 0.5 * narrowest);
  for (const ReacquireBox& b : assign_boxes(boxes, lost, explained, fleet_, w->t_ns, reacquire_)) {
    if (b.outcome == ReacquireOutcome::kAmbiguous) ++counters_.reacquire_ambiguous;
    if (b.outcome != ReacquireOutcome::kAssigned) continue;
    for (const LostVehicle& v : lost) {
      if (v.agv == b.agv) restart_from_box(gray, b, v, w);
    }
  }
}

// The box's heading resolved, its fix refined by the classical fit when that is the tray method,
// and the vehicle's track restarted from it.
void CameraFrameProcessor::restart_from_box(const cv::Mat& gray, const ReacquireBox& box,
                                            const LostVehicle& v, FrameWork* w) {
  Remembered& r = remembered_[v.agv];
  double theta = 0.0;
  const bool resolved = resolve_heading(box.tray, v, w->t_ns, r.have_box, r.box, r.box_t_ns,
                                        fleet_[v.agv], reacquire_, &theta);
  r.have_box = true;
  r.box = box.tray;
  r.box_t_ns = w->t_ns;
  if (!resolved) {
    ++counters_.reacquire_heading_unknown;
    return;
  }
  const TrayNetParams& np = reacquire_net_params_;
  const double mm_per_px = reacquire_net_->geometry().mm_per_px;
  const double s_mm = np.centre_sigma_px * mm_per_px;
  const std::array<double, 9> resolved_cov{
      s_mm * s_mm, 0, 0, 0, s_mm * s_mm, 0, 0, 0, np.angle_sigma_rad * np.angle_sigma_rad};
  TagFix fix;
  if (!tray_box_fix(box.tray, fleet_[v.agv], {box.tray.centre_mm.x, box.tray.centre_mm.y, theta},
                    resolved_cov, np, mm_per_px, &fix)) {
    return;
  }
  TrayFix refined;
  if (tray_enabled_ && !tray_learned() &&
      fit_tray(gray, cameras_[w->camera], fleet_[v.agv], fix.pose, fix.cov, tray_, &refined)) {
    fix = refined.fix;
  }
  fix.source = static_cast<std::int32_t>(w->camera);
  if (w->tracker->add_fix(v.agv, w->t_ns, fix) == FixResult::kStarted) {
    ++counters_.reacquired;
    r.have_box = false;
  }
}

}  // namespace agv::overhead
