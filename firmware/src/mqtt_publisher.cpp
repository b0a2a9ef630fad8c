#include "mqtt_publisher.hpp"

#include <mosquitto.h>

#include <chrono>
#include <cinttypes>
#include <cstdio>
#include <fstream>
#include <utility>

#include "affinity.hpp"
#include "agv/hal/clock.hpp"
#include "agv/posix/realtime.hpp"

namespace agv::app {

namespace {

// Reconnection backoff: the first retry soon (a restarting broker is back in well under a second),
// doubling to a cap that finds a returned broker within 2 s even when its start is slow: with a
// 1.6 s cap a broker up 0.5 s late (a loaded machine) was found only 2.6 s after the drop's next
// retry. One attempt a second against a broker that is down costs nothing.
constexpr std::int64_t kBackoffMinNs = 100 * hal::kNsPerMs;
constexpr std::int64_t kBackoffMaxNs = 1000 * hal::kNsPerMs;
constexpr int kKeepaliveS = 10;
// A broker that accepted the TCP connection but sent no CONNACK within this is tried again.
constexpr std::int64_t kConnackTimeoutNs = 3000 * hal::kNsPerMs;
// Refusal log lines: the first ones, then every 100th (a flood must not flood the journal).
constexpr std::uint64_t kLogFirstRefusals = 10;

std::int64_t steady_ns() {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(
             std::chrono::steady_clock::now().time_since_epoch())
      .count();
}

}  // namespace

MqttPublisher::MqttPublisher(const config::Vda5050Section& cfg, MqttHandoff& handoff,
                             std::int64_t stamp_offset_ns, std::string cpus)
    : cfg_(cfg), cpus_(std::move(cpus)), handoff_(handoff), stamp_offset_ns_(stamp_offset_ns) {
  id_.interface_name = cfg.interface_name;
  id_.manufacturer = cfg.manufacturer;
  id_.serial_number = cfg.serial_number;
  id_.map_id = cfg.map_id;
  handoff_.set_period_ns(static_cast<std::int64_t>(1e9 / cfg.rate_hz));
}

MqttPublisher::~MqttPublisher() { stop(); }

bool MqttPublisher::start(std::string* error) {
  if (!vda5050::parse_version(cfg_.version, &id_.version)) {
    *error = "vda5050.version: " + cfg_.version + " is not 2.1.0 or 3.0.0";
    return false;
  }
  if (!cfg_.password_file.empty()) {
    std::ifstream in(cfg_.password_file);
    if (!in || !std::getline(in, password_)) {
      *error = "vda5050.password_file: cannot read " + cfg_.password_file;
      return false;
    }
  }
  mosquitto_lib_init();
  mosq_ = mosquitto_new(cfg_.serial_number.c_str(), /*clean_session=*/true, this);
  if (!mosq_) {
    *error = "vda5050: cannot create the MQTT client";
    return false;
  }
  if (!cfg_.username.empty() &&
      mosquitto_username_pw_set(mosq_, cfg_.username.c_str(),
                                password_.empty() ? nullptr : password_.c_str()) !=
          MOSQ_ERR_SUCCESS) {
    *error = "vda5050.username: refused by libmosquitto";
    return false;
  }
  if (!cfg_.tls_ca_file.empty()) {
    const int rc =
        mosquitto_tls_set(mosq_, cfg_.tls_ca_file.c_str(), nullptr, nullptr, nullptr, nullptr);
    if (rc != MOSQ_ERR_SUCCESS) {
      *error = "vda5050.tls_ca_file: " + cfg_.tls_ca_file + ": " + mosquitto_strerror(rc);
      return false;
    }
  }
  mosquitto_connect_callback_set(mosq_, &MqttPublisher::connect_cb);
  mosquitto_disconnect_callback_set(mosq_, &MqttPublisher::disconnect_cb);
  mosquitto_message_callback_set(mosq_, &MqttPublisher::message_cb);
  std::fprintf(stderr, "agvloc: vda5050 %s to %s:%d as %s\n", cfg_.version.c_str(),
               cfg_.broker_host.c_str(), cfg_.broker_port,
               vda5050::topic(id_, "visualization").c_str());
  thread_ = std::thread([this] { run(); });
  return true;
}

void MqttPublisher::stop() {
  if (!thread_.joinable()) {
    if (mosq_) mosquitto_destroy(mosq_);
    mosq_ = nullptr;
    return;
  }
  stop_ = true;
  thread_.join();
  mosquitto_destroy(mosq_);
  mosq_ = nullptr;
  mosquitto_lib_cleanup();
}

MqttCounters MqttPublisher::counters() const {
  std::lock_guard<std::mutex> lock(counters_mutex_);
  return counters_;
}

void MqttPublisher::publish(const std::string& leaf, const std::string& payload, int qos,
                            bool retain) {
  const std::string t = vda5050::topic(id_, leaf);
  mosquitto_publish(mosq_, nullptr, t.c_str(), static_cast<int>(payload.size()), payload.data(),
                    qos, retain);
}

void MqttPublisher::try_connect() {
  const std::int64_t now = steady_ns();
  if (connecting_) {
    if (now < retry_at_ns_) return;  // waiting for the CONNACK
    connecting_ = false;             // none in time: a failed attempt
    mosquitto_disconnect(mosq_);
    connect_failed(now);
    return;
  }
  if (now < retry_at_ns_) return;
  // The will carries the time of this attempt: the broker sends it when the connection breaks.
  const std::string will =
      vda5050::encode_connection(id_, header_connection_++, last_t_ns_ + stamp_offset_ns_,
                                 vda5050::ConnectionState::kConnectionBroken);
  const std::string will_topic = vda5050::topic(id_, "connection");
  mosquitto_will_set(mosq_, will_topic.c_str(), static_cast<int>(will.size()), will.data(), 1,
                     true);
  // Asynchronous: an unreachable host does not hold this thread (nor its stop) for a TCP timeout;
  // mosquitto_loop completes the connection (name resolution still blocks).
  const int rc =
      mosquitto_connect_async(mosq_, cfg_.broker_host.c_str(), cfg_.broker_port, kKeepaliveS);
  if (rc == MOSQ_ERR_SUCCESS) {
    // connected_ is set by the CONNACK (connect_cb); no new attempt until then or the timeout.
    connecting_ = true;
    retry_at_ns_ = now + kConnackTimeoutNs;
    return;
  }
  connect_failed(now);
}

void MqttPublisher::connect_failed(std::int64_t now_ns) {
  {
    std::lock_guard<std::mutex> lock(counters_mutex_);
    ++counters_.connect_failures;
  }
  backoff_ns_ = backoff_ns_ == 0 ? kBackoffMinNs : std::min(2 * backoff_ns_, kBackoffMaxNs);
  retry_at_ns_ = now_ns + backoff_ns_;
}

void MqttPublisher::connect_cb(mosquitto* m, void* self_v, int rc) {
  auto* self = static_cast<MqttPublisher*>(self_v);
  if (rc != 0) {
    std::fprintf(stderr, "agvloc: vda5050: broker refused the connection: %s\n",
                 mosquitto_connack_string(rc));
    return;
  }
  self->connected_ = true;
  self->connecting_ = false;
  self->backoff_ns_ = 0;
  {
    std::lock_guard<std::mutex> lock(self->counters_mutex_);
    ++self->counters_.connects;
  }
  const std::string t = vda5050::topic(self->id_, "instantActions");
  mosquitto_subscribe(m, nullptr, t.c_str(), 0);
  self->publish("connection",
                vda5050::encode_connection(self->id_, self->header_connection_++,
                                           self->last_t_ns_ + self->stamp_offset_ns_,
                                           vda5050::ConnectionState::kOnline),
                1, true);
}

void MqttPublisher::disconnect_cb(mosquitto*, void* self_v, int) {
  auto* self = static_cast<MqttPublisher*>(self_v);
  if (self->connected_) self->retry_at_ns_ = 0;  // lost: try again at once, then back off
  self->connected_ = false;
}

void MqttPublisher::message_cb(mosquitto*, void* self_v, const mosquitto_message* msg) {
  static_cast<MqttPublisher*>(self_v)->on_message(msg);
}

void MqttPublisher::on_message(const mosquitto_message* msg) {
  const std::string_view text(static_cast<const char*>(msg->payload),
                              msg->payloadlen > 0 ? static_cast<std::size_t>(msg->payloadlen) : 0);
  vda5050::ParsedActions p = vda5050::parse_instant_actions(id_, text);
  std::lock_guard<std::mutex> lock(counters_mutex_);
  if (p.message_reason != vda5050::Reason::kNone) {
    const std::uint64_t n = ++counters_.messages_rejected;
    if (n <= kLogFirstRefusals || n % 100 == 0) {
      std::fprintf(stderr, "agvloc: vda5050: instantActions refused (%s), %" PRIu64 " so far\n",
                   vda5050::reason_name(p.message_reason), n);
    }
    return;
  }
  for (vda5050::ActionResult& r : p.refused) {
    const std::uint64_t n = ++counters_.actions_refused;
    if (n <= kLogFirstRefusals || n % 100 == 0) {
      std::fprintf(stderr, "agvloc: vda5050: %s %s refused (%s)\n", r.action_type.c_str(),
                   r.action_id.c_str(), r.result_description.c_str());
    }
    answers_.push_back(std::move(r));
  }
  // Several in one message or in quick succession: the newest wins, the others are answered
  // FAILED (superseded) so that no action waits for an answer forever.
  for (vda5050::InitPosition& a : p.accepted) {
    InitPoseCommand c;
    c.seq = next_seq_++;
    c.x_mm = a.x_m * 1000.0;
    c.y_mm = a.y_m * 1000.0;
    c.theta_rad = a.theta_rad;
    handoff_.post_command(c);
    if (pending_seq_ != 0) {
      answers_.push_back(
          {pending_.action_id, pending_.action_type, vda5050::ActionStatus::kFailed, "superseded"});
    }
    pending_seq_ = c.seq;
    pending_ = std::move(a);
  }
}

void MqttPublisher::publish_visualization() {
  localizer::TickRecord tick;
  if (!handoff_.take_sample(&tick)) return;
  last_t_ns_ = tick.t_ns;
  last_tick_ = tick;
  if (!connected_) {
    std::lock_guard<std::mutex> lock(counters_mutex_);
    ++counters_.dropped_offline;
    return;
  }
  const vda5050::Position p = vda5050::map_tick(tick);
  publish("visualization",
          vda5050::encode_visualization(id_, header_visualization_++, tick.t_ns + stamp_offset_ns_,
                                        p, header_state_ == 0 ? 0 : header_state_ - 1),
          0, false);
  std::lock_guard<std::mutex> lock(counters_mutex_);
  ++counters_.published;
}

void MqttPublisher::answer_actions() {
  if (pending_seq_ != 0) {
    bool ok = false;
    if (handoff_.applied_seq(&ok) == pending_seq_) {
      std::lock_guard<std::mutex> lock(counters_mutex_);
      if (ok) {
        ++counters_.actions_accepted;
      } else {
        ++counters_.actions_refused;
      }
      answers_.push_back({pending_.action_id, pending_.action_type,
                          ok ? vda5050::ActionStatus::kFinished : vda5050::ActionStatus::kFailed,
                          ok ? "" : "refused by the filter"});
      pending_seq_ = 0;
    }
  }
  if (answers_.empty() || !connected_) return;
  // The state after the action: the pose the loop has now (the sample of the tick that applied it
  // or a later one).
  publish("state",
          vda5050::encode_state(id_, header_state_++, last_t_ns_ + stamp_offset_ns_,
                                vda5050::map_tick(last_tick_), answers_),
          0, false);
  answers_.clear();
}

void MqttPublisher::run() {
  posix::set_thread_name("agv-mqtt");
  pin_this_thread(cpus_, "MQTT, loop.service_cpus");
  while (!stop_.load()) {
    if (!connected_) try_connect();
    // Network I/O for up to 10 ms: the visualization sample waits at most this long.
    const int rc = mosquitto_loop(mosq_, 10, 1);
    if (rc != MOSQ_ERR_SUCCESS) {
      if (connected_) {
        std::fprintf(stderr, "agvloc: vda5050: %s\n", mosquitto_strerror(rc));
        retry_at_ns_ = 0;  // lost: try again at once, then back off
      } else if (connecting_) {
        connecting_ = false;  // refused or unreachable
        connect_failed(steady_ns());
      }
      connected_ = false;
      // mosquitto_loop returns at once without a connection: do not spin.
      std::this_thread::sleep_for(std::chrono::milliseconds(10));
    }
    publish_visualization();
    answer_actions();
  }
  if (connected_) {
    // An orderly end: OFFLINE replaces the retained ONLINE (the will is for a broken connection).
    publish("connection",
            vda5050::encode_connection(id_, header_connection_++, last_t_ns_ + stamp_offset_ns_,
                                       vda5050::ConnectionState::kOffline),
            1, true);
    for (int i = 0; i < 20; ++i) mosquitto_loop(mosq_, 10, 1);
    mosquitto_disconnect(mosq_);
    mosquitto_loop(mosq_, 10, 1);
  }
}

std::string format_mqtt_counters(const MqttCounters& c, const MqttHandoff& h) {
  char buf[400];
  std::snprintf(buf, sizeof buf,
                "vda5050: visualization published %" PRIu64 ", dropped while offline %" PRIu64
                ", superseded %" PRIu64 ", loop skips %" PRIu64 " | connects %" PRIu64
                ", failed attempts %" PRIu64 " | initPosition accepted %" PRIu64
                ", refused %" PRIu64 " | instantActions messages refused %" PRIu64 "\n",
                c.published, c.dropped_offline, h.superseded(), h.busy_skips(), c.connects,
                c.connect_failures, c.actions_accepted, c.actions_refused, c.messages_rejected);
  return buf;
}

}  // namespace agv::app
