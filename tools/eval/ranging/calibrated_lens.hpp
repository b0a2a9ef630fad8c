// The ranging camera's lens as `agvloc-desk calibrate intrinsics` finds it from rendered views of
// a ChArUco board (eval_ranging_switch_on's AGV_EVAL_BOARD_VIEWS): the lens errors the project's
// own calibration leaves, instead of drawn ones. Built only beside the desk tool
// (AGV_EVAL_CALIBRATE).
#pragma once

#include <cstdint>
#include <string>

#include "agv/common/camera_model.hpp"

namespace agv::ranging_eval {

struct BoardCalibration {
  int views = 30;       // rendered views of normal sharpness
  double bow_mm = 0.0;  // the board's bow at its centre (a print on foam board)
  std::uint64_t seed = 1;
};

// The calibrated lens in *out and a one-line report of its errors against `truth`; false with
// *error when the calibration has no result.
bool calibrate_lens(const CameraIntrinsics& truth, const BoardCalibration& setup,
                    CameraIntrinsics* out, std::string* report, std::string* error);

}  // namespace agv::ranging_eval
