// The per-frame pipeline of one ceiling camera (Yang et al. Algorithm 1): search windows from the
// tracker's predictions, the predicted path with the area's ids first, the global search where it
// fails or where no track leads, then tray-plane fixes into the tracker. docs/design/overhead.md.
#include "agv/overhead/camera_frame.hpp"

#include <algorithm>
#include <cmath>
#include <string>
#include <unordered_set>

#include "agv/overhead/tag_code.hpp"
#include "camera_frame_internal.hpp"

namespace agv::overhead {

CameraFrameProcessor::CameraFrameProcessor(const std::vector<site::CeilingCamera>& cameras,
                                           const std::vector<site::FleetAgv>& fleet,
                                           const TagDetectParams& detect,
                                           const SearchParams& search)
    : cameras_(cameras), fleet_(fleet), detector_(detect), search_(search), state_(cameras.size()) {
  for (std::size_t i = 0; i < fleet_.size(); ++i) agv_of_tag_.emplace(fleet_[i].tag_id, i);
  for (CameraSearchState& s : state_) s.missed.assign(fleet_.size(), 0);
  remembered_.assign(fleet_.size(), {});
  sweep_frames_.assign(cameras_.size(), 0);
}

namespace {

// Kind of window first: the predicted reads are cheap and decode against the area's ids, so a tag
// they find is not decoded again (more strictly) by an area or full-image search of the frame.
std::vector<const SearchWindow*> in_level_order(const std::vector<SearchWindow>& windows) {
  std::vector<const SearchWindow*> order;
  order.reserve(windows.size());
  for (const SearchWindow& w : windows) order.push_back(&w);
  std::stable_sort(order.begin(), order.end(), [](const SearchWindow* a, const SearchWindow* b) {
    return static_cast<int>(a->level) < static_cast<int>(b->level);
  });
  return order;
}

bool wholly_inside(const std::array<Vec2, 4>& corners_px, int width_px, int height_px) {
  constexpr double kMarginPx = 2.0;
  for (const Vec2& c : corners_px) {
    if (!(c.x >= kMarginPx && c.y >= kMarginPx && c.x <= width_px - 1 - kMarginPx &&
          c.y <= height_px - 1 - kMarginPx)) {
      return false;
    }
  }
  return true;
}

}  // namespace

bool CameraFrameProcessor::process(std::size_t camera, std::int64_t t_ns, const cv::Mat& gray,
                                   FleetTracker* tracker, std::vector<Detection>* out,
                                   std::string* error) {
  auto fail = [&](const std::string& why) {
    ++counters_.rejected_frames;
    if (error) *error = why;
    return false;
  };
  if (camera >= cameras_.size()) {
    return fail("camera " + std::to_string(camera) + " out of range (" +
                std::to_string(cameras_.size()) + " cameras)");
  }
  if (tracker == nullptr || tracker->size() != fleet_.size()) {
    return fail("the tracker is missing or not sized for the fleet");
  }
  const CameraIntrinsics& k = cameras_[camera].intrinsics;
  if (gray.empty() || gray.type() != CV_8UC1 || gray.cols != k.width_px ||
      gray.rows != k.height_px) {
    return fail("camera " + cameras_[camera].id + ": frame is not 8-bit gray of " +
                std::to_string(k.width_px) + "x" + std::to_string(k.height_px));
  }
  ++counters_.frames;
  CameraSearchState& state = state_[camera];
  const std::vector<SearchWindow> windows =
      plan_search(cameras_[camera], fleet_, *tracker, t_ns, search_, state);
  ++state.frames;

  FrameWork w;
  w.camera = camera;
  w.t_ns = t_ns;
  w.tracker = tracker;
  w.out = out;
  w.found.assign(fleet_.size(), 0);
  w.looked_for.assign(fleet_.size(), 0);
  w.tray_applied.assign(fleet_.size(), 0);
  w.tag_pose.assign(fleet_.size(), Pose2{});
  w.has_tag_pose.assign(fleet_.size(), 0);
  for (const SearchWindow* win : in_level_order(windows)) {
    // A tag predicted across the image's edge may well be out of it: not finding it there is
    // no miss (an area search of its camera would cost much and find it no better).
    const bool expected = win->level != SearchLevel::kTrack ||
                          wholly_inside(win->predicted_corners_px, k.width_px, k.height_px);
    for (std::size_t agv : win->agvs) {
      if (agv < fleet_.size() && expected) w.looked_for[agv] = 1;
    }
    switch (win->level) {
      case SearchLevel::kTrack:
        ++counters_.windows_track;
        track_window(*win, gray, &w);
        break;
      case SearchLevel::kArea:
        ++counters_.windows_area;
        search_window(*win, gray, &w);
        break;
      case SearchLevel::kFull:
        ++counters_.windows_full;
        search_window(*win, gray, &w);
        break;
    }
  }
  if (tray_enabled_) fit_covered_trays(gray, &w);
  if (reacquiring()) reacquire_lost(gray, &w);
  // A vehicle found by any window is back on its track window next frame; one that a window
  // expected wholly in the image and that none found widens its search, more with every frame
  // in a row (search.hpp); the others (not in this view, or at its edge) keep theirs. A vehicle
  // whose tray box was applied is where its window looked: its tag is under a parcel, and an
  // area search would cost much (the frame time with parcels) and find it no better; its track
  // window still looks for the tag every frame.
  for (std::size_t i = 0; i < fleet_.size(); ++i) {
    if (w.found[i] || (w.tray_applied[i] && search_.tray_box_holds_window)) {
      state.missed[i] = 0;
    } else if (w.looked_for[i] && state.missed[i] < 255) {
      ++state.missed[i];
    }
  }
  return true;
}

void CameraFrameProcessor::track_window(const SearchWindow& win, const cv::Mat& gray,
                                        FrameWork* w) {
  bool pending = false;
  for (std::size_t agv : win.agvs) pending = pending || (agv < fleet_.size() && !w->found[agv]);
  if (!pending) return;
  const std::vector<std::uint32_t> allowed =
      ids_in_area(cameras_[w->camera], fleet_, *w->tracker, w->t_ns, win.rect);
  TagObservation obs;
  if (detector_.detect_predicted(gray, win.predicted_corners_px, allowed, &obs) &&
      w->ids_seen.count(obs.id) == 0) {
    ++counters_.predicted_reads;
    handle_tag(obs, SearchLevel::kTrack, w);
  }
  // The square at the prediction was not the expected vehicle's (or not readable): search the
  // window as a whole with the strict global decode.
  bool still = false;
  for (std::size_t agv : win.agvs) still = still || (agv < fleet_.size() && !w->found[agv]);
  if (still) search_window(win, gray, w);
}

void CameraFrameProcessor::search_window(const SearchWindow& win, const cv::Mat& gray,
                                         FrameWork* w) {
  // An area is searched for its vehicles: once an earlier window of the frame (often another
  // vehicle's overlapping area) has read them all, it would cost much and add nothing the
  // interval's sweep does not look for.
  bool pending = win.level != SearchLevel::kArea;
  for (std::size_t agv : win.agvs) pending = pending || (agv < fleet_.size() && !w->found[agv]);
  const auto inside = [&win](const std::pair<cv::Rect, int>& s) {
    return (s.first & win.rect) == win.rect && s.second <= win.decimation;
  };
  if (!pending || std::any_of(w->searched.begin(), w->searched.end(), inside)) {
    ++counters_.windows_skipped;
    return;
  }
  w->searched.emplace_back(win.rect, win.decimation);
  for (const TagObservation& obs : detector_.detect(gray, win.rect, win.decimation)) {
    if (w->ids_seen.count(obs.id) != 0) continue;
    ++counters_.searched_tags;
    handle_tag(obs, win.level, w);
  }
}

void CameraFrameProcessor::handle_tag(const TagObservation& obs, SearchLevel level, FrameWork* w) {
  w->ids_seen.insert(obs.id);
  Detection d;
  d.camera = w->camera;
  d.t_ns = w->t_ns;
  d.tag = obs;
  d.level = level;
  const auto it = agv_of_tag_.find(obs.id);
  if (it == agv_of_tag_.end()) {
    ++counters_.unknown_ids;
  } else {
    d.in_fleet = true;
    d.agv = it->second;
    const site::FleetAgv& agv = fleet_[d.agv];
    if (!may_start_track(obs, d.agv, *w)) {
      ++counters_.restricted_new_track_refused;
      if (w->out) w->out->push_back(d);
      return;
    }
    w->found[d.agv] = 1;
    d.has_fix = tag_fix_on_tray(cameras_[w->camera], obs.corners_px, obs.corner_sigma_px, agv,
                                tray_plane_, &d.fix);
    if (d.has_fix) {
      d.fix.source = static_cast<std::int32_t>(w->camera);
      w->tag_pose[d.agv] = d.fix.pose;
      w->has_tag_pose[d.agv] = 1;
      d.result = w->tracker->add_fix(d.agv, w->t_ns, d.fix);
    } else {
      ++counters_.no_fix;
    }
  }
  if (w->out) w->out->push_back(d);
}

// The area's ids make more bits correctable, which is safe only against the vehicles the area
// holds; the first fix of a track is not gated (nothing to gate by), so a vehicle without a track
// is started only by a code that also decodes to it against the whole family.
bool CameraFrameProcessor::may_start_track(const TagObservation& obs, std::size_t agv,
                                           const FrameWork& w) const {
  if (!obs.restricted) return true;
  const TrackState s = w.tracker->output(agv, w.t_ns).state;
  if (s != TrackState::kNone && s != TrackState::kLost) return true;
  const DecodeResult g = decode_global(obs.code, detector_.params().global_bits_corrected);
  return g.ok && g.id == obs.id;
}

void CameraFrameProcessor::fit_covered_trays(const cv::Mat& gray, FrameWork* w) {
  for (std::size_t i = 0; i < fleet_.size(); ++i) {
    if (!w->looked_for[i] || w->found[i]) continue;
    const TrackOutput o = w->tracker->output(i, w->t_ns);
    // A tentative track too: one restarted from a box is confirmed only by the boxes after it.
    if (!o.valid() && o.state != TrackState::kTentative) continue;
    TrayFix tray;
    const bool ok = tray_learned() ? learned_tray_fix(gray, i, o, w, &tray)
                                   : fit_tray(gray, cameras_[w->camera], fleet_[i], o.pose, o.cov,
                                              tray_, &tray);
    if (!ok) {
      ++counters_.tray_refused;
      ++counters_.tray_refused_by[static_cast<std::size_t>(tray.refusal)];
      continue;
    }
    tray.fix.source = static_cast<std::int32_t>(w->camera);
    if (w->tracker->add_fix(i, w->t_ns, tray.fix) == FixResult::kApplied) {
      ++counters_.tray_fixes;
      w->tray_applied[i] = 1;
    } else {
      ++counters_.tray_gated;
    }
  }
}

// The learned box nearest the prediction in the window around it. Boxes at vehicles whose tag
// this frame read are compared with the tag's fix (the tag wins; a disagreement is counted).
bool CameraFrameProcessor::learned_tray_fix(const cv::Mat& gray, std::size_t agv,
                                            const TrackOutput& o, FrameWork* w, TrayFix* out) {
  const site::FleetAgv& a = fleet_[agv];
  ++counters_.tray_net_windows;
  const std::vector<PlaneTray> trays = tray_net_->detect_on_plane(
      gray, cameras_[w->camera], {o.pose.x_mm, o.pose.y_mm}, a.tray_height_mm, tray_net_params_);
  const TrayNetParams& p = tray_net_params_;
  const PlaneTray* best = nullptr;
  double best_d = 0.5 * std::min(a.tray_length_mm, a.tray_width_mm);
  for (const PlaneTray& t : trays) {
    const double d = std::hypot(t.centre_mm.x - o.pose.x_mm, t.centre_mm.y - o.pose.y_mm);
    // A box nearer a vehicle read this frame is that vehicle's tray.
    std::size_t owner = agv;
    double owner_d = d;
    for (std::size_t j = 0; j < fleet_.size(); ++j) {
      if (!w->has_tag_pose[j]) continue;
      const double dj =
          std::hypot(t.centre_mm.x - w->tag_pose[j].x_mm, t.centre_mm.y - w->tag_pose[j].y_mm);
      if (dj < owner_d) owner = j, owner_d = dj;
    }
    if (owner != agv) {
      const double axis_err =
          std::abs(wrap_angle_rad(2.0 * (t.axis_rad - w->tag_pose[owner].theta_rad))) / 2.0;
      const bool long_is_x = fleet_[owner].tray_length_mm >= fleet_[owner].tray_width_mm;
      const double e = long_is_x ? axis_err : std::abs(0.5 * kPi - axis_err);
      if (owner_d > p.tag_disagree_mm || e > p.tag_disagree_rad) ++counters_.tray_tag_disagree;
      continue;
    }
    if (d < best_d) best = &t, best_d = d;
  }
  if (!best) return (out->refusal = TrayRefusal::kNoOutline, false);
  if (tray_box_fix(*best, a, o.pose, o.cov, p, tray_net_->geometry().mm_per_px, &out->fix)) {
    return true;
  }
  // tray_box_fix refuses a square tray, an unresolvable half turn (3 sigma beyond a quarter
  // turn) or a box that is not this tray's size.
  const bool square = std::abs(a.tray_length_mm - a.tray_width_mm) <
                      0.1 * std::max(a.tray_length_mm, a.tray_width_mm);
  const bool loose = 3.0 * std::sqrt(std::max(o.cov[8], 0.0)) >= 0.5 * kPi;
  out->refusal = square  ? TrayRefusal::kBadInput
                 : loose ? TrayRefusal::kUncertain
                         : TrayRefusal::kSizeMismatch;
  return false;
}

}  // namespace agv::overhead
