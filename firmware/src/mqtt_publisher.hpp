// VDA 5050 over MQTT (libmosquitto), in its own thread (docs/guide/vda5050.md): visualization from
// the output loop's newest tick, connection ONLINE / OFFLINE with a CONNECTIONBROKEN last will,
// instantActions subscribed and initPosition handed to the loop, answered in a state message.
// The loop talks to it only through MqttHandoff; a broker that is down, slow or hostile costs the
// loop nothing.
#pragma once

#include <atomic>
#include <cstdint>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include "agv/config/config.hpp"
#include "agv/vda5050/vda5050.hpp"
#include "mqtt_handoff.hpp"

struct mosquitto;
struct mosquitto_message;

namespace agv::app {

struct MqttCounters {
  std::uint64_t published = 0;        // visualization messages the client library accepted
  std::uint64_t publish_failed = 0;   // any message the client library refused (never published)
  std::uint64_t dropped_offline = 0;  // visualization samples while not connected
  std::uint64_t connects = 0;         // successful connections (1 + reconnections)
  std::uint64_t connect_failures = 0;
  std::uint64_t actions_accepted = 0;
  std::uint64_t actions_refused = 0;    // initPosition refused (answered FAILED)
  std::uint64_t messages_rejected = 0;  // instantActions messages refused as a whole
};

// Where message timestamps come from.
enum class StampClock {
  // agvloc run: the wall clock (CLOCK_REALTIME) read at each message, so that a clock set by NTP
  // after the start is followed; a visualization is stamped with its tick's wall time (now minus
  // the tick's age on CLOCK_MONOTONIC, the loop's clock).
  kWall,
  // replay: the recording's time of the newest tick (messages match poses.csv).
  kLoop,
};

// The files the configuration names (vda5050.password_file, vda5050.tls_ca_file), read the way
// start() reads them: present, a regular file, at most a bound in size, readable, not empty.
// False with one line per problem in *errors. For --check-config and start().
bool check_vda5050_files(const config::Vda5050Section& cfg, std::vector<std::string>* errors);

class MqttPublisher {
 public:
  // cpus: loop.service_cpus, where the MQTT thread runs.
  MqttPublisher(const config::Vda5050Section& cfg, MqttHandoff& handoff, StampClock stamps,
                std::string cpus = {});
  ~MqttPublisher();
  MqttPublisher(const MqttPublisher&) = delete;
  MqttPublisher& operator=(const MqttPublisher&) = delete;

  // False with *error when the configuration cannot work (version, password file, TLS).
  bool start(std::string* error);
  // Publishes connection OFFLINE, disconnects, joins.
  void stop();
  MqttCounters counters() const;

 private:
  void run();
  void try_connect();
  void connect_failed(std::int64_t now_ns, const char* why);
  void log_link(bool up, const char* why);
  bool publish(const std::string& leaf, const std::string& payload, int qos, bool retain);
  std::int64_t now_stamp_ns() const;
  std::int64_t tick_stamp_ns(std::int64_t t_ns) const;
  void on_message(const mosquitto_message* msg);
  void publish_visualization();
  void answer_actions();
  static void connect_cb(mosquitto* m, void* self, int rc);
  static void disconnect_cb(mosquitto* m, void* self, int rc);
  static void message_cb(mosquitto* m, void* self, const mosquitto_message* msg);

  config::Vda5050Section cfg_;
  std::string cpus_;
  vda5050::Identity id_;
  MqttHandoff& handoff_;
  StampClock stamps_;
  std::string password_;
  mosquitto* mosq_ = nullptr;
  std::thread thread_;
  std::atomic<bool> stop_{false};
  bool connected_ = false;
  bool connecting_ = false;  // connect started, no CONNACK yet
  std::int64_t retry_at_ns_ = 0;
  std::int64_t backoff_ns_ = 0;
  std::uint32_t header_visualization_ = 0;
  // The next connection headerId. Each connection attempt reserves two: ONLINE's and, one above
  // it, the last will's, so the will is above every message before it on the topic.
  std::uint32_t header_connection_ = 0;
  std::uint32_t header_state_ = 0;
  std::int64_t last_t_ns_ = 0;  // newest tick time (stamps the other messages)
  localizer::TickRecord last_tick_;
  // The initPosition handed to the loop and not yet answered (seq 0: none).
  std::uint64_t next_seq_ = 1;
  std::uint64_t pending_seq_ = 0;
  vda5050::InitPosition pending_;
  std::vector<vda5050::ActionResult> answers_;  // to publish in the next state message
  // Link changes logged (up or down; unknown before the first), at most kLinkLines a window.
  int link_logged_ = -1;
  std::int64_t link_window_start_ns_ = INT64_MIN;
  int link_lines_in_window_ = 0;
  std::uint64_t link_changes_unlogged_ = 0;
  mutable std::mutex counters_mutex_;
  MqttCounters counters_;
};

// One summary line: "vda5050: published N, ...".
std::string format_mqtt_counters(const MqttCounters& c, const MqttHandoff& h);

}  // namespace agv::app
