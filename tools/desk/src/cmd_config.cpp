// agvloc-desk config: work on a vehicle configuration at the desk. `config apply` merges the
// calibration snippets into it and checks the result as `agvloc run --check-config` does.
#include <CLI/CLI.hpp>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iterator>

#include "agv/config/config.hpp"
#include "agv/recording/recording.hpp"
#include "cli_parse.hpp"
#include "commands.hpp"
#include "config.hpp"
#include "config_apply.hpp"
#include "subcommands.hpp"

namespace agv::desk {

namespace {

namespace fs = std::filesystem;

const Subcommand kConfigSubcommands[] = {
    {"apply", config_apply_command,
     "merge calibration snippets into a configuration (--config BASE SNIPPET... --out FILE)"},
};
const CommandGroup kConfig{"config", kConfigSubcommands, std::size(kConfigSubcommands)};

// The output appears whole or not at all: a check that fails, or a full disk, leaves no
// half-written configuration to deploy.
bool write_atomically(const std::string& path, const std::string& text, std::string* error) {
  const std::string tmp = path + ".tmp";
  {
    std::ofstream f(tmp, std::ios::binary | std::ios::trunc);
    f << text;
    f.flush();
    if (!f) {
      *error = "cannot write " + tmp;
      std::error_code ec;
      fs::remove(tmp, ec);
      return false;
    }
  }
  std::error_code ec;
  fs::rename(tmp, path, ec);
  if (ec) {
    *error = "cannot rename " + tmp + " to " + path + ": " + ec.message();
    fs::remove(tmp, ec);
    return false;
  }
  return true;
}

}  // namespace

void print_config_subcommands(FILE* f) { print_group_lines(f, kConfig); }

int config_command(int argc, char** argv) { return dispatch_group(kConfig, argc, argv); }

int config_apply_command(int argc, char** argv) {
  CLI::App app{
      "Merge the snippets of `calibrate intrinsics` (intrinsics.yaml) and `calibrate vehicle` "
      "(vehicle_calibration.yaml) into a vehicle configuration and write the result to --out, "
      "keeping the configuration's comments and layout. Refused, naming the key: a snippet key "
      "the configuration does not have, two snippets setting one key to different values, a "
      "result that `agvloc run --check-config` would refuse (docs/guide/commissioning.md)",
      "agvloc-desk config apply"};
  std::string base_path, out_path;
  std::vector<std::string> snippet_paths;
  bool force = false;
  app.add_option("--config", base_path, "The vehicle configuration to start from")->required();
  app.add_option("snippets", snippet_paths, "Calibration snippets, applied together")->required();
  app.add_option("--out", out_path,
                 "Write the merged configuration here (a relative landmark.map is read relative "
                 "to this file's directory)")
      ->required();
  app.add_flag("--force", force, "Overwrite --out if it exists (also when it is --config)");
  if (const int parse_rc = cli::parse(app, argc, argv); parse_rc >= 0) return parse_rc;
  const char* who = "agvloc-desk config apply";
  auto fail = [who](const std::string& m) {
    std::fprintf(stderr, "%s: %s\n", who, m.c_str());
    return 2;
  };
  std::error_code ec;
  if (fs::exists(out_path, ec) && !force) {
    const bool is_base = fs::equivalent(out_path, base_path, ec);
    return fail("--out " + out_path + (is_base ? " is the --config file" : " exists") +
                "; write elsewhere, or pass --force to overwrite it");
  }
  config_apply::Text base{base_path, {}};
  std::string err;
  if (!recording::read_file_bounded(base_path, config::kMaxConfigBytes, &base.text, &err)) {
    return fail(err);
  }
  std::vector<config_apply::Text> snippets;
  for (const auto& p : snippet_paths) {
    config_apply::Text t{p, {}};
    if (!recording::read_file_bounded(p, config::kMaxConfigBytes, &t.text, &err)) return fail(err);
    snippets.push_back(std::move(t));
  }
  config_apply::Merged merged;
  std::vector<std::string> errors;
  if (!config_apply::merge(base, snippets, &merged, &errors)) {
    for (const auto& e : errors) std::fprintf(stderr, "%s: %s\n", who, e.c_str());
    return fail("nothing written");
  }

  // The checker of `agvloc run --check-config`, on the result where it will live.
  std::string out_dir = fs::path(out_path).parent_path().string();
  if (out_dir.empty()) out_dir = ".";
  config::Config cfg;
  errors.clear();
  const bool parsed = config::parse_config(merged.text, out_dir, &cfg, &errors);
  LandmarkMap map;
  const LandmarkMap* map_ptr = nullptr;
  if (parsed && !cfg.map_file.empty()) {
    if (config::load_map_file(cfg.map_file, &map, &err)) {
      map_ptr = &map;
    } else {
      errors.push_back("landmark.map (relative to --out's directory): " + err);
    }
  }
  if (parsed && errors.empty()) config::check_can_localize(cfg, map_ptr, &errors);
  if (!errors.empty()) {
    for (const auto& e : errors) {
      // Name the snippet when the refused key came from one.
      std::string from;
      for (const auto& c : merged.changes) {
        if (e.rfind(c.key + ":", 0) == 0) from = " (set by " + c.from + ")";
      }
      std::fprintf(stderr, "%s: merged configuration: %s%s\n", who, e.c_str(), from.c_str());
    }
    return fail("the merged configuration would not pass --check-config; nothing written");
  }

  std::string sources;
  for (const auto& p : snippet_paths) sources += " " + p;
  const std::string text =
      "# agvloc-desk config apply --config " + base_path + sources + "\n" + merged.text;
  if (!write_atomically(out_path, text, &err)) {
    std::fprintf(stderr, "%s: %s\n", who, err.c_str());
    return 1;
  }
  int changed = 0, added = 0, same = 0;
  for (const auto& c : merged.changes) {
    std::string what;
    if (c.before.empty()) {
      what = c.after + " (new)";
      ++added;
    } else if (c.before == c.after) {
      what = c.after + " (unchanged)";
      ++same;
    } else {
      what = c.before + " -> " + c.after;
      ++changed;
    }
    std::printf("  %-32s %s  [%s]\n", c.key.c_str(), what.c_str(), c.from.c_str());
  }
  std::printf("%s: %d changed, %d new, %d unchanged; wrote %s\n", who, changed, added, same,
              out_path.c_str());
  if (!merged.comments_kept) {
    std::printf(
        "%s: note: %s's layout could not be edited in place, so the file was rewritten by "
        "yaml-cpp, which drops comments\n",
        who, base_path.c_str());
  }
  std::printf("checked as `agvloc run --config %s --check-config` does:\n%s", out_path.c_str(),
              config::config_summary(cfg, map_ptr).c_str());
  return 0;
}

}  // namespace agv::desk
