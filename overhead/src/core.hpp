// What replay and run share: the per-frame pipeline (CameraFrameProcessor) and the fleet's
// tracks, the fixed-rate publication of every vehicle's state (tracks.csv, MQTT), detections.csv
// and the counters of the summary.
#pragma once

#include <cstdint>
#include <map>
#include <memory>
#include <opencv2/core.hpp>
#include <string>
#include <string_view>
#include <vector>

#include "agv/overhead/camera_frame.hpp"
#include "agv/overhead/detection_msg.hpp"
#include "agv/overhead/order_intake.hpp"
#include "config.hpp"
#include "diag.hpp"
#include "outputs.hpp"
#include "visualization.hpp"

namespace agv::overhead_app {

class TrackerCore {
 public:
  TrackerCore(const OverheadConfig& cfg, const site::Site& site);

  // --out (empty: none) and MQTT when configured; false with *error.
  bool open_outputs(const std::string& out_dir, std::string* error);
  // One frame of site camera `camera` exposed at t_ns.
  void process(std::size_t camera, std::int64_t t_ns, const cv::Mat& gray);
  // The tags of one frame of site camera `camera` from a detector process: turned into fixes
  // with this site's camera and fleet and applied by their exposure time, as process() does.
  void apply_tags(std::size_t camera, std::int64_t t_ns, const std::vector<overhead::MsgTag>& tags);
  // Of apply_tags: tags of no fleet vehicle, without a fix, and restricted decodes that would
  // have started a track.
  struct RemoteCounters {
    std::uint64_t tags = 0, unknown_ids = 0, no_fix = 0, restricted_refused = 0;
  };
  const RemoteCounters& remote_counters() const { return remote_; }
  // One message from the vehicles' order topics (orders.subscribe) received at t_ns on the
  // tracks' clock: an accepted order's base becomes the vehicle's route from t_ns (one node:
  // its route is cleared); a refusal is counted by reason, the first few named on stderr.
  void apply_order(std::string_view topic, std::string_view payload, std::int64_t t_ns);
  struct OrderCounters {
    std::uint64_t messages = 0, routes_set = 0, routes_cleared = 0, duplicates = 0, refused = 0;
    std::map<std::string, std::uint64_t> refused_by_reason;  // every reason, from 0
  };
  const OrderCounters& order_counters() const { return orders_; }
  // The diagnostics view's orders (has_orders with orders.subscribe).
  void fill_orders_diag(DiagView* v) const;
  // The diagnostics view's tray boxes (has_tray with tray.enabled): this process's frames.
  void fill_tray_diag(DiagView* v) const;
  // A frame that could not be read: counted, the first few named on stderr.
  void frame_unreadable(const std::string& what);
  // Every tracked vehicle's state extrapolated to t_ns, to tracks.csv and MQTT.
  void publish(std::int64_t t_ns);
  // A camera's fault state on MQTT (when configured): a VDA 5050 state message whose
  // serialNumber is the camera's id, errors[] holding a cameraFault while it is in a fault.
  void publish_camera_state(const std::string& camera_id, bool fault, const std::string& what);
  // Flushes MQTT, prints the summary (prefix: "agvloc-overhead replay"), closes the CSV files.
  bool finish(const std::string& prefix, std::size_t cameras, std::string* error);

  std::int64_t period_ns() const;
  // For the diagnostics page: the tracks, and the detections of the last frame processed.
  const overhead::FleetTracker& tracker() const { return tracker_; }
  const std::vector<overhead::Detection>& last_detections() const { return detections_; }
  std::uint64_t frames() const { return frames_; }
  const site::Site& site() const { return site_; }
  const OverheadConfig& config() const { return cfg_; }
  std::uint64_t unreadable_frames() const { return bad_frames_; }

 private:
  void print_summary(const std::string& prefix, std::size_t cameras) const;
  // Loads the learned detector: the tray method when learned, re-acquisition when enabled.
  void use_tray_model(const std::string& path, bool learned);

  const OverheadConfig& cfg_;
  const site::Site& site_;
  overhead::CameraFrameProcessor processor_;
  overhead::FleetTracker tracker_;
  std::vector<overhead::Detection> detections_;
  CsvOut csv_;
  std::unique_ptr<MqttOut> mqtt_;
  std::vector<vda5050::Identity> ids_;
  std::vector<std::uint32_t> header_ids_;
  std::map<std::string, std::uint32_t> camera_header_ids_;
  std::uint64_t frames_ = 0, bad_frames_ = 0, detections_total_ = 0;
  RemoteCounters remote_;
  overhead::OrderIntake order_intake_;
  OrderCounters orders_;
  std::int64_t newest_frame_ns_ = 0;  // exposure of the newest frame processed
  static constexpr std::int64_t kMaxDataLagNs = 1'000'000'000;
  std::string tray_model_error_;  // tray.method learned with a model that cannot be used
  std::string reacquire_error_;   // the same for re-acquisition alone
};

}  // namespace agv::overhead_app
