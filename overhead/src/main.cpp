// agvloc-overhead: the site's fleet tracked from ceiling cameras (docs/guide/overhead.md).
// Subcommands: check-config, replay, run, detect, record, config-doc. Exit codes: 0 done, 1 failure
// while running, 2 bad input (the command line's convention: cli_parse.hpp).
#include <CLI/CLI.hpp>
#include <cstdio>
#include <string>
#include <vector>

#include "cli_parse.hpp"
#include "config.hpp"
#include "detect.hpp"
#include "inputs.hpp"
#include "record.hpp"
#include "replay.hpp"
#include "run.hpp"

namespace {

namespace oa = agv::overhead_app;

// The options every tracking command shares.
void add_config_site(CLI::App* cmd, std::string* config_path, std::string* site_path,
                     bool config_required) {
  auto* c = cmd->add_option("--config", *config_path,
                            config_required ? "configuration YAML (the cameras' devices)"
                                            : "configuration YAML (default: the defaults)");
  if (config_required) c->required();
  cmd->add_option("--site", *site_path, "site file (docs/guide/site.md)")->required();
}

CLI::Option* add_duration(CLI::App* cmd, double* duration_s) {
  return cmd
      ->add_option("--duration-s", *duration_s, "stop after this many seconds (default: SIGTERM)")
      ->check(CLI::Range(1e-3, 1e7));
}

int check_config(const std::string& path, const std::string& site_path) {
  oa::OverheadConfig cfg;
  std::vector<std::string> errors;
  agv::site::Site site;
  const bool ok = oa::load_config(path, &cfg, &errors);
  if (ok && !site_path.empty() && oa::load_site_file(site_path, &site, &errors)) {
    std::string err;
    if (!oa::check_config_against_site(cfg, site, &err)) errors.push_back(path + ": " + err);
  }
  for (const std::string& e : errors) std::fprintf(stderr, "agvloc-overhead: %s\n", e.c_str());
  if (!errors.empty()) return 2;
  std::printf("%s: OK\n", path.c_str());
  return 0;
}

struct Commands {
  std::string check_path, check_site;
  oa::ReplayArgs replay;
  oa::RunArgs run;
  bool from_broker = false;
  oa::DetectArgs detect;
  oa::RecordArgs record;
};

void add_commands(CLI::App* app, Commands* c) {
  auto* check = app->add_subcommand("check-config",
                                    "check a configuration (and its cameras "
                                    "against a site)");
  check->add_option("config", c->check_path, "configuration YAML")->required();
  check->add_option("--site", c->check_site, "site file: the cameras must be in it");

  auto* replay = app->add_subcommand("replay",
                                     "track the fleet in recorded frames of ceiling "
                                     "cameras");
  add_config_site(replay, &c->replay.config_path, &c->replay.site_path, false);
  replay->add_option("--recordings", c->replay.recordings, "one recording folder per camera")
      ->required()
      ->expected(1, -1);
  replay->add_option("--out", c->replay.out_dir, "output folder (tracks CSV)");
  replay->add_flag("--fast", c->replay.fast, "as fast as possible instead of the recording's pace");

  auto* run = app->add_subcommand("run",
                                  "live ceiling cameras (V4L2, libcamera, Aravis) until "
                                  "SIGTERM, or the detectors' tags from the broker");
  add_config_site(run, &c->run.config_path, &c->run.site_path, true);
  run->add_flag("--detections-from-broker", c->from_broker,
                "track from the detector processes' tags on the broker");
  run->add_option("--out", c->run.out_dir, "output folder (tracks CSV)");
  add_duration(run, &c->run.duration_s);

  auto* detect = app->add_subcommand(
      "detect",
      "one camera's tags to the broker: its live camera (cameras.<id>.device) until "
      "SIGTERM, or a recording of it (--replay)");
  add_config_site(detect, &c->detect.config_path, &c->detect.site_path, false);
  detect->add_option("--camera", c->detect.camera, "the site camera's id")->required();
  auto* replay_dir = detect->add_option("--replay", c->detect.replay_dir, "the camera's recording");
  detect->add_flag("--fast", c->detect.fast, "as fast as possible instead of the recording's pace")
      ->needs(replay_dir);
  auto* duration = add_duration(detect, &c->detect.duration_s);
  duration->excludes(replay_dir);

  auto* record = app->add_subcommand("record",
                                     "record every configured camera, one folder each "
                                     "under --out, for replay");
  add_config_site(record, &c->record.config_path, &c->record.site_path, true);
  record->add_option("--out", c->record.out_dir, "the recording's folder")->required();
  add_duration(record, &c->record.duration_s);

  app->add_subcommand("config-doc", "print the configuration key table (Markdown)");
}

int dispatch(const CLI::App& app, const Commands& c) {
  if (app.got_subcommand("check-config")) return check_config(c.check_path, c.check_site);
  if (app.got_subcommand("replay")) return oa::run_replay(c.replay);
  if (app.got_subcommand("run"))
    return c.from_broker ? oa::run_broker_tracker(c.run) : oa::run_live_command(c.run);
  if (app.got_subcommand("detect")) return oa::run_detect(c.detect);
  if (app.got_subcommand("record")) return oa::run_record_command(c.record);
  std::fputs(oa::config_keys_doc().c_str(), stdout);
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{
      "agvloc-overhead: the site's fleet tracked from ceiling cameras "
      "(docs/guide/overhead.md). Exit codes: 0 done, 1 failure while running, 2 bad "
      "input."};
  app.require_subcommand(1);
  Commands c;
  add_commands(&app, &c);
  if (const int rc = agv::cli::parse(app, argc, argv); rc >= 0) return rc;
  return dispatch(app, c);
}
