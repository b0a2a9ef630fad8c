#include "visualization.hpp"

#include <mosquitto.h>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <cstring>
#include <thread>

namespace agv::overhead_app {

vda5050::Position position_of(const overhead::TrackOutput& t) {
  vda5050::Position p;
  p.x_m = t.pose.x_mm / 1000.0;
  p.y_m = t.pose.y_mm / 1000.0;
  p.theta_rad = std::remainder(t.pose.theta_rad, 2.0 * M_PI);
  p.initialized = t.valid();
  p.vx_mps = t.v_mps;
  p.omega_radps = t.omega_radps;
  if (!p.initialized) {
    p.localization_score = 0.0;
    p.deviation_range_m = -1.0;
    return p;
  }
  const double three_sigma_mm = 3.0 * t.sigma_xy_mm;
  p.deviation_range_m = three_sigma_mm / 1000.0;
  p.localization_score =
      std::clamp(1.0 - three_sigma_mm / vda5050::kScoreZeroAtDeviationMm, 0.0, 1.0);
  if (t.state == overhead::TrackState::kCoasting) {
    p.localization_score = std::min(p.localization_score, vda5050::kDeadReckoningScoreCap);
  }
  return p;
}

vda5050::Identity identity_of(const MqttOutput& cfg, const std::string& map_id,
                              const std::string& agv_id) {
  vda5050::Identity id;
  vda5050::parse_version(cfg.version, &id.version);  // checked by the configuration
  id.interface_name = cfg.interface_name;
  id.manufacturer = cfg.manufacturer;
  id.serial_number = agv_id;
  id.map_id = map_id;
  return id;
}

std::string visualization_json(const vda5050::Identity& id, std::uint32_t header_id,
                               std::int64_t epoch_ns, const overhead::TrackOutput& t) {
  return vda5050::encode_visualization(id, header_id, epoch_ns, position_of(t), 0);
}

MqttOut::~MqttOut() { stop(0); }

void MqttOut::on_connect(mosquitto*, void* self, int rc) {
  static_cast<MqttOut*>(self)->connack_.store(rc);
}

void MqttOut::on_publish(mosquitto*, void* self, int) { ++static_cast<MqttOut*>(self)->sent_; }

bool MqttOut::start(const MqttOutput& cfg, int connect_timeout_ms, std::string* error) {
  mosquitto_lib_init();
  mosq_ = mosquitto_new(nullptr, /*clean_session=*/true, this);
  if (!mosq_) return (*error = "output.mqtt: cannot create an MQTT client", false);
  mosquitto_connect_callback_set(mosq_, &MqttOut::on_connect);
  mosquitto_publish_callback_set(mosq_, &MqttOut::on_publish);
  mosquitto_reconnect_delay_set(mosq_, 1, 10, true);
  const std::string where =
      "output.mqtt: broker " + cfg.broker_host + ":" + std::to_string(cfg.port) + ": ";
  int rc = mosquitto_connect_async(mosq_, cfg.broker_host.c_str(), cfg.port, 30);
  if (rc == MOSQ_ERR_SUCCESS) rc = mosquitto_loop_start(mosq_);
  if (rc != MOSQ_ERR_SUCCESS) {
    *error = where + (rc == MOSQ_ERR_ERRNO ? std::strerror(errno) : mosquitto_strerror(rc));
    stop(0);
    return false;
  }
  const auto until =
      std::chrono::steady_clock::now() + std::chrono::milliseconds(connect_timeout_ms);
  while (connack_.load() < 0 && std::chrono::steady_clock::now() < until) {
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  }
  const int ack = connack_.load();
  if (ack != 0) {
    *error = where + (ack < 0 ? "no connection within " + std::to_string(connect_timeout_ms) + " ms"
                              : std::string(mosquitto_connack_string(ack)));
    stop(0);
    return false;
  }
  return true;
}

void MqttOut::publish(const std::string& topic, const std::string& payload) {
  if (!mosq_) return;
  const int rc = mosquitto_publish(mosq_, nullptr, topic.c_str(), static_cast<int>(payload.size()),
                                   payload.data(), 0, false);
  if (rc == MOSQ_ERR_SUCCESS) {
    ++queued_;
  } else {
    ++dropped_;
  }
}

void MqttOut::stop(int flush_timeout_ms) {
  if (!mosq_) return;
  const auto until = std::chrono::steady_clock::now() + std::chrono::milliseconds(flush_timeout_ms);
  while (sent_.load() < queued_ && std::chrono::steady_clock::now() < until) {
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  }
  mosquitto_disconnect(mosq_);
  mosquitto_loop_stop(mosq_, false);
  mosquitto_destroy(mosq_);
  mosq_ = nullptr;
  mosquitto_lib_cleanup();
}

}  // namespace agv::overhead_app
