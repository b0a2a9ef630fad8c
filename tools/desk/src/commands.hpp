// Subcommands of agvloc-desk, the desk tool (not shipped to the vehicle). Each returns the
// process exit code: 0 success, 1 runtime failure (message on stderr), 2 usage error.
#pragma once

namespace agv::desk {

int sim(int argc, char** argv);       // write a simulated recording
int landmark(int argc, char** argv);  // print landmarks as SVG/PNG
int report(int argc, char** argv);    // accuracy against truth + trajectory plot of a replay
// `calibrate vehicle`: mounting, odometry and time offset from a calibration drive
// (cmd_calibrate_vehicle.cpp; registered in the `calibrate` dispatcher).
int calibrate_vehicle(int argc, char** argv);

}  // namespace agv::desk
