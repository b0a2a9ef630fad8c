// Where each ceiling camera looks for which vehicle (Yang et al. Algorithm 1, lines 11-18, made
// exact): a window around every track's predicted tag (its 3-sigma ellipse on the tray plane
// projected into the image, plus the tag), the camera's area for a track that missed its window,
// and the whole image at a fixed interval for vehicles not yet tracked. Also which ids an area
// may hold (the vehicles whose predicted position, widened by their sigma, lies in it): the set
// the predicted path decodes against (tag_code.hpp). Pure; docs/design/overhead.md.
// Tag geometry: the tag's centre is the vehicle's pose on the plane z = tray_height_mm, its page
// "up" the vehicle's +x; corners in page order TL, TR, BR, BL are, in the vehicle frame (x
// forward, y left), (+s/2, +s/2), (+s/2, -s/2), (-s/2, -s/2), (-s/2, +s/2): the renderer's
// AgvTruth::tag_corners_px (sim/site_render.hpp).
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <opencv2/core.hpp>
#include <string>
#include <vector>

#include "agv/overhead/tracker.hpp"
#include "agv/site/site.hpp"

namespace agv::overhead {

struct SearchParams {
  // The window covers this many sigmas of the prediction's position and heading.
  double window_sigmas = 3.0;
  double window_margin_px = 12.0;  // beyond the predicted tag's corners
  // A wider or taller window (in the pixels it is searched at, after decimation) falls back to
  // the area search.
  int max_window_px = 512;
  // A track or area window whose smallest predicted tag is n times this side (px, its shortest
  // side) is searched shrunk n times, up to max_decimation (1: never): libapriltag's cost goes
  // with the pixels, and it finds a tag of this size reliably; the tag is then refined and read
  // at full resolution (TagDetector::detect with a decimation). The same rule as the rack
  // landmarks' windows (ranging::WindowOptions).
  double decimated_side_px = 32.0;
  int max_decimation = 4;
  // Whole image every this many frames of the camera while some vehicle of the fleet has no
  // track (none or lost), and on the camera's first frame; 0: the first frame only.
  int full_sweep_every_frames = 15;
  // A search of more pixels than this (an area's after its decimation, the whole image's before:
  // its strips are fixed before the tags in view are known) is spread over consecutive frames,
  // one horizontal strip per frame (the strips overlap by the largest tag the view can hold, so
  // each tag lies wholly in one): the cost of one frame stays bounded, and with it the exposure to
  // publish latency of every frame queued behind it. The interval's whole-image search (a
  // 3840 x 2160 image is 4 strips, at most full_sweep_every_frames), the whole-image search for a
  // vehicle lost in view (the strips in turn while it stays lost), and an area (the part in the
  // prediction's strip first, then the nearest others, one more per frame it stays unfound). The
  // camera's first frame stays whole. 0: always at once.
  int sweep_max_pixels = 2'500'000;
  // Area of a camera: its image divided into area_cols x area_rows tiles (paper: regions of the
  // site); a track that missed its window is looked for in the tile of its prediction and the
  // eight around it.
  int area_cols = 4, area_rows = 3;
  // A vehicle whose tray box (tray_fit.hpp) was applied in a frame keeps its track window next
  // frame instead of the area: its tag is under a parcel and the box has placed it, so the tag
  // would be no more findable in the area, and the areas of half a fleet's covered vehicles are
  // most of a frame's cost. false: a covered vehicle's miss widens its search like any other.
  bool tray_box_holds_window = true;
};

// Empty string when the parameters are usable, otherwise what is wrong (names the field).
std::string validate(const SearchParams& params);

enum class SearchLevel : std::uint8_t { kTrack, kArea, kFull };

struct SearchWindow {
  SearchLevel level = SearchLevel::kTrack;
  cv::Rect rect;                  // clipped to the image
  std::vector<std::size_t> agvs;  // the vehicles expected in it (empty for kFull)
  int decimation = 1;             // searched shrunk this many times (SearchParams)
  // The tag's predicted corners (page order, distorted pixels) for kTrack windows.
  std::array<Vec2, 4> predicted_corners_px{};
};

struct CameraSearchState {
  std::int64_t frames = 0;  // frames seen by this camera
  // Per vehicle: frames in a row its window found nothing (1: the area next; 2 or more: the
  // whole image too, as the paper's second emergency level). Saturate, do not wrap.
  std::vector<std::uint8_t> missed;
};

// The windows for one frame of camera `cam` exposed at t_ns (the camera's frames so far and
// last frame's misses in `state`; fleet[i] is the tracker's vehicle i):
// - a kTrack window per vehicle with a track (tentative, confirmed or coasting) whose predicted
//   tag lies in the view: the predicted corners' box widened by window_sigmas of the position
//   and heading (projected through the lens at the prediction) and window_margin_px, clipped to
//   the image;
// - instead a kArea window (the tiles around the prediction's, identical ones merged) for a
//   vehicle whose window missed last frame, or, only where its window lies, whose window came
//   out larger than max_window_px;
// - no window for a vehicle predicted behind the camera or whose widened box misses the image;
// - a kFull window (the whole image, no vehicles) last, when the sweep is due (SearchParams) or
//   a coasting vehicle in view missed its area too (missed >= 2); on a large image the
//   interval's sweep, the lost vehicle's search and a large area are a strip per frame
//   (sweep_max_pixels). Whole-image windows are shrunk for the smallest tag of the fleet anywhere
//   in the view (decimated_side_px).
// Invalid params (validate) give one kFull window; invalid intrinsics, none.
std::vector<SearchWindow> plan_search(const site::CeilingCamera& cam,
                                      const std::vector<site::FleetAgv>& fleet,
                                      const FleetTracker& tracker, std::int64_t t_ns,
                                      const SearchParams& params, const CameraSearchState& state);

// The sizes the fleet's tags can take in the camera's view: the shortest side and the largest
// extent (px) over a 3 x 3 grid of the image on each vehicle's tray plane, from the lens's local
// scale there. ok false when no point of the grid maps onto a tray plane.
struct ViewTagSizes {
  bool ok = false;
  double min_side_px = 0.0, max_extent_px = 0.0;
};
ViewTagSizes view_tag_sizes(const site::CeilingCamera& cam,
                            const std::vector<site::FleetAgv>& fleet);

// The fleet's tag ids a window may hold: the vehicles whose predicted tray-plane position,
// widened by 3 sigma and the tag's half diagonal, projects into rect (tracks not valid are in
// every set; a vehicle without a track can be anywhere; a valid one predicted behind the camera
// is in none). In fleet order.
std::vector<std::uint32_t> ids_in_area(const site::CeilingCamera& cam,
                                       const std::vector<site::FleetAgv>& fleet,
                                       const FleetTracker& tracker, std::int64_t t_ns,
                                       const cv::Rect& rect);

}  // namespace agv::overhead
