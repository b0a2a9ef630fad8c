#include "mqtt_in.hpp"

#include <mosquitto.h>

#include <algorithm>
#include <chrono>
#include <cstring>
#include <thread>

namespace agv::overhead_app {

namespace {
constexpr int kConnectTimeoutMs = 5000;
}  // namespace

bool MqttIn::start(const MqttOutput& cfg, const std::vector<std::string>& topics,
                   std::string* error) {
  topics_ = topics;
  mosquitto_lib_init();
  mosq_ = mosquitto_new(nullptr, true, this);
  if (!mosq_) return (*error = "cannot create an MQTT client", false);
  mosquitto_connect_callback_set(mosq_, &MqttIn::on_connect);
  mosquitto_subscribe_callback_set(mosq_, &MqttIn::on_subscribe);
  mosquitto_message_callback_set(mosq_, &MqttIn::on_message);
  mosquitto_reconnect_delay_set(mosq_, 1, 10, true);
  int rc = mosquitto_connect_async(mosq_, cfg.broker_host.c_str(), cfg.port, 30);
  if (rc == MOSQ_ERR_SUCCESS) rc = mosquitto_loop_start(mosq_);
  const std::string where = "broker " + cfg.broker_host + ":" + std::to_string(cfg.port) + ": ";
  if (rc != MOSQ_ERR_SUCCESS) return (*error = where + mosquitto_strerror(rc), false);
  const auto until =
      std::chrono::steady_clock::now() + std::chrono::milliseconds(kConnectTimeoutMs);
  while (acknowledged_.load() < topics_.size() && std::chrono::steady_clock::now() < until)
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  if (acknowledged_.load() < topics_.size())
    return (*error = where + "not subscribed within 5 s", false);
  return true;
}

bool MqttIn::pop(MqttMessage* out, int wait_ms) {
  std::unique_lock<std::mutex> lock(mu_);
  if (!cv_.wait_for(lock, std::chrono::milliseconds(wait_ms), [&] { return !q_.empty(); }))
    return false;
  *out = std::move(q_.front());
  q_.pop_front();
  queued_bytes_ -= out->topic.size() + out->payload.size();
  return true;
}

void MqttIn::stop() {
  if (!mosq_) return;
  mosquitto_disconnect(mosq_);
  mosquitto_loop_stop(mosq_, false);
  mosquitto_destroy(mosq_);
  mosq_ = nullptr;
  mosquitto_lib_cleanup();
}

void MqttIn::on_connect(mosquitto* m, void* self, int rc) {
  if (rc != 0) return;
  for (const std::string& t : static_cast<MqttIn*>(self)->topics_)
    mosquitto_subscribe(m, nullptr, t.c_str(), 0);
}

void MqttIn::on_subscribe(mosquitto*, void* self, int, int, const int*) {
  ++static_cast<MqttIn*>(self)->acknowledged_;
}

void MqttIn::on_message(mosquitto*, void* self, const mosquitto_message* msg) {
  auto* in = static_cast<MqttIn*>(self);
  std::lock_guard<std::mutex> lock(in->mu_);
  const std::size_t topic_len = msg->topic ? std::strlen(msg->topic) : 0;
  const std::size_t bytes = topic_len + static_cast<std::size_t>(std::max(msg->payloadlen, 0));
  if (in->q_.size() >= kMaxQueued || in->queued_bytes_ + bytes > kMaxQueuedBytes) {
    ++in->overflow_;
    return;
  }
  in->q_.push_back({std::string(msg->topic ? msg->topic : "", topic_len),
                    std::string(static_cast<const char*>(msg->payload),
                                static_cast<std::size_t>(std::max(msg->payloadlen, 0)))});
  in->queued_bytes_ += bytes;
  in->cv_.notify_one();
}

}  // namespace agv::overhead_app
