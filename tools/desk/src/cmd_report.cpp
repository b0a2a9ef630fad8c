// agvloc-desk report REPLAY_OUT --recording REC [--map FILE] [--plot FILE]
#include <CLI/CLI.hpp>
#include <cstdio>
#include <filesystem>

#include "cli_parse.hpp"
#include "commands.hpp"
#include "config.hpp"
#include "report.hpp"

namespace agv::desk {

int report(int argc, char** argv) {
  CLI::App app{
      "Accuracy of a replay against the recording's truth.csv and the trajectory plot, from "
      "the replay's poses.csv and fixes.csv (docs/guide/replay.md)",
      "agvloc-desk report"};
  std::string out_dir, rec_dir, map_file, plot;
  app.add_option("replay_out", out_dir, "output directory of `agvloc replay --out`")->required();
  app.add_option("--recording", rec_dir, "the recording that was replayed")->required();
  app.add_option("--map", map_file, "landmark map to draw (default: RECORDING/map.csv if present)");
  app.add_option("--plot", plot, "trajectory plot to write (default: REPLAY_OUT/trajectory.svg)");
  if (const int parse_rc = cli::parse(app, argc, argv); parse_rc >= 0) return parse_rc;
  namespace fs = std::filesystem;
  std::string err;
  recording::Recording rec;
  if (!recording::read_recording(rec_dir, &rec, &err)) {
    std::fprintf(stderr, "agvloc-desk report: %s\n", err.c_str());
    return 2;
  }
  for (const auto& w : rec.warnings) {
    std::fprintf(stderr, "agvloc-desk report: warning: %s\n", w.c_str());
  }
  if (map_file.empty() && fs::exists(fs::path(rec_dir) / "map.csv")) {
    map_file = (fs::path(rec_dir) / "map.csv").string();
  }
  LandmarkMap map;
  if (!map_file.empty() && !config::load_map_file(map_file, &map, &err)) {
    std::fprintf(stderr, "agvloc-desk report: map: %s\n", err.c_str());
    return 2;
  }
  std::vector<PoseRow> ticks;
  std::vector<FixRow> fixes;
  if (!read_poses_csv((fs::path(out_dir) / "poses.csv").string(), &ticks, &err) ||
      !read_fixes_csv((fs::path(out_dir) / "fixes.csv").string(), &fixes, &err)) {
    std::fprintf(stderr, "agvloc-desk report: %s\n", err.c_str());
    return 2;
  }
  if (plot.empty()) plot = (fs::path(out_dir) / "trajectory.svg").string();
  std::vector<Vec2> odo_track;
  AccuracySummary acc;
  if (rec.has_truth) acc = evaluate(rec, ticks, fixes, &odo_track);
  if (!write_plot(plot, rec, ticks, odo_track, map_file.empty() ? nullptr : &map, &err)) {
    std::fprintf(stderr, "agvloc-desk report: %s\n", err.c_str());
    return 1;
  }
  if (rec.has_truth) {
    std::fputs(format_accuracy(acc).c_str(), stdout);
  } else {
    std::printf("%s has no truth.csv: no accuracy figures\n", rec_dir.c_str());
  }
  std::printf("plot: %s\n", plot.c_str());
  return 0;
}

}  // namespace agv::desk
