#include "run.hpp"

#include <atomic>
#include <cmath>
#include <cstdio>

#include "detect.hpp"
#include "inputs.hpp"
#include "live.hpp"

namespace agv::overhead_app {

namespace {

std::atomic<bool> g_stop{false};

extern "C" void on_stop_signal(int) { g_stop.store(true); }

}  // namespace

int run_live_command(const RunArgs& args) {
  LiveInputs in;
  if (!start_live("run", args.config_path, args.site_path, on_stop_signal, &in)) return 2;
  std::string err;
  TrackerCore core(in.cfg, in.site);
  if (!core.open_outputs(args.out_dir, &err)) return command_fail("run", 1, err);
  OverheadDiag diag(in.cfg.diag);
  LiveDiag live_diag;
  if (in.cfg.diag.enabled) {
    if (!diag.start(&err)) return command_fail("run", 1, err);
    live_diag.server = &diag;
    for (const site::FleetAgv& a : in.site.fleet) live_diag.agv_ids.push_back(a.id);
    const bool v6 = in.cfg.diag.bind_address.find(':') != std::string::npos;
    std::fprintf(stderr, "agvloc-overhead run: diag: serving http://%s%s%s:%d/\n", v6 ? "[" : "",
                 in.cfg.diag.bind_address.c_str(), v6 ? "]" : "", diag.port());
  }
  std::fprintf(stderr, "agvloc-overhead run: %zu cameras, %zu vehicles, publishing at %g Hz\n",
               in.cams.size(), in.site.fleet.size(), in.cfg.output_rate_hz);
  MqttIn orders;
  if (in.cfg.orders.subscribe) {
    const std::string topic = orders_subscription(in.cfg);
    if (!orders.start(in.cfg.mqtt, {topic}, &err)) return command_fail("run", 1, err);
    std::fprintf(stderr, "agvloc-overhead run: orders from %s\n", topic.c_str());
  }
  const LiveCounters n = run_live(&in.cams, &core, g_stop,
                                  static_cast<std::int64_t>(std::llround(args.duration_s * 1e9)),
                                  live_diag, in.cfg.orders.subscribe ? &orders : nullptr);
  orders.stop();
  std::printf(
      "agvloc-overhead run: %llu ticks (%llu skipped), %llu frames dropped behind, %llu "
      "camera reopens\n",
      static_cast<unsigned long long>(n.ticks), static_cast<unsigned long long>(n.ticks_skipped),
      static_cast<unsigned long long>(n.frames_dropped),
      static_cast<unsigned long long>(n.reopens));
  for (std::size_t i = 0; i < in.cams.size(); ++i)
    std::printf("agvloc-overhead run: camera %s\n", describe(in.cams[i].id, n.cameras[i]).c_str());
  if (!core.finish("agvloc-overhead run", in.cams.size(), &err)) return command_fail("run", 1, err);
  return 0;
}

}  // namespace agv::overhead_app
