#include "run.hpp"

#include <atomic>
#include <cmath>
#include <csignal>
#include <cstdio>

#include "inputs.hpp"
#include "live.hpp"

namespace agv::overhead_app {

namespace {

std::atomic<bool> g_stop{false};

extern "C" void on_stop_signal(int) { g_stop.store(true); }

int run_fail(int code, const std::string& msg) {
  std::fprintf(stderr, "agvloc-overhead run: %s\n", msg.c_str());
  return code;
}

}  // namespace

int run_live_command(const RunArgs& args) {
  OverheadConfig cfg;
  std::vector<std::string> errors;
  if (!load_config(args.config_path, &cfg, &errors)) {
    for (const std::string& e : errors) run_fail(2, e);
    return 2;
  }
  site::Site site;
  if (!load_site_file(args.site_path, &site, &errors)) {
    for (const std::string& e : errors) run_fail(2, e);
    return 2;
  }
  std::string err;
  if (!check_config_against_site(cfg, site, &err))
    return run_fail(2, args.config_path + ": " + err);
  std::vector<LiveCamera> cams;
  if (!make_live_cameras(cfg, site, &cams, &err)) return run_fail(2, args.config_path + ": " + err);
  TrackerCore core(cfg, site);
  if (!core.open_outputs(args.out_dir, &err)) return run_fail(1, err);
  struct sigaction sa {};
  sa.sa_handler = on_stop_signal;
  sigemptyset(&sa.sa_mask);
  sigaction(SIGINT, &sa, nullptr);
  sigaction(SIGTERM, &sa, nullptr);
  OverheadDiag diag(cfg.diag);
  LiveDiag live_diag;
  if (cfg.diag.enabled) {
    if (!diag.start(&err)) return run_fail(1, err);
    live_diag.server = &diag;
    for (const site::FleetAgv& a : site.fleet) live_diag.agv_ids.push_back(a.id);
    const bool v6 = cfg.diag.bind_address.find(':') != std::string::npos;
    std::fprintf(stderr, "agvloc-overhead run: diag: serving http://%s%s%s:%d/\n", v6 ? "[" : "",
                 cfg.diag.bind_address.c_str(), v6 ? "]" : "", diag.port());
  }
  std::fprintf(stderr, "agvloc-overhead run: %zu cameras, %zu vehicles, publishing at %g Hz\n",
               cams.size(), site.fleet.size(), cfg.output_rate_hz);
  const LiveCounters n =
      run_live(&cams, &core, g_stop, static_cast<std::int64_t>(std::llround(args.duration_s * 1e9)),
               live_diag);
  std::printf(
      "agvloc-overhead run: %llu ticks (%llu skipped), %llu frames dropped behind, %llu "
      "camera reopens\n",
      static_cast<unsigned long long>(n.ticks), static_cast<unsigned long long>(n.ticks_skipped),
      static_cast<unsigned long long>(n.frames_dropped),
      static_cast<unsigned long long>(n.reopens));
  for (std::size_t i = 0; i < cams.size(); ++i)
    std::printf("agvloc-overhead run: camera %s\n", describe(cams[i].id, n.cameras[i]).c_str());
  if (!core.finish("agvloc-overhead run", cams.size(), &err)) return run_fail(1, err);
  return 0;
}

}  // namespace agv::overhead_app
