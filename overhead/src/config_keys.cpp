// The key table of agvloc-overhead's configuration. Defaults are the library structs' own
// (TrackerParams, SearchParams, TagDetectParams): test_overhead_config proves the table equals
// them, so a default changed in the library shows up here and in the guide.
#include <cmath>
#include <cstdint>
#include <type_traits>
#include <utility>

#include "config.hpp"

#define AGV_OH_AT(member) \
  [](auto& cfg_) -> auto& { return cfg_.member; }

namespace agv::overhead_app {

namespace {

template <typename Cfg>
KeyOf<Cfg> base(const char* name, KeyType type, double lo, double hi, Value def, const char* unit,
                const char* doc) {
  KeyOf<Cfg> k;
  k.name = name;
  k.type = type;
  k.lo = lo;
  k.hi = hi;
  k.def = std::move(def);
  k.unit = unit;
  k.doc = doc;
  return k;
}

template <typename Cfg = OverheadConfig, typename Ref>
KeyOf<Cfg> number(const char* name, Ref ref, double lo, double hi, double def, const char* unit,
                  const char* doc) {
  KeyOf<Cfg> k = base<Cfg>(name, KeyType::kNumber, lo, hi, def, unit, doc);
  k.get = [ref](const Cfg& c) { return Value{static_cast<double>(ref(c))}; };
  k.set = [ref](Cfg& c, const Value& v) { ref(c) = std::get<double>(v); };
  return k;
}

template <typename Cfg = OverheadConfig, typename Ref>
KeyOf<Cfg> integer(const char* name, Ref ref, std::int64_t lo, std::int64_t hi, std::int64_t def,
                   const char* unit, const char* doc) {
  KeyOf<Cfg> k = base<Cfg>(name, KeyType::kInteger, static_cast<double>(lo),
                           static_cast<double>(hi), def, unit, doc);
  k.get = [ref](const Cfg& c) { return Value{static_cast<std::int64_t>(ref(c))}; };
  k.set = [ref](Cfg& c, const Value& v) {
    using T = std::remove_reference_t<decltype(ref(c))>;
    ref(c) = static_cast<T>(std::get<std::int64_t>(v));
  };
  return k;
}

template <typename Cfg = OverheadConfig, typename Ref>
KeyOf<Cfg> boolean(const char* name, Ref ref, bool def, const char* doc) {
  KeyOf<Cfg> k = base<Cfg>(name, KeyType::kBool, 0, 0, def, "", doc);
  k.get = [ref](const Cfg& c) { return Value{static_cast<bool>(ref(c))}; };
  k.set = [ref](Cfg& c, const Value& v) { ref(c) = std::get<bool>(v); };
  return k;
}

template <typename Cfg = OverheadConfig, typename Ref>
KeyOf<Cfg> string(const char* name, Ref ref, const char* def, const char* doc,
                  std::vector<std::string> choices = {}) {
  KeyOf<Cfg> k = base<Cfg>(name, choices.empty() ? KeyType::kString : KeyType::kChoice, 0, 0,
                           std::string(def), "", doc);
  k.choices = std::move(choices);
  k.get = [ref](const Cfg& c) { return Value{std::string(ref(c))}; };
  k.set = [ref](Cfg& c, const Value& v) { ref(c) = std::get<std::string>(v); };
  return k;
}

std::vector<Key> tracker_keys() {
  return {
      number("tracker.accel_noise_mps2", AGV_OH_AT(tracker.accel_noise_mps2), 0.01, 100, 1.0,
             "m/s²",
             "White acceleration density of the constant-speed model: higher follows "
             "sharper speed changes, smooths less"),
      number("tracker.alpha_noise_radps2", AGV_OH_AT(tracker.alpha_noise_radps2), 0.01, 100, 0.3,
             "rad/s²",
             "White turn-rate acceleration density between turns: lower keeps the turn rate, "
             "and the heading extrapolated to the publish time, steadier"),
      number("tracker.maneuver_alpha_noise_radps2", AGV_OH_AT(tracker.maneuver_alpha_noise_radps2),
             0, 100, 2.0, "rad/s²",
             "Density for a fix whose heading shows a turn starting or stopping (beyond "
             "maneuver_chi2 of the steady prediction), and for a prediction over more than "
             "coast_after_ms without a fix (a turn may have started unseen); it is gated by "
             "this prediction. 0: off (such fixes are gated by the steady one)"),
      number("tracker.maneuver_chi2", AGV_OH_AT(tracker.maneuver_chi2), 1, 1000, 9.0, "",
             "Squared heading innovation (1 dof) beyond which a fix is taken as a turn's start "
             "or end"),
      number("tracker.gate_chi2", AGV_OH_AT(tracker.gate_chi2), 1, 1000, 16.27, "",
             "A fix farther than this squared Mahalanobis distance (3 dof) is refused; 16.27 is "
             "chi2 0.999, so a wrong id cannot move another vehicle's track"),
      integer("tracker.confirm_fixes", AGV_OH_AT(tracker.confirm_fixes), 1, 100, 3, "",
              "Fixes within confirm_window_ms that turn a tentative track confirmed"),
      number("tracker.confirm_window_ms", AGV_OH_AT(tracker.confirm_window_ms), 1, 60000, 1000,
             "ms", "Window of the confirm_fixes"),
      number("tracker.coast_after_ms", AGV_OH_AT(tracker.coast_after_ms), 1, 60000, 300, "ms",
             "No fix for this long: the track is coasting (extrapolated, sigma growing)"),
      number("tracker.lost_after_ms", AGV_OH_AT(tracker.lost_after_ms), 1, 600000, 3000, "ms",
             "No fix for this long: the track is lost (never reported confident)"),
      number("tracker.lost_sigma_mm", AGV_OH_AT(tracker.lost_sigma_mm), 1, 100000, 500, "mm",
             "Position sigma beyond this: the track is lost"),
      number("tracker.max_fix_age_ms", AGV_OH_AT(tracker.max_fix_age_ms), 0, 60000, 500, "ms",
             "A fix older than the filter's newest by more than this is refused (counted), not "
             "replayed; bounds the cost of a camera's latency"),
      integer("tracker.history", AGV_OH_AT(tracker.history), 1, 1024, 64, "",
              "Filter states kept per vehicle for delayed fixes (also bounds the fixes replayed)"),
      number("tracker.initial_speed_sigma_mps", AGV_OH_AT(tracker.initial_speed_sigma_mps), 0.001,
             20, 1.0, "m/s", "Speed sigma of a track started from one fix"),
      number("tracker.initial_turn_sigma_radps", AGV_OH_AT(tracker.initial_turn_sigma_radps), 0.001,
             20, 1.0, "rad/s", "Turn-rate sigma of a track started from one fix"),
      boolean("tracker.route_prior", AGV_OH_AT(tracker.route_prior), false,
              "A coasting vehicle on its route (its fleet manager's order, orders.subscribe) is "
              "extrapolated along the route round its corners, not straight on"),
      number("tracker.route.max_cross_track_mm", AGV_OH_AT(tracker.route.max_cross_track_mm), 1,
             10000, 300.0, "mm", "The last fix farther from the route than this: no route prior"),
      number("tracker.route.max_heading_error_rad", AGV_OH_AT(tracker.route.max_heading_error_rad),
             0.01, 3.14, 0.5, "rad",
             "The last fix's heading farther from the route's direction than this: no route prior"),
      number("tracker.route.cross_track_sigma_mm", AGV_OH_AT(tracker.route.cross_track_sigma_mm), 1,
             5000, 150.0, "mm",
             "How closely the vehicles keep to their routes (the predicted cross-track sigma "
             "never below it; a controller's tolerance, corners cut on arcs)"),
      number("tracker.route.heading_sigma_rad", AGV_OH_AT(tracker.route.heading_sigma_rad), 0.001,
             3.14, 0.15, "rad", "The same for heading"),
  };
}

std::vector<Key> search_detect_keys() {
  return {
      number("search.window_sigmas", AGV_OH_AT(search.window_sigmas), 0.5, 20, 3.0, "",
             "A track's search window covers this many sigmas of its prediction"),
      number("search.window_margin_px", AGV_OH_AT(search.window_margin_px), 0, 1000, 12.0, "px",
             "Margin of a track's window beyond the predicted tag's corners"),
      integer("search.max_window_px", AGV_OH_AT(search.max_window_px), 16, 16384, 512, "px",
              "A track window wider or taller than this, in the pixels it is searched at (after "
              "decimation), falls back to the area search"),
      number("search.decimated_side_px", AGV_OH_AT(search.decimated_side_px), 8, 4096, 32.0, "px",
             "A track or area window whose smallest predicted tag is n times this side is "
             "searched shrunk n times (up to search.max_decimation), the tag then refined at "
             "full resolution"),
      integer("search.max_decimation", AGV_OH_AT(search.max_decimation), 1, 8, 4, "",
              "Largest shrink factor of a window's search; 1 searches every window at full "
              "resolution"),
      integer("search.full_sweep_every_frames", AGV_OH_AT(search.full_sweep_every_frames), 1,
              100000, 15, "frames",
              "Whole-image search every this many frames of a camera (vehicles not yet tracked); "
              "1 searches every frame whole"),
      integer("search.sweep_max_pixels", AGV_OH_AT(search.sweep_max_pixels), 0, 1000000000, 2500000,
              "px",
              "A larger search is spread over consecutive frames, a horizontal strip per frame "
              "(overlapping by the largest tag in view): the interval's whole-image search "
              "(full_sweep_every_frames), the search for a vehicle lost in view, and an area "
              "(counted after its shrink; its prediction's strip first): bounds one frame's "
              "cost and the latency of the frames behind it; the first frame stays whole; 0 "
              "searches at once"),
      integer("search.area_cols", AGV_OH_AT(search.area_cols), 1, 64, 4, "",
              "A camera's image is cut into area_cols x area_rows areas for the area search and "
              "the restricted decoding"),
      integer("search.area_rows", AGV_OH_AT(search.area_rows), 1, 64, 3, "", "See area_cols"),
      boolean("search.tray_box_holds_window", AGV_OH_AT(search.tray_box_holds_window), true,
              "A vehicle whose tray box was applied (its tag under a parcel) keeps its track "
              "window next frame instead of the area search; false widens its search like any "
              "other miss"),
      number("detect.quad_decimate", AGV_OH_AT(detect.quad_decimate), 1, 8, 1.0, "",
             "libapriltag's quad_decimate: 1 keeps 40 px tags findable, 2 halves the search cost "
             "for large tags"),
      integer("detect.global_bits_corrected", AGV_OH_AT(detect.global_bits_corrected), 0, 3, 2,
              "bits",
              "Bits the whole-family decode (new tracks) may correct: few keep a wrong id "
              "out"),
      number("detect.edge_band_px", AGV_OH_AT(detect.edge_band_px), 0.5, 20, 3.0, "px",
             "Half width of the band searched for each edge of the tag's square"),
      number("detect.predicted_search_px", AGV_OH_AT(detect.predicted_search_px), 0, 100, 8.0, "px",
             "How far from its predicted corners a tracked tag may be found"),
      number("detect.min_contrast", AGV_OH_AT(detect.min_contrast), 0, 255, 20.0, "8-bit",
             "Smallest black-to-white border contrast for a square to count"),
      number("detect.max_edge_rms_px", AGV_OH_AT(detect.max_edge_rms_px), 0.01, 10, 0.8, "px",
             "Largest RMS distance of edge points from their fitted line"),
      number("detect.tray_tilt_sigma_rad", AGV_OH_AT(tray_plane.tilt_rad), 0, 0.5, 0.0087, "rad",
             "How far a tray's top may tilt (per axis; 0.0087 = 0.5 deg): seen off the camera's "
             "axis a tilt turns the tag's image, so every tag fix's heading sigma grows with it "
             "(0: level trays)"),
      number("detect.tray_height_sigma_mm", AGV_OH_AT(tray_plane.height_mm), 0, 200, 2.0, "mm",
             "How far a tag may sit above or below its vehicle's tray_height_mm (load, wheel "
             "wear): seen off the camera's axis it moves the fix, so the position sigma grows"),
      boolean("tray.enabled", AGV_OH_AT(tray_fit), true,
              "A tracked vehicle whose tag a window expected and did not read (a parcel on it) "
              "is fixed from its tray's box, gated like a tag fix; never starts a track"),
      integer("tray.min_sides_seen", AGV_OH_AT(tray.min_sides_seen), 2, 4, 3, "sides",
              "Tray sides that must be seen for a box fit: 2 fits more covered trays, with about "
              "a fifth of two-side fits outside their covariance on rendered random parcels"),
      number("tray.side_offset_bias_share", AGV_OH_AT(tray.side_offset_bias_share), 0, 1, 0.25, "",
             "Share of a classical box's side-offset variance the next frames share, carried "
             "as a bias the tracker does not average down: 0 lets the sigma fall below the "
             "error (NEES 6.3 on rendered covered tags), 1 follows each box's scatter"),
      string("tray.method", AGV_OH_AT(tray_method), "classical",
             "The tray's box: classical (edges, the known size; about 1 mm at 6 m on rendered "
             "frames) or learned (the ONNX detector of tray.model_path; coarser, "
             "docs/design/overhead.md)",
             {"classical", "learned"}),
      string("tray.model_path", AGV_OH_AT(tray_model_path), "",
             "The learned detector's ONNX file (models/tray_obb.onnx): tray.method learned and "
             "reacquire; missing, corrupt or for another window size: named at start, tracking "
             "on tags alone (learned) or without re-acquisition"),
      boolean("reacquire.enabled", AGV_OH_AT(reacquire.enabled), false,
              "With tray.model_path set (either tray.method): a vehicle lost while its tag was "
              "hidden is searched for with the learned detector over the view around where it "
              "can be, and restarted from a box only nothing else explains. Off by default: on "
              "a rendered 20-vehicle run it restarted covered vehicles from other vehicles' "
              "boxes, valid and metres wrong (docs/design/overhead.md)"),
      number("reacquire.max_speed_mps", AGV_OH_AT(reacquire.max_speed_mps), 0.1, 10, 2.0, "m/s",
             "The fleet's top speed: a lost vehicle is looked for within this speed of its last "
             "fix"),
      number("reacquire.max_turn_rate_radps", AGV_OH_AT(reacquire.max_turn_rate_radps), 0.05, 10,
             1.0, "rad/s",
             "The fleet's top turn rate: the last heading resolves a box's half turn while the "
             "vehicle cannot have turned a quarter turn since"),
      number("reacquire.max_lost_s", AGV_OH_AT(reacquire.max_lost_s), 1, 3600, 30.0, "s",
             "A vehicle lost longer than this is not searched for"),
      integer("reacquire.sweep_every_frames", AGV_OH_AT(reacquire.sweep_every_frames), 1, 1000, 5,
              "frames", "A camera's view is swept for lost vehicles every this many frames"),
      number("reacquire.min_score", AGV_OH_AT(reacquire.min_score), 0.05, 1, 0.7, "",
             "Smallest detector score of a box that may restart a track"),
      boolean("reacquire.forward_only", AGV_OH_AT(reacquire.forward_only), true,
              "The fleet drives forward: two sweeps that see a lost vehicle's box moved along "
              "its long axis give its heading (false: only the last heading does)"),
      number("reacquire.min_travel_mm", AGV_OH_AT(reacquire.min_travel_mm), 10, 5000, 150.0, "mm",
             "Travel between two sweeps that gives the heading"),
      integer("identity.min_tag_distance", AGV_OH_AT(min_tag_distance), 11, 36, 12, "bits",
              "Two fleet tags whose tag36h11 codes (any turn) are fewer bits apart are refused "
              "with the site: 12 keeps a 6-bit misread off the other's code, 13 lets an area of "
              "any fleet tags correct 6 bits (at most about 30 ids qualify); 11 checks nothing"),
  };
}

std::vector<Key> output_keys() {
  return {
      number("output.rate_hz", AGV_OH_AT(output_rate_hz), 1, 200, 30.0, "Hz",
             "Every vehicle's state is published at this fixed rate, extrapolated to the publish "
             "time (a scheduler wants 30 Hz or more)"),
      boolean("output.mqtt.enabled", AGV_OH_AT(mqtt.enabled), false,
              "Publish VDA 5050 visualization messages per vehicle (replay too)"),
      string("output.mqtt.broker_host", AGV_OH_AT(mqtt.broker_host), "localhost",
             "The MQTT broker's host name or address"),
      integer("output.mqtt.port", AGV_OH_AT(mqtt.port), 1, 65535, 1883, "", "The broker's port"),
      string("output.mqtt.interface_name", AGV_OH_AT(mqtt.interface_name), "agvloc-overhead",
             "First topic level: an interface of its own, so these messages never mix with the "
             "vehicles' own uagv topics"),
      string("output.mqtt.manufacturer", AGV_OH_AT(mqtt.manufacturer), "agvloc",
             "Third topic level and the messages' manufacturer"),
      string("output.mqtt.version", AGV_OH_AT(mqtt.version), "2.1.0",
             "VDA 5050 version of the messages (topic v2 or v3)", {"2.0.0", "2.1.0", "3.0.0"}),
      string("output.mqtt.map_id", AGV_OH_AT(mqtt.map_id), "",
             "agvPosition.mapId; empty: the site's name"),
      string("detections.topic_prefix", AGV_OH_AT(detections.topic_prefix), "agvloc-overhead",
             "Detector processes publish each frame's tags on PREFIX/detections/CAMERA_ID of "
             "the output.mqtt broker; `run --detections-from-broker` subscribes there"),
      boolean("orders.subscribe", AGV_OH_AT(orders.subscribe), false,
              "run: read every fleet vehicle's VDA 5050 order from the output.mqtt broker as its "
              "route (needs tracker.route_prior); refused orders are counted by reason"),
      string("orders.interface_name", AGV_OH_AT(orders.interface_name), "uagv",
             "First topic level of the vehicles' orders: INTERFACE/vN/MANUFACTURER/ID/order, ID "
             "a fleet vehicle's id in the site file"),
      boolean("diag.enabled", AGV_OH_AT(diag.enabled), false,
              "run: serve the diagnostics page and Prometheus /metrics (cameras, vehicles)"),
      string("diag.bind_address", AGV_OH_AT(diag.bind_address), "127.0.0.1",
             "Address the page listens on; not loopback only with diag.allow_remote"),
      integer("diag.port", AGV_OH_AT(diag.port), 0, 65535, 8090, "",
              "The page's TCP port (0: any free one; the vehicle's page defaults elsewhere)"),
      boolean("diag.allow_remote", AGV_OH_AT(diag.allow_remote), false,
              "Allow a non-loopback diag.bind_address: the page has no authentication"),
      integer("diag.max_clients", AGV_OH_AT(diag.max_clients), 1, 64, 4, "",
              "Requests in progress at once; more are answered 503"),
      integer("diag.threads", AGV_OH_AT(diag.threads), 1, 8, 1, "",
              "Threads serving the page (not real-time)"),
      integer("diag.view_width_px", AGV_OH_AT(diag.view_width_px), 160, 3840, 960, "px",
              "Width of each camera's view on the page (/camera/<index>.png): the frame "
              "downscaled to it (never enlarged), detections and track windows drawn"),
  };
}

}  // namespace

const std::vector<CameraKey>& camera_keys() {
  using C = CameraSettings;
  static const std::vector<CameraKey> keys = {
      number<C>("latency_ms", AGV_OH_AT(latency_ms), 0, 1000, 0.0, "ms",
                "replay: exposure to the frame's arrival at the tracker (fixes keep their "
                "exposure time; the tracker applies a late fix where it belongs)"),
      string<C>("driver", AGV_OH_AT(driver), "v4l2",
                "run, record: the live driver (docs/guide/camera.md); aravis: GigE Vision / USB3 "
                "Vision, frames stamped by the camera's clock",
                {"v4l2", "libcamera", "aravis"}),
      string<C>("device", AGV_OH_AT(device), "",
                "run, record: V4L2 device node (/dev/video0), libcamera camera id, or Aravis "
                "device id or IP address; empty: not opened"),
      number<C>("fps", AGV_OH_AT(fps), 1, 240, 30.0, "Hz", "run, record: the camera's frame rate"),
      integer<C>("exposure_us", AGV_OH_AT(exposure_us), 10, 1000000, 500, "µs",
                 "run, record: fixed exposure; blur = speed x exposure (1 mm at 2 m/s for 500 µs)"),
      number<C>("analogue_gain", AGV_OH_AT(analogue_gain), 1, 64, 1.0, "",
                "run, record: fixed analogue gain (brightens, adds noise)"),
  };
  return keys;
}

const std::vector<Key>& config_keys() {
  static const std::vector<Key> keys = [] {
    std::vector<Key> all = tracker_keys();
    for (auto* part : {search_detect_keys, output_keys}) {
      for (Key& k : part()) all.push_back(std::move(k));
    }
    return all;
  }();
  return keys;
}

}  // namespace agv::overhead_app
