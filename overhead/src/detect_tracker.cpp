// `run --detections-from-broker`: the tracker fed by the detector processes. libmosquitto's
// thread queues the payloads; this thread decodes them (a refused message is counted by reason
// and named on stderr, never applied) and hands each frame's tags to TrackerCore::apply_tags. The
// tracks are published on the detections' clock: every tick up to a frame's exposure before the
// frame, as replay does with its arrival order. With diag.enabled its page and /metrics carry
// the messages' counts (refusals by reason) and the vehicles' tracks.
#include <mosquitto.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <condition_variable>
#include <csignal>
#include <cstdio>
#include <deque>
#include <map>
#include <mutex>
#include <thread>

#include "core.hpp"
#include "detect.hpp"
#include "diag.hpp"
#include "inputs.hpp"
#include "mqtt_in.hpp"

namespace agv::overhead_app {
namespace {

std::atomic<bool> g_bus_stop{false};
extern "C" void on_bus_stop_signal(int) { g_bus_stop.store(true); }

struct BusCounters {
  std::uint64_t messages = 0, refused = 0, seq_gaps = 0;
  std::map<std::string, std::uint64_t> refused_by_reason;  // every reason, from 0
  std::map<std::string, std::uint64_t> next_seq;           // per camera id
  BusCounters() {
    // kTooManyTags is the last reason: a series per reason from the start, so a rate over
    // /metrics sees the first refusal.
    for (int r = 1; r <= static_cast<int>(overhead::MsgReason::kTooManyTags); ++r)
      refused_by_reason[reason_name(static_cast<overhead::MsgReason>(r))] = 0;
  }
};

// One payload: decoded, checked, applied. `ticks` publishes up to a time.
template <typename Ticks>
void handle(const std::string& payload, const std::vector<std::string>& camera_ids,
            TrackerCore* core, BusCounters* n, Ticks ticks) {
  overhead::DetectionMsg msg;
  ++n->messages;
  const overhead::MsgReason why = overhead::decode_detections(payload, camera_ids, &msg);
  if (why != overhead::MsgReason::kNone) {
    if (++n->refused <= 5)
      command_fail("run", 0, std::string("detections message refused: ") + reason_name(why));
    ++n->refused_by_reason[reason_name(why)];
    return;
  }
  const auto next = n->next_seq.find(msg.camera_id);
  if (next != n->next_seq.end() && msg.seq > next->second) n->seq_gaps += msg.seq - next->second;
  n->next_seq[msg.camera_id] = msg.seq + 1;
  ticks(msg.t_ns);
  const auto cam = std::find(camera_ids.begin(), camera_ids.end(), msg.camera_id);
  core->apply_tags(static_cast<std::size_t>(cam - camera_ids.begin()), msg.t_ns, msg.tags);
}

void print_bus_summary(const BusCounters& n, const TrackerCore& core, std::uint64_t overflow) {
  const auto u = [](std::uint64_t v) { return static_cast<unsigned long long>(v); };
  const TrackerCore::RemoteCounters& r = core.remote_counters();
  std::printf(
      "agvloc-overhead run: detections from the broker: %llu messages (%llu refused, %llu lost "
      "by sequence, %llu dropped behind), %llu tags (%llu unknown ids, %llu without fix, %llu "
      "restricted decodes refused)\n",
      u(n.messages), u(n.refused), u(n.seq_gaps), u(overflow), u(r.tags), u(r.unknown_ids),
      u(r.no_fix), u(r.restricted_refused));
  for (const auto& [reason, count] : n.refused_by_reason) {
    if (count > 0) std::printf("agvloc-overhead run: refused %s: %llu\n", reason.c_str(), u(count));
  }
}

// The diagnostics page of the broker-fed tracker: its counters and every vehicle's track at the
// newest tick (detections' clock); no camera of its own.
class BusDiagFeeder {
 public:
  BusDiagFeeder(const OverheadConfig& cfg, const site::Site& site) : server_(cfg.diag) {
    enabled_ = cfg.diag.enabled;
    for (const site::FleetAgv& a : site.fleet) agv_ids_.push_back(a.id);
  }
  bool start(const TrackerCore& core, std::string* error) {
    if (!enabled_) return true;
    if (!server_.start(error)) return false;
    server_.attach(core.site(), core.config().search);
    const std::string& host = core.config().diag.bind_address;
    const bool v6 = host.find(':') != std::string::npos;
    std::fprintf(stderr, "agvloc-overhead run: diag: serving http://%s%s%s:%d/\n", v6 ? "[" : "",
                 host.c_str(), v6 ? "]" : "", server_.port());
    return true;
  }
  // At most every kMinPeriod of the host's clock, and whenever `now` (the queue ran empty).
  void update(const BusCounters& n, const TrackerCore& core, std::uint64_t overflow,
              std::uint64_t ticks, std::int64_t t_ns, bool now) {
    const auto wall = std::chrono::steady_clock::now();
    if (!enabled_ || (!now && wall - last_ < kMinPeriod)) return;
    last_ = wall;
    DiagView v;
    v.t_ns = t_ns;
    v.ticks = ticks;
    v.has_bus = true;
    const TrackerCore::RemoteCounters& r = core.remote_counters();
    v.bus = {n.messages, n.seq_gaps,    overflow, n.refused_by_reason,
             r.tags,     r.unknown_ids, r.no_fix, r.restricted_refused};
    for (std::size_t a = 0; a < agv_ids_.size(); ++a) {
      AgvDiag g;
      g.id = agv_ids_[a];
      g.track = core.tracker().output(a, t_ns);
      if (g.track.state != overhead::TrackState::kNone) g.source = "tag";
      v.agvs.push_back(std::move(g));
    }
    core.fill_orders_diag(&v);
    server_.update(std::move(v));
  }
  void stop() { server_.stop(); }

 private:
  static constexpr std::chrono::milliseconds kMinPeriod{100};
  bool enabled_ = false;
  std::vector<std::string> agv_ids_;
  std::chrono::steady_clock::time_point last_{};
  OverheadDiag server_;
};

}  // namespace

int run_broker_tracker(const RunArgs& a) {
  OverheadConfig cfg;
  site::Site site;
  if (!load_config_and_site("run", a.config_path, a.site_path, &cfg, &site)) return 2;
  std::signal(SIGINT, on_bus_stop_signal);
  std::signal(SIGTERM, on_bus_stop_signal);
  std::vector<std::string> camera_ids;
  for (const site::CeilingCamera& c : site.cameras) camera_ids.push_back(c.id);
  std::string err;
  if (!check_site_topic_ids(cfg, site, true, &err)) return command_fail("run", 2, err);
  TrackerCore core(cfg, site);
  if (!core.open_outputs(a.out_dir, &err)) return command_fail("run", 1, err);
  BusDiagFeeder diag(cfg, site);
  if (!diag.start(core, &err)) return command_fail("run", 1, err);
  MqttIn in;
  const std::string topic = detections_subscription(cfg);
  std::vector<std::string> topics = {topic};
  if (cfg.orders.subscribe) topics.push_back(orders_subscription(cfg));
  if (!in.start(cfg.mqtt, topics, &err)) return command_fail("run", 1, err);
  std::fprintf(stderr, "agvloc-overhead run: detections from %s, %zu vehicles\n", topic.c_str(),
               site.fleet.size());
  if (cfg.orders.subscribe)
    std::fprintf(stderr, "agvloc-overhead run: orders from %s\n", topics.back().c_str());
  const auto end =
      std::chrono::steady_clock::now() + std::chrono::nanoseconds(std::llround(a.duration_s * 1e9));
  bool started = false;
  std::int64_t next_tick = 0;
  std::uint64_t ticks_done = 0;
  const auto ticks = [&](std::int64_t t_ns) {
    if (!started) next_tick = t_ns, started = true;
    for (; next_tick <= t_ns; next_tick += core.period_ns(), ++ticks_done) core.publish(next_tick);
  };
  BusCounters n;
  MqttMessage msg;
  while (!g_bus_stop.load() && (a.duration_s <= 0.0 || std::chrono::steady_clock::now() < end)) {
    const bool got = in.pop(&msg, 100);
    const std::int64_t newest_ns = started ? next_tick - core.period_ns() : 0;
    if (got && is_order_topic(cfg, msg.topic))
      core.apply_order(msg.topic, msg.payload, newest_ns);
    else if (got)
      handle(msg.payload, camera_ids, &core, &n, ticks);
    diag.update(n, core, in.overflow(), ticks_done, newest_ns, !got);
  }
  in.stop();
  diag.stop();
  if (started) core.publish(next_tick);
  print_bus_summary(n, core, in.overflow());
  if (!core.finish("agvloc-overhead run", site.cameras.size(), &err))
    return command_fail("run", 1, err);
  return 0;
}

}  // namespace agv::overhead_app
