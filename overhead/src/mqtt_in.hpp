// Subscriptions on the site broker whose messages wait in a bounded queue for the tracker's
// thread: libmosquitto's own thread only queues (topic and payload, in the order the broker
// forwarded them), so nothing it receives touches the tracks. Used for the detector processes'
// detections (`run --detections-from-broker`) and the vehicles' orders (orders.subscribe).
#pragma once

#include <atomic>
#include <condition_variable>
#include <cstddef>
#include <cstdint>
#include <deque>
#include <mutex>
#include <string>
#include <vector>

#include "config.hpp"

struct mosquitto;
struct mosquitto_message;

namespace agv::overhead_app {

struct MqttMessage {
  std::string topic, payload;
};

class MqttIn {
 public:
  // Beyond either: dropped and counted (the tracker is behind, or a client floods the broker).
  static constexpr std::size_t kMaxQueued = 10000;
  static constexpr std::size_t kMaxQueuedBytes = 64u << 20;

  MqttIn() = default;
  MqttIn(const MqttIn&) = delete;
  MqttIn& operator=(const MqttIn&) = delete;
  ~MqttIn() { stop(); }
  // Connects to cfg's broker and subscribes to every topic filter; false with *error when the
  // broker cannot be reached or has not acknowledged the subscriptions within 5 s.
  bool start(const MqttOutput& cfg, const std::vector<std::string>& topics, std::string* error);
  // The oldest message, waiting up to wait_ms; false when none came.
  bool pop(MqttMessage* out, int wait_ms);
  void stop();
  std::uint64_t overflow() const { return overflow_.load(); }

 private:
  static void on_connect(mosquitto* m, void* self, int rc);
  static void on_subscribe(mosquitto* m, void* self, int mid, int qos_count, const int* qos);
  static void on_message(mosquitto* m, void* self, const mosquitto_message* msg);

  mosquitto* mosq_ = nullptr;
  std::vector<std::string> topics_;
  std::atomic<std::size_t> acknowledged_{0};
  std::atomic<std::uint64_t> overflow_{0};
  std::mutex mu_;
  std::condition_variable cv_;
  std::deque<MqttMessage> q_;
  std::size_t queued_bytes_ = 0;
};

}  // namespace agv::overhead_app
