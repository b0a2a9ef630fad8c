// One ceiling camera's frame through the tracker (Yang et al. Algorithm 1): plan the search windows
// (search.hpp), read each tracked vehicle's tag on the predicted path against its area's ids,
// search the area and whole-image windows with the global decode, turn every tag into a fix on
// its vehicle's tray plane (tag_fix.hpp) and hand the fixes to the tracker. A tag id not in the
// fleet is ignored and counted; a fix the tracker gates is counted, never applied. Pure.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <opencv2/core.hpp>
#include <string>
#include <unordered_map>
#include <vector>

#include "agv/overhead/reacquire.hpp"
#include "agv/overhead/search.hpp"
#include "agv/overhead/tag_detect.hpp"
#include "agv/overhead/tag_fix.hpp"
#include "agv/overhead/tracker.hpp"
#include "agv/overhead/tray_fit.hpp"
#include "agv/overhead/tray_net.hpp"
#include "agv/site/site.hpp"

namespace agv::overhead {

// One tag seen in one frame, as replay writes it to detections.csv.
struct Detection {
  std::size_t camera = 0;
  std::int64_t t_ns = 0;  // exposure time (host clock)
  TagObservation tag;
  SearchLevel level = SearchLevel::kFull;
  bool in_fleet = false;  // tag id belongs to a vehicle of the fleet
  std::size_t agv = 0;    // fleet index when in_fleet
  bool has_fix = false;   // the tray-plane fit succeeded
  TagFix fix;
  FixResult result = FixResult::kInvalid;  // what the tracker did with it
};

struct FrameCounters {
  std::uint64_t frames = 0, windows_track = 0, windows_area = 0, windows_full = 0;
  std::uint64_t predicted_reads = 0, searched_tags = 0, unknown_ids = 0, no_fix = 0;
  std::uint64_t rejected_frames = 0;  // bad input to process(), nothing done
  // Area and whole-image searches not made: every vehicle of the area already read this frame,
  // or the region inside one searched this frame at the same or a finer decimation.
  std::uint64_t windows_skipped = 0;
  // A restricted (area) decode of a vehicle that has no track: not applied, because a track is
  // started only from the strict global decode (the first fix of a track is not gated).
  std::uint64_t restricted_new_track_refused = 0;
  // Covered tags (a tracked vehicle expected wholly in view, its tag not read): tray fits applied
  // to its track, gated by it, or refused by the fit (too few sides, ambiguous heading, ...).
  std::uint64_t tray_fixes = 0, tray_gated = 0, tray_refused = 0;
  // tray_refused by TrayRefusal (index: the enum's value; the learned box's refusals too).
  std::array<std::uint64_t, kTrayRefusalCount> tray_refused_by{};
  // The learned detector: windows it ran on; boxes found at a vehicle whose tag was read in the
  // same frame that disagree with the tag's fix (the tag wins; the box is dropped).
  std::uint64_t tray_net_windows = 0, tray_tag_disagree = 0;
  // Re-acquisition (reacquire.hpp): sweeps of a view for lost vehicles, the detector's windows
  // they took, tracks restarted from a box, and boxes given to no vehicle because two lost
  // vehicles could be there (or one vehicle had two boxes), or because the half turn was unknown.
  std::uint64_t reacquire_sweeps = 0, reacquire_windows = 0, reacquired = 0;
  std::uint64_t reacquire_ambiguous = 0, reacquire_heading_unknown = 0;
};

class CameraFrameProcessor {
 public:
  // fleet and cameras as in the site; two vehicles with one tag id are refused by the site
  // checker before this is built.
  CameraFrameProcessor(const std::vector<site::CeilingCamera>& cameras,
                       const std::vector<site::FleetAgv>& fleet, const TagDetectParams& detect,
                       const SearchParams& search);
  // Processes one frame of camera `camera` exposed at t_ns and feeds the tracker; every tag seen
  // is appended to *out when not null. False with *error, and nothing done, for a camera index
  // out of range, a tracker not sized for the fleet, or a frame that is not 8-bit gray of the
  // camera's size.
  bool process(std::size_t camera, std::int64_t t_ns, const cv::Mat& gray, FleetTracker* tracker,
               std::vector<Detection>* out, std::string* error = nullptr);
  const FrameCounters& counters() const { return counters_; }
  // The search state of camera `camera` (frames seen, vehicles whose window missed).
  const CameraSearchState& search_state(std::size_t camera) const { return state_.at(camera); }
  // The tray's oriented box for a tracked vehicle whose tag was not read (tray_fit.hpp): on by
  // default. A tray fix only updates a valid track (confirmed or coasting), never starts one.
  void set_tray_fit(bool enabled, const TrayFitParams& params = {}) {
    tray_enabled_ = enabled;
    tray_ = params;
  }
  // How far the trays' tops may depart from level at their nominal height (tag_fix.hpp): widens
  // every tag fix's covariance. Default: level trays at their height.
  void set_tray_plane_sigma(const TrayPlaneSigma& sigma) { tray_plane_ = sigma; }
  // The tray's box from the learned detector (tray_net.hpp) instead of the classical fit: the
  // rectified window around the prediction, the box nearest it turned into a fix (the half-turn
  // resolved by the prediction). A null net goes back to the classical fit.
  void set_tray_net(std::shared_ptr<const TrayNet> net, const TrayNetParams& params = {}) {
    tray_net_ = std::move(net);
    tray_net_params_ = params;
  }
  bool tray_learned() const { return tray_net_ && tray_net_->loaded(); }
  // Re-acquisition of vehicles lost while their tags were hidden, by the learned detector swept
  // over the view (reacquire.hpp); the box is refined by the classical fit when that is the tray
  // method. A null net turns it off (the default).
  void set_reacquire(std::shared_ptr<const TrayNet> net, const ReacquireParams& params = {},
                     const TrayNetParams& net_params = {}) {
    reacquire_net_ = std::move(net);
    reacquire_ = params;
    reacquire_net_params_ = net_params;
  }
  bool reacquiring() const {
    return reacquire_.enabled && reacquire_net_ && reacquire_net_->loaded();
  }

 private:
  struct FrameWork;
  void track_window(const SearchWindow& win, const cv::Mat& gray, FrameWork* w);
  void search_window(const SearchWindow& win, const cv::Mat& gray, FrameWork* w);
  void handle_tag(const TagObservation& obs, SearchLevel level, FrameWork* w);
  bool may_start_track(const TagObservation& obs, std::size_t agv, const FrameWork& w) const;
  void fit_covered_trays(const cv::Mat& gray, FrameWork* w);
  // False with out->refusal set when no box at the prediction makes a fix.
  bool learned_tray_fix(const cv::Mat& gray, std::size_t agv, const TrackOutput& o, FrameWork* w,
                        TrayFix* out);
  void reacquire_lost(const cv::Mat& gray, FrameWork* w);
  std::vector<LostVehicle> lost_vehicles(FrameWork* w, std::vector<Vec2>* explained);
  std::vector<PlaneTray> sweep_for(const cv::Mat& gray, std::size_t camera, std::int64_t t_ns,
                                   const std::vector<LostVehicle>& lost);
  void restart_from_box(const cv::Mat& gray, const ReacquireBox& box, const LostVehicle& v,
                        FrameWork* w);

  std::vector<site::CeilingCamera> cameras_;
  std::vector<site::FleetAgv> fleet_;
  std::unordered_map<std::uint32_t, std::size_t> agv_of_tag_;
  TagDetector detector_;
  SearchParams search_;
  std::vector<CameraSearchState> state_;
  FrameCounters counters_;
  bool tray_enabled_ = true;
  TrayFitParams tray_;
  TrayPlaneSigma tray_plane_;
  std::shared_ptr<const TrayNet> tray_net_;
  TrayNetParams tray_net_params_;
  std::shared_ptr<const TrayNet> reacquire_net_;
  ReacquireParams reacquire_;
  TrayNetParams reacquire_net_params_;
  // Per vehicle: what its track was at its last fix while valid, and the box a sweep last gave
  // it (for the heading from travel).
  struct Remembered {
    bool known = false;
    LostVehicle last;
    bool have_box = false;
    PlaneTray box;
    std::int64_t box_t_ns = 0;
  };
  std::vector<Remembered> remembered_;
  std::vector<std::uint64_t> sweep_frames_;  // per camera: frames with a lost vehicle to sweep for
};

}  // namespace agv::overhead
