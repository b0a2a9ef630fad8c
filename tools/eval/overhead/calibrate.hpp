// eval_overhead --calibrate-tags N: the camera poses the tracker is told come from this project's
// own ceiling calibration (agvloc-desk calibrate ceiling: tools/desk/src/calib_ceiling.hpp), run
// on rendered frames of N tags standing at surveyed positions in each camera's view, the survey
// itself off by a random error; the tracker is told the solve's sigmas, as `calibrate ceiling
// --write` writes them into the site file.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "agv/site/site.hpp"

namespace agv::eval {

struct CalibrationSetup {
  int tags = 0;                  // surveyed tags per camera (>= 3)
  int frames = 2;                // rendered frames of them per camera
  double tag_mm = 160.0;         // black square's side
  double survey_error_mm = 0.0;  // sigma of each surveyed coordinate (x, y and z), Gaussian
  // > 0: the lens too is calibrated (agvloc-desk calibrate intrinsics) from this many rendered
  // views of a ChArUco board through the true lens, as on a bench before mounting, and the pose
  // is solved with it; 0: the true lens.
  int board_views = 0;
  // The board's bow at its centre (sim::BoardImageOptions::bow_mm): 0.5 mm on its 660 x 480 mm,
  // a print glued on foam board; the calibration takes it flat, as the command does.
  double board_bow_mm = 0.5;
  std::uint64_t seed = 1;
};

// The camera as the calibration solves it from frames rendered through `truth`, with the solved
// pose's sigmas in position_sigma_mm and angle_sigma_rad, and the calibrated lens when
// setup.board_views > 0. False with *error when a solve fails. *report: the solves' residuals
// and their errors against the truth.
bool calibrated_camera(const site::CeilingCamera& truth, const CalibrationSetup& setup,
                       site::CeilingCamera* out, std::string* report, std::string* error);

// Every camera of the site, the seed moved by the camera's index and the tags as large as the
// fleet's first; one report line per camera on stdout.
bool calibrated_cameras(const site::Site& site, CalibrationSetup setup,
                        std::vector<site::CeilingCamera>* out, std::string* error);

}  // namespace agv::eval
