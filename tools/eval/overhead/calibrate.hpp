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
  std::uint64_t seed = 1;
};

// The camera as the calibration solves it from frames rendered through `truth`, with the solved
// pose's sigmas in position_sigma_mm and angle_sigma_rad. False with *error when the solve fails.
// *report: one line, the solve's residuals and its error against the truth.
bool calibrated_camera(const site::CeilingCamera& truth, const CalibrationSetup& setup,
                       site::CeilingCamera* out, std::string* report, std::string* error);

// Every camera of the site, the seed moved by the camera's index and the tags as large as the
// fleet's first; one report line per camera on stdout.
bool calibrated_cameras(const site::Site& site, CalibrationSetup setup,
                        std::vector<site::CeilingCamera>* out, std::string* error);

}  // namespace agv::eval
