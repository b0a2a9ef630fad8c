#include "calibrated_lens.hpp"

#include <cstdio>
#include <utility>
#include <vector>

#include "calib_intrinsics.hpp"

namespace agv::ranging_eval {

// An 11 x 8 ChArUco board of 60 mm squares (660 x 480 mm) filling 45-85 % of the image width,
// tilted up to 35 degrees, 0.5 px defocus, sensor noise: the same board as eval_overhead's
// --board-views.
bool calibrate_lens(const CameraIntrinsics& truth, const BoardCalibration& setup,
                    CameraIntrinsics* out, std::string* report, std::string* error) {
  namespace cal = desk::calib;
  cal::BoardSpec spec;
  spec.square_mm = 60.0;
  spec.marker_mm = 45.0;
  cal::SimBoardSet set;
  set.camera = truth;
  set.views = setup.views;
  set.blurred = 0;
  set.bow_mm = setup.bow_mm;
  set.seed = setup.seed;
  std::vector<cal::SimView> sim;
  if (!cal::simulate_board_views(spec, set, &sim, error)) return false;
  const cal::Options options;
  std::vector<cal::View> views;
  for (const auto& v : sim) views.push_back(cal::detect_view(v.image, v.name, spec, options));
  const cal::Result r = cal::calibrate(std::move(views), spec, options);
  if (!r.ok) return *error = "lens calibration: " + r.error, false;
  *out = r.intrinsics;
  char line[320];
  std::snprintf(line, sizeof line,
                "lens from %d of %d board views (bowed %.2f mm, seed %llu), rms %.3f px; error fx "
                "%+.3f %% fy %+.3f %% (told %.3f / %.3f %%), cx %+.2f cy %+.2f px, k1 %+.5f",
                r.usable, setup.views, setup.bow_mm, static_cast<unsigned long long>(setup.seed),
                r.rms_px, 100.0 * (out->fx / truth.fx - 1.0), 100.0 * (out->fy / truth.fy - 1.0),
                100.0 * r.stddev[0] / out->fx, 100.0 * r.stddev[1] / out->fy, out->cx - truth.cx,
                out->cy - truth.cy, out->k1 - truth.k1);
  *report = line;
  return true;
}

}  // namespace agv::ranging_eval
