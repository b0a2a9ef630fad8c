#include "mqtt_publisher.hpp"

#include <mosquitto.h>

#include <cerrno>
#include <chrono>
#include <cinttypes>
#include <cstdio>
#include <cstring>
#include <utility>

#include "affinity.hpp"
#include "agv/common/log_escape.hpp"
#include "agv/hal/clock.hpp"
#include "agv/posix/realtime.hpp"
#include "agv/recording/recording.hpp"

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
// Link change lines (connected / lost): at most this many a window; a flapping broker's further
// changes are counted in the next line that is written.
constexpr int kLinkLines = 6;
constexpr std::int64_t kLinkWindowNs = 60'000 * hal::kNsPerMs;
// A password is one line; a CA bundle is a few hundred kB at most (Debian's whole bundle: 220 kB).
constexpr std::uintmax_t kMaxPasswordFileBytes = 4096;
constexpr std::uintmax_t kMaxCaFileBytes = 1u << 20;

std::int64_t steady_ns() {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(
             std::chrono::steady_clock::now().time_since_epoch())
      .count();
}

std::int64_t wall_ns() {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(
             std::chrono::system_clock::now().time_since_epoch())
      .count();
}

// The password: the file's first line, without a trailing CR.
bool read_password(const std::string& path, std::string* password, std::string* error) {
  std::string text;
  if (!recording::read_file_bounded(path, kMaxPasswordFileBytes, &text, error)) {
    *error = "vda5050.password_file: " + *error;
    return false;
  }
  *password = text.substr(0, text.find('\n'));
  if (!password->empty() && password->back() == '\r') password->pop_back();
  if (password->empty()) {
    *error = "vda5050.password_file: " + path + ": the first line is empty (no password)";
    return false;
  }
  return true;
}

bool check_ca_file(const std::string& path, std::string* error) {
  std::string text;
  if (!recording::read_file_bounded(path, kMaxCaFileBytes, &text, error)) {
    *error = "vda5050.tls_ca_file: " + *error;
    return false;
  }
  if (text.find("-----BEGIN CERTIFICATE-----") == std::string::npos) {
    *error = "vda5050.tls_ca_file: " + path + ": no PEM certificate in it";
    return false;
  }
  return true;
}

}  // namespace

bool check_vda5050_files(const config::Vda5050Section& cfg, std::vector<std::string>* errors) {
  const std::size_t before = errors->size();
  std::string error, password;
  if (!cfg.password_file.empty() && !read_password(cfg.password_file, &password, &error)) {
    errors->push_back(error);
  }
  if (!cfg.tls_ca_file.empty() && !check_ca_file(cfg.tls_ca_file, &error)) {
    errors->push_back(error);
  }
  return errors->size() == before;
}

MqttPublisher::MqttPublisher(const config::Vda5050Section& cfg, MqttHandoff& handoff,
                             StampClock stamps, std::string cpus)
    : cfg_(cfg), cpus_(std::move(cpus)), handoff_(handoff), stamps_(stamps) {
  id_.interface_name = cfg.interface_name;
  id_.manufacturer = cfg.manufacturer;
  id_.serial_number = cfg.serial_number;
  id_.map_id = cfg.map_id;
  handoff_.set_period_ns(static_cast<std::int64_t>(1e9 / cfg.rate_hz));
}

MqttPublisher::~MqttPublisher() { stop(); }

bool MqttPublisher::start(std::string* error) {
  if (!vda5050::parse_version(cfg_.version, &id_.version)) {
    *error = "vda5050.version: " + cfg_.version + " is not 2.0.0, 2.1.0 or 3.0.0";
    return false;
  }
  if (!cfg_.password_file.empty() && !read_password(cfg_.password_file, &password_, error)) {
    return false;
  }
  if (!cfg_.tls_ca_file.empty() && !check_ca_file(cfg_.tls_ca_file, error)) return false;
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
               escape_for_log(cfg_.broker_host).c_str(), cfg_.broker_port,
               escape_for_log(vda5050::topic(id_, "visualization")).c_str());
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

bool MqttPublisher::publish(const std::string& leaf, const std::string& payload, int qos,
                            bool retain) {
  const std::string t = vda5050::topic(id_, leaf);
  const int rc = mosquitto_publish(mosq_, nullptr, t.c_str(), static_cast<int>(payload.size()),
                                   payload.data(), qos, retain);
  if (rc == MOSQ_ERR_SUCCESS) return true;
  std::lock_guard<std::mutex> lock(counters_mutex_);
  const std::uint64_t n = ++counters_.publish_failed;
  if (n <= kLogFirstRefusals || n % 100 == 0) {
    std::fprintf(stderr, "agvloc: vda5050: %s not published (%s), %" PRIu64 " so far\n",
                 escape_for_log(t).c_str(), mosquitto_strerror(rc), n);
  }
  return false;
}

std::int64_t MqttPublisher::now_stamp_ns() const {
  return stamps_ == StampClock::kWall ? wall_ns() : last_t_ns_;
}

std::int64_t MqttPublisher::tick_stamp_ns(std::int64_t t_ns) const {
  if (stamps_ == StampClock::kLoop) return t_ns;
  const std::int64_t age_ns = steady_ns() - t_ns;
  return wall_ns() - (age_ns > 0 ? age_ns : 0);
}

void MqttPublisher::log_link(bool up, const char* why) {
  if (link_logged_ == (up ? 1 : 0)) return;  // not a change
  link_logged_ = up ? 1 : 0;
  const std::int64_t now = steady_ns();
  if (link_window_start_ns_ == INT64_MIN || now - link_window_start_ns_ >= kLinkWindowNs) {
    link_window_start_ns_ = now;
    link_lines_in_window_ = 0;
  }
  if (link_lines_in_window_ >= kLinkLines) {
    ++link_changes_unlogged_;
    return;
  }
  ++link_lines_in_window_;
  char unlogged[64] = "";
  if (link_changes_unlogged_ > 0) {
    std::snprintf(unlogged, sizeof unlogged, " (%" PRIu64 " earlier changes not logged)",
                  link_changes_unlogged_);
    link_changes_unlogged_ = 0;
  }
  const std::string host = escape_for_log(cfg_.broker_host);
  if (up) {
    std::fprintf(stderr, "agvloc: vda5050: connected to %s:%d%s\n", host.c_str(), cfg_.broker_port,
                 unlogged);
  } else {
    std::fprintf(stderr, "agvloc: vda5050: no connection to %s:%d (%s); retrying%s\n", host.c_str(),
                 cfg_.broker_port, why, unlogged);
  }
}

void MqttPublisher::try_connect() {
  const std::int64_t now = steady_ns();
  if (connecting_) {
    if (now < retry_at_ns_) return;  // waiting for the CONNACK
    connecting_ = false;             // none in time: a failed attempt
    mosquitto_disconnect(mosq_);
    connect_failed(now, "no CONNACK in time");
    return;
  }
  if (now < retry_at_ns_) return;
  // The will carries the time of this attempt: the broker sends it when the connection breaks.
  // Its headerId is the one above ONLINE's (reserved in connect_cb): MQTT 3.1.1 sets the will
  // only with the connection, before ONLINE is sent.
  const std::string will = vda5050::encode_connection(id_, header_connection_ + 1, now_stamp_ns(),
                                                      vda5050::ConnectionState::kConnectionBroken);
  const std::string will_topic = vda5050::topic(id_, "connection");
  const int will_rc = mosquitto_will_set(mosq_, will_topic.c_str(), static_cast<int>(will.size()),
                                         will.data(), 1, true);
  if (will_rc != MOSQ_ERR_SUCCESS) {
    // A topic the library refuses (the configuration checker refuses it first): no connection,
    // so nothing is published and nothing counted as published.
    connect_failed(now, (std::string("the last will on ") + escape_for_log(will_topic) + ": " +
                         mosquitto_strerror(will_rc))
                            .c_str());
    return;
  }
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
  connect_failed(now, rc == MOSQ_ERR_ERRNO ? std::strerror(errno) : mosquitto_strerror(rc));
}

void MqttPublisher::connect_failed(std::int64_t now_ns, const char* why) {
  {
    std::lock_guard<std::mutex> lock(counters_mutex_);
    ++counters_.connect_failures;
  }
  log_link(false, why);
  backoff_ns_ = backoff_ns_ == 0 ? kBackoffMinNs : std::min(2 * backoff_ns_, kBackoffMaxNs);
  retry_at_ns_ = now_ns + backoff_ns_;
}

void MqttPublisher::connect_cb(mosquitto* m, void* self_v, int rc) {
  auto* self = static_cast<MqttPublisher*>(self_v);
  if (rc != 0) {
    // The attempt ends at the CONNACK timeout (try_connect); logged as a change, not per retry.
    self->log_link(false, mosquitto_connack_string(rc));
    return;
  }
  self->connected_ = true;
  self->connecting_ = false;
  self->backoff_ns_ = 0;
  {
    std::lock_guard<std::mutex> lock(self->counters_mutex_);
    ++self->counters_.connects;
  }
  self->log_link(true, "");
  const std::string t = vda5050::topic(self->id_, "instantActions");
  mosquitto_subscribe(m, nullptr, t.c_str(), 0);
  const std::uint32_t online_id = self->header_connection_;
  self->header_connection_ += 2;  // online_id + 1 is the will's
  self->publish("connection",
                vda5050::encode_connection(self->id_, online_id, self->now_stamp_ns(),
                                           vda5050::ConnectionState::kOnline),
                1, true);
}

void MqttPublisher::disconnect_cb(mosquitto*, void* self_v, int rc) {
  auto* self = static_cast<MqttPublisher*>(self_v);
  if (self->connected_) {
    self->retry_at_ns_ = 0;  // lost: try again at once, then back off
    self->log_link(false, rc == 0 ? "disconnected" : mosquitto_strerror(rc));
  }
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
      std::fprintf(stderr, "agvloc: vda5050: %s %s refused (%s)\n",
                   escape_for_log(r.action_type).c_str(), escape_for_log(r.action_id).c_str(),
                   escape_for_log(r.result_description).c_str());
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
  CommandAnswer answer;
  if (!handoff_.take_sample(&tick, &answer)) return;
  last_t_ns_ = tick.t_ns;
  last_tick_ = tick;
  if (answer.seq != 0 && answer.seq == pending_seq_) {
    // This sample is the tick that applied the command (or a later one): the state answering it
    // carries the pose after the action.
    {
      std::lock_guard<std::mutex> lock(counters_mutex_);
      ++(answer.ok ? counters_.actions_accepted : counters_.actions_refused);
    }
    answers_.push_back(
        {pending_.action_id, pending_.action_type,
         answer.ok ? vda5050::ActionStatus::kFinished : vda5050::ActionStatus::kFailed,
         answer.ok ? "" : "refused by the filter"});
    pending_seq_ = 0;
  }
  if (!connected_) {
    std::lock_guard<std::mutex> lock(counters_mutex_);
    ++counters_.dropped_offline;
    return;
  }
  const vda5050::Position p = vda5050::map_tick(tick);
  const bool ok =
      publish("visualization",
              vda5050::encode_visualization(id_, header_visualization_++, tick_stamp_ns(tick.t_ns),
                                            p, header_state_ == 0 ? 0 : header_state_ - 1),
              0, false);
  if (ok) {
    std::lock_guard<std::mutex> lock(counters_mutex_);
    ++counters_.published;
  }
}

void MqttPublisher::answer_actions() {
  if (answers_.empty() || !connected_) return;
  // last_tick_: the sample that carried the loop's answer, or a later one.
  publish("state",
          vda5050::encode_state(id_, header_state_++, now_stamp_ns(), vda5050::map_tick(last_tick_),
                                answers_),
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
      const char* why = rc == MOSQ_ERR_ERRNO ? std::strerror(errno) : mosquitto_strerror(rc);
      if (connected_) {
        log_link(false, why);
        retry_at_ns_ = 0;  // lost: try again at once, then back off
      } else if (connecting_) {
        connecting_ = false;  // refused or unreachable
        connect_failed(steady_ns(), why);
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
            vda5050::encode_connection(id_, header_connection_++, now_stamp_ns(),
                                       vda5050::ConnectionState::kOffline),
            1, true);
    for (int i = 0; i < 20; ++i) mosquitto_loop(mosq_, 10, 1);
    connected_ = false;  // an orderly end is not a lost link (disconnect_cb logs nothing)
    mosquitto_disconnect(mosq_);
    mosquitto_loop(mosq_, 10, 1);
  }
}

std::string format_mqtt_counters(const MqttCounters& c, const MqttHandoff& h) {
  char buf[440];
  std::snprintf(
      buf, sizeof buf,
      "vda5050: visualization published %" PRIu64 ", publish failed %" PRIu64
      ", dropped while offline %" PRIu64 ", superseded %" PRIu64 ", loop skips %" PRIu64
      " | connects %" PRIu64 ", failed attempts %" PRIu64 " | initPosition accepted %" PRIu64
      ", refused %" PRIu64 " | instantActions messages refused %" PRIu64 "\n",
      c.published, c.publish_failed, c.dropped_offline, h.superseded(), h.busy_skips(), c.connects,
      c.connect_failures, c.actions_accepted, c.actions_refused, c.messages_rejected);
  return buf;
}

}  // namespace agv::app
