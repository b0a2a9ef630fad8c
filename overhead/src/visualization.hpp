// The tracker's output on MQTT: per vehicle, a VDA 5050 `visualization` message (agvPosition in
// metres, velocity) on <interface_name>/v<major>/<manufacturer>/<agv id>/visualization, through
// libmosquitto (docs/guide/overhead.md "MQTT").
#pragma once

#include <atomic>
#include <cstdint>
#include <string>

#include "agv/overhead/tracker.hpp"
#include "agv/vda5050/vda5050.hpp"
#include "config.hpp"

struct mosquitto;

namespace agv::overhead_app {

// localizationScore of a track: 1 - 3 sigma / 100 mm clamped to [0, 1] (the vehicle's mapping,
// docs/guide/vda5050.md), capped at 0.5 while coasting (extrapolated, not seen) and 0 unless the
// track is confirmed or coasting (positionInitialized false).
vda5050::Position position_of(const overhead::TrackOutput& t);

vda5050::Identity identity_of(const MqttOutput& cfg, const std::string& map_id,
                              const std::string& agv_id);

// One vehicle's visualization message; epoch_ns is the message's timestamp (Unix epoch).
std::string visualization_json(const vda5050::Identity& id, std::uint32_t header_id,
                               std::int64_t epoch_ns, const overhead::TrackOutput& t);

class MqttOut {
 public:
  MqttOut() = default;
  ~MqttOut();
  MqttOut(const MqttOut&) = delete;
  MqttOut& operator=(const MqttOut&) = delete;

  // Connects (libmosquitto's own thread keeps the link and reconnects); false with *error when
  // the broker does not accept the connection within connect_timeout_ms.
  bool start(const MqttOutput& cfg, int connect_timeout_ms, std::string* error);
  // QoS 0; a message the library refuses (link down) is counted as dropped.
  void publish(const std::string& topic, const std::string& payload);
  // Waits up to flush_timeout_ms for the queued messages to be written, then disconnects.
  void stop(int flush_timeout_ms);

  std::uint64_t sent() const { return sent_.load(); }
  std::uint64_t dropped() const { return dropped_; }

 private:
  static void on_connect(mosquitto* m, void* self, int rc);
  static void on_publish(mosquitto* m, void* self, int mid);
  mosquitto* mosq_ = nullptr;
  std::atomic<int> connack_{-1};
  std::atomic<std::uint64_t> sent_{0};
  std::uint64_t queued_ = 0, dropped_ = 0;
};

}  // namespace agv::overhead_app
