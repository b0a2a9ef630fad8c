// Subcommands of agvloc-desk, the desk tool (not shipped to the vehicle). Each returns the
// process exit code: 0 success, 1 runtime failure (message on stderr), 2 usage error.
#pragma once

#include <cstdio>

namespace agv::desk {

int sim(int argc, char** argv);             // write a simulated recording
int landmark(int argc, char** argv);        // print landmarks as SVG/PNG
int report(int argc, char** argv);          // accuracy against truth + trajectory plot of a replay
int calibrate(int argc, char** argv);       // dispatcher: calibrate intrinsics|vehicle|check
void print_calibrate_subcommands(FILE* f);  // one usage line per calibrate subcommand
int calibrate_intrinsics(int argc, char** argv);  // camera intrinsics from board images
// calibrate vehicle: mounting, odometry and time offset from a calibration drive. Exit 0 all
// determined, 1 some not determined (not written) or failure, 2 bad input.
int calibrate_vehicle(int argc, char** argv);
int sim_board(int argc, char** argv);  // simulated calibration-board views
// calibrate check: parked-vehicle check with a printed landmark at a taped pose. Exit 0 within
// tolerance, 1 out of tolerance, 2 bad input.
int calibrate_check(int argc, char** argv);
// calibrate ceiling: a ceiling camera's pose from tags at surveyed positions. Exit 0 solved,
// 1 no pose or write failure, 2 bad input. ceiling-check: the site file's pose against such
// frames. Exit 0 pass, 1 fail, 2 bad input.
int calibrate_ceiling(int argc, char** argv);
int calibrate_ceiling_check(int argc, char** argv);
// calibrate ranging-mount: the second camera's mount from a drive past rack landmarks, the
// vehicle localized by the floor camera. Exit 0 solved, 1 no mount or write failure, 2 bad input.
int calibrate_ranging_mount(int argc, char** argv);
int config_command(int argc, char** argv);  // dispatcher: config apply
void print_config_subcommands(FILE* f);     // one usage line per config subcommand
// config apply: calibration snippets merged into a configuration. Exit 0 written, 1 write
// failure, 2 refused (conflict, unknown key, fails the checker; nothing written).
int config_apply_command(int argc, char** argv);
// The site (docs/guide/site.md). Exit 0 success, 1 failure, 2 bad input.
int site_command(int argc, char** argv);         // site check|draw
int plan_command(int argc, char** argv);         // route between two points of a site
int fleet_command(int argc, char** argv);        // fleet simulation on a site
int render_site_command(int argc, char** argv);  // frames of a site's cameras

}  // namespace agv::desk
