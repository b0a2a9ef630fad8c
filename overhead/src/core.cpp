#include "core.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <iterator>

#include "agv/overhead/tag_code.hpp"

namespace agv::overhead_app {

namespace {

constexpr int kMqttConnectTimeoutMs = 5000;
constexpr int kMqttFlushTimeoutMs = 3000;
constexpr std::uint64_t kFrameWarningsShown = 5;

std::int64_t epoch_now_ns() {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(
             std::chrono::system_clock::now().time_since_epoch())
      .count();
}

unsigned long long ull(std::uint64_t v) { return static_cast<unsigned long long>(v); }

std::vector<std::string> fleet_ids(const site::Site& site) {
  std::vector<std::string> ids;
  for (const site::FleetAgv& a : site.fleet) ids.push_back(a.id);
  return ids;
}

}  // namespace

TrackerCore::TrackerCore(const OverheadConfig& cfg, const site::Site& site)
    : cfg_(cfg),
      site_(site),
      processor_(site.cameras, site.fleet, cfg.detect, cfg.search),
      tracker_(site.fleet.size(), cfg.tracker),
      header_ids_(site.fleet.size(), 0),
      order_intake_(fleet_ids(site), cfg.orders.interface_name) {
  for (int r = static_cast<int>(overhead::OrderReason::kBadTopic); r < overhead::kOrderReasonCount;
       ++r)
    orders_.refused_by_reason[overhead::order_reason_name(static_cast<overhead::OrderReason>(r))] =
        0;
  orders_.refused_by_reason["route_refused"] = 0;
  processor_.set_tray_fit(cfg.tray_fit, cfg.tray);
  processor_.set_tray_plane_sigma(cfg.tray_plane);
  const bool learned = cfg.tray_fit && cfg.tray_method == "learned";
  const bool reacquire = cfg.reacquire.enabled && !cfg.tray_model_path.empty();
  if (learned || reacquire) use_tray_model(cfg.tray_model_path, learned);
}

// The learned detector's model is read here (the library does no file I/O). A model that cannot
// be used is named at start and the tracker runs on tags alone, saying so: a classical fit in its
// place would be a method nobody chose.
void TrackerCore::use_tray_model(const std::string& path, bool learned) {
  std::string error;
  std::ifstream f(path, std::ios::binary);
  const std::string bytes((std::istreambuf_iterator<char>(f)), std::istreambuf_iterator<char>());
  auto net = std::make_shared<overhead::TrayNet>();
  if (path.empty()) {
    error = "tray.model_path is empty";
  } else if (!f.good() && bytes.empty()) {
    error = "tray.model_path '" + path + "': cannot be read";
  } else if (!net->load(bytes.data(), bytes.size(), &error)) {
    error = "tray.model_path '" + path + "': " + error;
  }
  if (!error.empty()) {
    std::fprintf(stderr,
                 learned ? "agvloc-overhead: %s; tray.method learned unavailable: tracking on "
                           "tags alone (no tray boxes for covered tags)\n"
                         : "agvloc-overhead: %s; no re-acquisition of vehicles lost under a "
                           "parcel\n",
                 error.c_str());
    if (learned) processor_.set_tray_fit(false);
    (learned ? tray_model_error_ : reacquire_error_) = error;
    return;
  }
  if (cfg_.reacquire.enabled) processor_.set_reacquire(net, cfg_.reacquire);
  if (learned) processor_.set_tray_net(std::move(net));
}

void TrackerCore::apply_order(std::string_view topic, std::string_view payload, std::int64_t t_ns) {
  ++orders_.messages;
  overhead::OrderRoute route;
  std::string why;
  overhead::OrderReason r = order_intake_.take(topic, payload, &route, &why);
  if (r == overhead::OrderReason::kDuplicate) {
    ++orders_.duplicates;
    return;
  }
  if (r == overhead::OrderReason::kNone && route.waypoints_mm.size() < 2) {
    tracker_.clear_route(route.agv);  // to stay at its one node: nothing to follow
    ++orders_.routes_cleared;
    return;
  }
  if (r == overhead::OrderReason::kNone) {
    if (tracker_.set_route(route.agv, route.waypoints_mm, t_ns, &why)) {
      ++orders_.routes_set;
      return;
    }
    tracker_.clear_route(route.agv);  // an order it cannot follow: no stale route either
    order_intake_.forget(route.agv);
    ++orders_.routes_cleared;
  }
  ++orders_.refused;
  const char* name =
      r == overhead::OrderReason::kNone ? "route_refused" : overhead::order_reason_name(r);
  ++orders_.refused_by_reason[name];
  if (orders_.refused <= kFrameWarningsShown)
    std::fprintf(stderr, "agvloc-overhead: order refused (%s): %s\n", name, why.c_str());
}

void TrackerCore::fill_orders_diag(DiagView* v) const {
  v->has_orders = cfg_.orders.subscribe;
  if (!v->has_orders) return;
  v->orders = {orders_.messages, orders_.routes_set, orders_.routes_cleared, orders_.duplicates,
               orders_.refused_by_reason};
}

void TrackerCore::fill_tray_diag(DiagView* v) const {
  v->has_tray = cfg_.tray_fit;
  if (!v->has_tray) return;
  const overhead::FrameCounters& f = processor_.counters();
  v->tray = {f.tray_fixes, f.tray_gated, f.tray_tag_disagree, {}};
  for (std::size_t r = 1; r < overhead::kTrayRefusalCount; ++r) {
    const char* name = overhead::to_string(static_cast<overhead::TrayRefusal>(r));
    v->tray.refused[name] = f.tray_refused_by[r];
  }
}

void TrackerCore::publish_camera_state(const std::string& camera_id, bool fault,
                                       const std::string& what) {
  if (!mqtt_ || !topic_level_ok(camera_id)) return;
  const std::string map_id = cfg_.mqtt.map_id.empty() ? site_.name : cfg_.mqtt.map_id;
  const vda5050::Identity id = identity_of(cfg_.mqtt, map_id, camera_id);
  std::vector<vda5050::StateError> errors;
  if (fault) {
    errors.push_back(
        {"cameraFault", "WARNING", "camera " + camera_id + ": " + what, {{"cameraId", camera_id}}});
  }
  std::uint32_t& header = camera_header_ids_[camera_id];
  mqtt_->publish(
      vda5050::topic(id, "state"),
      vda5050::encode_state(id, header++, epoch_now_ns(), vda5050::Position{}, {}, errors));
}

std::int64_t TrackerCore::period_ns() const {
  return static_cast<std::int64_t>(std::llround(1e9 / cfg_.output_rate_hz));
}

bool TrackerCore::open_outputs(const std::string& out_dir, std::string* error) {
  if (!out_dir.empty() && !csv_.open(out_dir, error)) return false;
  if (!cfg_.mqtt.enabled) return true;
  const std::string map_id = cfg_.mqtt.map_id.empty() ? site_.name : cfg_.mqtt.map_id;
  for (const site::FleetAgv& a : site_.fleet) {
    if (!topic_level_ok(a.id)) {
      *error = "fleet: AGV id '" + a.id + "' cannot be an MQTT topic level";
      return false;
    }
    ids_.push_back(identity_of(cfg_.mqtt, map_id, a.id));
  }
  mqtt_ = std::make_unique<MqttOut>();
  return mqtt_->start(cfg_.mqtt, kMqttConnectTimeoutMs, error);
}

void TrackerCore::process(std::size_t camera, std::int64_t t_ns, const cv::Mat& gray) {
  detections_.clear();
  processor_.process(camera, t_ns, gray, &tracker_, &detections_);
  newest_frame_ns_ = frames_ == 0 ? t_ns : std::max(newest_frame_ns_, t_ns);
  ++frames_;
  for (const overhead::Detection& d : detections_) {
    ++detections_total_;
    if (csv_.is_open()) csv_.detection(detection_row(site_, d));
  }
}

void TrackerCore::apply_tags(std::size_t camera, std::int64_t t_ns,
                             const std::vector<overhead::MsgTag>& tags) {
  detections_.clear();
  for (const overhead::MsgTag& m : tags) {
    overhead::Detection d;
    d.camera = camera;
    d.t_ns = t_ns;
    d.tag = m.tag;
    d.level = m.level;
    ++remote_.tags;
    const auto agv = std::find_if(site_.fleet.begin(), site_.fleet.end(),
                                  [&](const site::FleetAgv& a) { return a.tag_id == m.tag.id; });
    d.in_fleet = agv != site_.fleet.end();
    if (!d.in_fleet) {
      ++remote_.unknown_ids;
    } else {
      d.agv = static_cast<std::size_t>(agv - site_.fleet.begin());
      // As CameraFrameProcessor: a track starts only from a strict global decode.
      const overhead::TrackState s = tracker_.output(d.agv, t_ns).state;
      const bool untracked = s == overhead::TrackState::kNone || s == overhead::TrackState::kLost;
      const overhead::DecodeResult g =
          overhead::decode_global(m.tag.code, cfg_.detect.global_bits_corrected);
      if (m.tag.restricted && untracked && !(g.ok && g.id == m.tag.id)) {
        ++remote_.restricted_refused;
      } else {
        d.has_fix = overhead::tag_fix_on_tray(site_.cameras[camera], m.tag.corners_px,
                                              m.tag.corner_sigma_px, *agv, cfg_.tray_plane, &d.fix);
        d.fix.source = static_cast<std::int32_t>(camera);
        if (d.has_fix) d.result = tracker_.add_fix(d.agv, t_ns, d.fix);
        if (!d.has_fix) ++remote_.no_fix;
      }
    }
    detections_.push_back(d);
  }
  newest_frame_ns_ = frames_ == 0 ? t_ns : std::max(newest_frame_ns_, t_ns);
  ++frames_;
  for (const overhead::Detection& d : detections_) {
    ++detections_total_;
    if (csv_.is_open()) csv_.detection(detection_row(site_, d));
  }
}

void TrackerCore::frame_unreadable(const std::string& what) {
  if (++bad_frames_ <= kFrameWarningsShown) {
    std::fprintf(stderr, "agvloc-overhead: frame skipped: %s\n", what.c_str());
  }
}

void TrackerCore::publish(std::int64_t t_ns) {
  // Tracks are dropped or lost by the time of the data, not of the publish clock: a pipeline
  // behind its cameras (frames queued, a loaded machine) must not drop a tentative track whose
  // next fix is in a frame not processed yet. The outputs below still extrapolate to t_ns by the
  // same rules, so they never report a track valid that its age would have lost; and a pipeline
  // more than kMaxDataLagNs behind (cameras gone) no longer holds the states back.
  std::int64_t states_ns = t_ns;
  if (frames_ > 0) states_ns = std::min(t_ns, std::max(newest_frame_ns_, t_ns - kMaxDataLagNs));
  tracker_.update_states(states_ns);
  const std::int64_t epoch_ns = mqtt_ ? epoch_now_ns() : 0;
  for (std::size_t i = 0; i < site_.fleet.size(); ++i) {
    const overhead::TrackOutput t = tracker_.output(i, t_ns);
    if (t.state == overhead::TrackState::kNone) continue;
    if (csv_.is_open()) csv_.track(track_row(site_.fleet[i].id, t));
    if (mqtt_) {
      mqtt_->publish(vda5050::topic(ids_[i], "visualization"),
                     visualization_json(ids_[i], header_ids_[i]++, epoch_ns, t));
    }
  }
}

bool TrackerCore::finish(const std::string& prefix, std::size_t cameras, std::string* error) {
  if (mqtt_) mqtt_->stop(kMqttFlushTimeoutMs);
  print_summary(prefix, cameras);
  return !csv_.is_open() || csv_.close(error);
}

void TrackerCore::print_summary(const std::string& prefix, std::size_t cameras) const {
  const overhead::FrameCounters& f = processor_.counters();
  const overhead::TrackerCounters& c = tracker_.counters();
  const char* p = prefix.c_str();
  std::printf(
      "%s: %zu cameras, %llu frames (%llu unreadable, skipped), %llu detections (%llu unknown "
      "ids, %llu without fix)\n",
      p, cameras, ull(frames_), ull(bad_frames_), ull(detections_total_), ull(f.unknown_ids),
      ull(f.no_fix));
  std::printf(
      "%s: fixes applied %llu, tracks started %llu, gated %llu, too old %llu, invalid %llu, lost "
      "%llu\n",
      p, ull(c.applied), ull(c.started), ull(c.gated), ull(c.too_old), ull(c.invalid), ull(c.lost));
  std::printf(
      "%s: search windows: track %llu (tags read on the predicted path %llu), area %llu, whole "
      "image %llu, not searched (already read or searched) %llu; tags found by searching %llu\n",
      p, ull(f.windows_track), ull(f.predicted_reads), ull(f.windows_area), ull(f.windows_full),
      ull(f.windows_skipped), ull(f.searched_tags));
  std::printf(
      "%s: tray boxes (%s) applied %llu, gated %llu, refused %llu; learned boxes disagreeing "
      "with a read tag %llu\n",
      p,
      !tray_model_error_.empty()  ? "off: model unusable"
      : processor_.tray_learned() ? "learned"
                                  : "classical",
      ull(f.tray_fixes), ull(f.tray_gated), ull(f.tray_refused), ull(f.tray_tag_disagree));
  for (std::size_t r = 1; r < overhead::kTrayRefusalCount; ++r) {
    if (f.tray_refused_by[r] == 0) continue;
    std::printf("%s: tray boxes refused %s: %llu\n", p,
                overhead::to_string(static_cast<overhead::TrayRefusal>(r)),
                ull(f.tray_refused_by[r]));
  }
  std::printf(
      "%s: re-acquisition (%s): sweeps %llu, detector windows %llu, tracks restarted %llu, "
      "boxes two lost vehicles could be %llu, half turn unknown %llu\n",
      p,
      processor_.reacquiring()    ? "on"
      : !reacquire_error_.empty() ? "off: model unusable"
      : cfg_.reacquire.enabled    ? "off: no tray.model_path"
                                  : "off",
      ull(f.reacquire_sweeps), ull(f.reacquire_windows), ull(f.reacquired),
      ull(f.reacquire_ambiguous), ull(f.reacquire_heading_unknown));
  if (cfg_.orders.subscribe) {
    const OrderCounters& o = orders_;
    std::printf(
        "%s: orders: %llu messages, %llu routes set, %llu cleared, %llu duplicates, %llu "
        "refused\n",
        p, ull(o.messages), ull(o.routes_set), ull(o.routes_cleared), ull(o.duplicates),
        ull(o.refused));
    for (const auto& [reason, count] : o.refused_by_reason) {
      if (count > 0) std::printf("%s: order refused %s: %llu\n", p, reason.c_str(), ull(count));
    }
  }
  if (mqtt_) {
    std::printf("%s: mqtt: %llu messages sent, %llu dropped\n", p, ull(mqtt_->sent()),
                ull(mqtt_->dropped()));
  }
}

}  // namespace agv::overhead_app
