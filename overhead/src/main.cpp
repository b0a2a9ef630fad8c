// agvloc-overhead: the site's fleet tracked from ceiling cameras (docs/guide/overhead.md).
// Subcommands: check-config, replay, run, record, config-doc.
#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>
#include <vector>

#include "config.hpp"
#include "detect.hpp"
#include "inputs.hpp"
#include "record.hpp"
#include "replay.hpp"
#include "run.hpp"

namespace {

using agv::overhead_app::ReplayArgs;

constexpr const char* kUsage =
    "usage: agvloc-overhead <command> [options]\n"
    "  check-config CONFIG [--site SITE]   check a configuration (and its cameras against a site)\n"
    "  replay --config C --site SITE --recordings DIR... [--out OUT] [--fast]\n"
    "                                      track the fleet in recorded frames of ceiling cameras\n"
    "  run --config C --site SITE [--out OUT] [--duration-s S]\n"
    "                                      live ceiling cameras (V4L2, libcamera, Aravis) until\n"
    "                                      SIGTERM\n"
    "  run --detections-from-broker --config C --site SITE [--out OUT] [--duration-s S]\n"
    "                                      track from the detector processes' tags on the broker\n"
    "  detect --config C --site SITE --camera ID --replay DIR [--fast]\n"
    "                                      one camera's tags to the broker (a recording of it)\n"
    "  record --config C --site SITE --out DIR [--duration-s S]\n"
    "                                      record every configured camera, one folder each under\n"
    "                                      DIR, for replay\n"
    "  config-doc                          print the configuration key table (Markdown)\n"
    "Exit codes: 0 done, 1 failure while running, 2 bad input. docs/guide/overhead.md\n";

int usage_error(const std::string& msg) {
  std::fprintf(stderr, "agvloc-overhead: %s\n%s", msg.c_str(), kUsage);
  return 2;
}

bool is_option(const char* a) { return std::strncmp(a, "--", 2) == 0; }

// Options of replay; false with *error on an unknown or incomplete option.
bool parse_replay(int argc, char** argv, ReplayArgs* a, std::string* error) {
  for (int i = 0; i < argc; ++i) {
    const std::string o = argv[i];
    auto value = [&](std::string* out) {
      if (i + 1 >= argc || is_option(argv[i + 1])) return (*error = o + " needs a value", false);
      *out = argv[++i];
      return true;
    };
    if (o == "--config") {
      if (!value(&a->config_path)) return false;
    } else if (o == "--site") {
      if (!value(&a->site_path)) return false;
    } else if (o == "--out") {
      if (!value(&a->out_dir)) return false;
    } else if (o == "--fast") {
      a->fast = true;
    } else if (o == "--recordings") {
      while (i + 1 < argc && !is_option(argv[i + 1])) a->recordings.emplace_back(argv[++i]);
    } else {
      return (*error = "unknown option '" + o + "'", false);
    }
  }
  if (a->site_path.empty()) return (*error = "--site is required", false);
  if (a->recordings.empty()) return (*error = "--recordings needs at least one folder", false);
  return true;
}

// Options of detect; false with *error on an unknown or incomplete option.
bool parse_detect(int argc, char** argv, agv::overhead_app::DetectArgs* a, std::string* error) {
  for (int i = 0; i < argc; ++i) {
    const std::string o = argv[i];
    if (o == "--fast") {
      a->fast = true;
      continue;
    }
    if (i + 1 >= argc || is_option(argv[i + 1])) return (*error = o + " needs a value", false);
    const std::string v = argv[++i];
    if (o == "--config") {
      a->config_path = v;
    } else if (o == "--site") {
      a->site_path = v;
    } else if (o == "--camera") {
      a->camera = v;
    } else if (o == "--replay") {
      a->replay_dir = v;
    } else {
      return (*error = "unknown option '" + o + "'", false);
    }
  }
  if (a->site_path.empty()) return (*error = "--site is required", false);
  if (a->camera.empty()) return (*error = "--camera is required", false);
  if (a->replay_dir.empty())
    return (*error = "--replay is required (the camera's recording)", false);
  return true;
}

// Options of run and record; false with *error on an unknown, incomplete or out-of-range option.
template <typename Args>
bool parse_live(int argc, char** argv, Args* a, std::string* error) {
  for (int i = 0; i < argc; ++i) {
    const std::string o = argv[i];
    if (i + 1 >= argc || is_option(argv[i + 1])) return (*error = o + " needs a value", false);
    const std::string v = argv[++i];
    if (o == "--config") {
      a->config_path = v;
    } else if (o == "--site") {
      a->site_path = v;
    } else if (o == "--out") {
      a->out_dir = v;
    } else if (o == "--duration-s") {
      char* end = nullptr;
      a->duration_s = std::strtod(v.c_str(), &end);
      if (end == v.c_str() || *end != '\0' || !(a->duration_s > 0.0 && a->duration_s <= 1e7)) {
        return (*error = "--duration-s takes seconds in (0, 1e7]", false);
      }
    } else {
      return (*error = "unknown option '" + o + "'", false);
    }
  }
  if (a->config_path.empty())
    return (*error = "--config is required (the cameras' devices)", false);
  if (a->site_path.empty()) return (*error = "--site is required", false);
  return true;
}

int check_config(int argc, char** argv) {
  std::string path, site_path;
  for (int i = 0; i < argc; ++i) {
    const std::string o = argv[i];
    if (o == "--site" && i + 1 < argc) {
      site_path = argv[++i];
    } else if (!is_option(argv[i]) && path.empty()) {
      path = o;
    } else {
      return usage_error("check-config: unexpected argument '" + o + "'");
    }
  }
  if (path.empty()) return usage_error("check-config needs a configuration file");
  agv::overhead_app::OverheadConfig cfg;
  std::vector<std::string> errors;
  agv::site::Site site;
  bool ok = agv::overhead_app::load_config(path, &cfg, &errors);
  if (ok && !site_path.empty() && agv::overhead_app::load_site_file(site_path, &site, &errors)) {
    std::string err;
    if (!agv::overhead_app::check_config_against_site(cfg, site, &err))
      errors.push_back(path + ": " + err);
  }
  for (const std::string& e : errors) std::fprintf(stderr, "agvloc-overhead: %s\n", e.c_str());
  if (!errors.empty()) return 2;
  std::printf("%s: OK\n", path.c_str());
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  if (argc < 2) return usage_error("no command");
  const std::string cmd = argv[1];
  if (cmd == "--help" || cmd == "-h" || cmd == "help") {
    std::fputs(kUsage, stdout);
    return 0;
  }
  if (cmd == "check-config") return check_config(argc - 2, argv + 2);
  if (cmd == "config-doc") {
    std::fputs(agv::overhead_app::config_keys_doc().c_str(), stdout);
    return 0;
  }
  if (cmd == "replay") {
    ReplayArgs a;
    std::string err;
    if (!parse_replay(argc - 2, argv + 2, &a, &err)) return usage_error("replay: " + err);
    return agv::overhead_app::run_replay(a);
  }
  if (cmd == "run") {
    agv::overhead_app::RunArgs a;
    std::string err;
    std::vector<char*> args(argv + 2, argv + argc);
    const auto flag = std::find(args.begin(), args.end(), std::string("--detections-from-broker"));
    const bool from_broker = flag != args.end();
    if (from_broker) args.erase(flag);
    if (!parse_live(static_cast<int>(args.size()), args.data(), &a, &err))
      return usage_error("run: " + err);
    return from_broker ? agv::overhead_app::run_broker_tracker(a)
                       : agv::overhead_app::run_live_command(a);
  }
  if (cmd == "detect") {
    agv::overhead_app::DetectArgs a;
    std::string err;
    if (!parse_detect(argc - 2, argv + 2, &a, &err)) return usage_error("detect: " + err);
    return agv::overhead_app::run_detect(a);
  }
  if (cmd == "record") {
    agv::overhead_app::RecordArgs a;
    std::string err;
    if (!parse_live(argc - 2, argv + 2, &a, &err)) return usage_error("record: " + err);
    if (a.out_dir.empty()) return usage_error("record: --out is required (the recording's folder)");
    return agv::overhead_app::run_record_command(a);
  }
  return usage_error("unknown command '" + cmd + "'");
}
